"""Route-loss recovery (Section IV D): follow the last good route by elapsed time, then
explore after the timeout."""

import pytest

from ratslam_graph.errors import InputError
from ratslam_graph.features import Route
from ratslam_graph.navigation.recovery import (
    RecoveryMode,
    RecoveryParams,
    RecoveryState,
    position_on_route,
    track_route,
)

R = Route(ids=[10, 11, 12, 13], times=[0.0, 2.0, 4.0, 6.0])


def test_position_by_elapsed_time():
    assert [position_on_route(R, t) for t in (0.0, 1.0, 2.0, 3.5, 6.0, 99.0)] == [0, 1, 1, 2, 3, 3]


def test_recovery_times_out_into_exploration():
    p = RecoveryParams(timeout_s=3.0)
    s = track_route(RecoveryState(), None, 0.0, p)
    assert s.mode is RecoveryMode.EXPLORING and s.route is None
    s = track_route(s, R, 100.0, p)
    assert s.mode is RecoveryMode.FOLLOWING and s.target == 11
    s = track_route(s, None, 101.0, p)  # lost at 101: elapsed since planning 1 s
    assert (s.mode, s.target, s.lost_s) == (RecoveryMode.RECOVERING, 11, 101.0)
    s = track_route(s, None, 103.5, p)  # elapsed 3.5 s -> node 2; 2.5 s since the loss
    assert (s.mode, s.target, s.lost_s) == (RecoveryMode.RECOVERING, 12, 101.0)
    s = track_route(s, None, 104.0, p)  # exactly the timeout: still relied on
    assert s.mode is RecoveryMode.RECOVERING
    s = track_route(s, None, 104.01, p)
    assert s.mode is RecoveryMode.EXPLORING and s.route is None and s.target == -1


def test_a_fresh_route_ends_recovery_and_restarts_the_clock():
    p = RecoveryParams(timeout_s=3.0)
    s = track_route(track_route(RecoveryState(), R, 0.0, p), None, 2.0, p)
    s = track_route(s, Route([5, 6], [0.0, 1.0]), 4.0, p)
    assert s.mode is RecoveryMode.FOLLOWING and s.target == 6 and s.planned_s == 4.0
    s = track_route(s, None, 6.5, p)
    assert s.mode is RecoveryMode.RECOVERING and s.lost_s == 6.5
    assert track_route(s, None, 9.5, p).mode is RecoveryMode.RECOVERING
    assert track_route(s, None, 9.6, p).mode is RecoveryMode.EXPLORING


def test_bad_params():
    with pytest.raises(InputError):
        RecoveryParams(timeout_s=-1.0)
    with pytest.raises(InputError):
        position_on_route(Route(), 0.0)
