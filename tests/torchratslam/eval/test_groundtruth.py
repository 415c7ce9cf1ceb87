"""Ground truth that does not describe a map is refused or warned about, before an ATE."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from torchratslam.errors import InputError
from torchratslam.eval.groundtruth import check_groundtruth_covers, groundtruth_coverage


def _square(t, side=4.0, period=8.0):
    """A square route of ``side`` m walked once every ``period`` s, at times ``t``."""
    s = (np.asarray(t) % period) / period * 4 * side
    edge, f = np.divmod(s, side)
    corners = np.array([[0, 0], [side, 0], [side, side], [0, side], [0, 0]], float)
    a, b = corners[edge.astype(int)], corners[edge.astype(int) + 1]
    return a + (b - a) * (f / side)[:, None]


def _gt(t, xy):
    return np.column_stack([t, xy, np.zeros(len(t))])


def test_coverage_against_brute_force_path_lengths():
    t = np.linspace(0.5, 7.5, 15)
    xy = _square(t) + 0.01
    tg = np.arange(0.0, 8.01, 0.25)
    c = groundtruth_coverage(t[::-1], xy[::-1], _gt(tg, _square(tg)))  # any order
    want_map = sum(math.dist(xy[i], xy[i + 1]) for i in range(len(t) - 1))
    truth = [(np.interp(x, tg, _square(tg)[:, 0]), np.interp(x, tg, _square(tg)[:, 1])) for x in t]
    want_gt = sum(math.dist(truth[i], truth[i + 1]) for i in range(len(t) - 1))
    assert c.map_path_m == pytest.approx(want_map) and c.groundtruth_path_m == pytest.approx(
        want_gt
    )
    assert c.in_time == 1.0 and c.samples == int(((tg >= 0.5) & (tg <= 7.5)).sum())
    assert c.path_ratio == pytest.approx(max(want_map, want_gt) / min(want_map, want_gt))


def test_the_ground_truth_of_another_route_is_refused(caplog):
    t = np.linspace(0.2, 7.8, 39)
    xy = _square(t)  # the map's route: 16 m in 8 s
    tg = np.arange(0.0, 549.0)
    slow = _gt(tg, _square(tg, side=4.0, period=300.0))  # another tour, same time base
    with pytest.raises(InputError, match=r"sim:virtual_tour: the map runs 15\.2 m, the gro"):
        check_groundtruth_covers(t, xy, slow, source="sim:virtual_tour")
    with caplog.at_level(logging.WARNING, logger="torchratslam"):
        check_groundtruth_covers(t, xy, _gt(t, _square(t)), source="gt.csv")
    assert caplog.text == ""  # its own ground truth: nothing to say


def test_time_ranges_refused_under_half_and_warned_when_partial(caplog):
    t = np.linspace(0.0, 10.0, 21)
    xy = _square(t, period=10.0)
    tg = np.linspace(0.0, 6.0, 61)
    with caplog.at_level(logging.WARNING, logger="torchratslam"):
        check_groundtruth_covers(t, xy, _gt(tg, _square(tg, period=10.0)), source="g.csv")
    assert "covers 62% of the map's times" in caplog.text
    late = _gt(tg + 100.0, _square(tg, period=10.0))
    with pytest.raises(InputError, match=r"cover 0% of the map's .*\[100, 106\] s"):
        check_groundtruth_covers(t, xy, late, source="g.csv")
    caplog.clear()
    sparse = _gt(np.array([0.0, 10.0]), _square(np.array([0.0, 10.0]), period=10.0))
    with caplog.at_level(logging.WARNING, logger="torchratslam"), pytest.raises(InputError):
        check_groundtruth_covers(t, xy, sparse, source="g.csv")  # a point: not this route
    t2 = np.linspace(1.0, 1.8, 5)
    xy2 = np.column_stack([t2, np.zeros(5)])
    with caplog.at_level(logging.WARNING, logger="torchratslam"):
        check_groundtruth_covers(
            t2, xy2, _gt(np.array([0.0, 3.0]), np.array([[0, 0], [3, 0.0]])), source="g.csv"
        )
    assert "only 0 ground-truth pose(s)" in caplog.text


def test_a_map_of_the_small_run_against_another_tour(small_run):
    from torchratslam.maps.io import load_state
    from torchratslam.readers.datasets import open_data

    s = load_state(small_run.out)
    own = open_data(small_run.data).groundtruth()
    c = check_groundtruth_covers(s.exp_t, s.exp_pose, own, source=small_run.data)
    assert c.path_ratio < 1.5
    other = open_data("sim:virtual_tour").groundtruth()
    with pytest.raises(InputError, match="it is not the ground truth of the map"):
        check_groundtruth_covers(s.exp_t, s.exp_pose, other, source="sim:virtual_tour")
