"""Route-loss recovery (experience-map paper, Section IV D).

While navigating, the route is found afresh from each peak experience. A brand-new
experience has no links yet, so no time stamp reaches the goal and the route is lost for
a while. The robot then keeps using the last good route, placing itself along it by the
time elapsed since that route was planned; once the old route has been relied on for
longer than a timeout it is discarded and the robot returns to exploration.

The tracker is a pure function on a frozen state::

    state = RecoveryState()
    state = track_route(state, route_or_none, now_s, params)
    state.mode, state.target

Example:
    >>> from ratslam_graph.features import Route
    >>> from ratslam_graph.navigation.recovery import RecoveryParams, RecoveryState, track_route
    >>> p = RecoveryParams(timeout_s=5.0)
    >>> s = track_route(RecoveryState(), Route([3, 4, 5], [0.0, 2.0, 4.0]), 10.0, p)
    >>> s = track_route(s, None, 13.0, p)
    >>> s.mode.value, s.target
    ('recovering', 5)
    >>> track_route(s, None, 18.5, p).mode.value
    'exploring'
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace

import numpy as np

from ratslam_graph.errors import InputError
from ratslam_graph.features import Route

__all__ = ["RecoveryMode", "RecoveryParams", "RecoveryState", "position_on_route", "track_route"]


class RecoveryMode(enum.Enum):
    """What the navigator follows."""

    EXPLORING = "exploring"
    """No route: explore to acquire one."""
    FOLLOWING = "following"
    """A fresh route from the current peak experience."""
    RECOVERING = "recovering"
    """The last good route, positioned by elapsed time."""


@dataclass(frozen=True)
class RecoveryParams:
    """Route-loss recovery parameters.

    Attributes:
        timeout_s: how long an old route may be relied on after the route was lost (s).
    """

    timeout_s: float = 10.0

    def __post_init__(self) -> None:
        if not self.timeout_s >= 0:
            raise InputError(f"recovery timeout_s={self.timeout_s} must be >= 0")


@dataclass(frozen=True)
class RecoveryState:
    """The tracker's state.

    Attributes:
        mode: exploring, following or recovering.
        route: the last good route (None while exploring).
        planned_s: when ``route`` was planned (s).
        lost_s: when the route was lost (``nan`` unless recovering).
        target: the route's experience the robot should head for now (-1 if none).
    """

    mode: RecoveryMode = RecoveryMode.EXPLORING
    route: Route | None = None
    planned_s: float = float("nan")
    lost_s: float = float("nan")
    target: int = -1


def position_on_route(route: Route, elapsed_s: float) -> int:
    """Index of the first route node not yet reached after ``elapsed_s`` seconds.

    The robot is assumed to travel at the route's planned pace: the node with the
    smallest time stamp ``>= elapsed_s`` (the goal once the route's total time passed).
    """
    if len(route) == 0:
        raise InputError("an empty route has no position")
    k = int(np.searchsorted(np.asarray(route.times, dtype=np.float64), elapsed_s, side="left"))
    return min(k, len(route) - 1)


def track_route(
    state: RecoveryState, route: Route | None, now_s: float, params: RecoveryParams
) -> RecoveryState:
    """Advance the recovery state machine by one update.

    Args:
        state: the previous state.
        route: the route found from the current peak experience this update, or None
            when the goal has no finite time stamp (route lost).
        now_s: the current time (s).
        params: the timeout.

    Returns:
        FOLLOWING with the fresh route when there is one; otherwise RECOVERING on the
        last good route (target placed by the time since it was planned) until
        ``timeout_s`` has passed since the loss; then EXPLORING without a route.
    """
    if route is not None and len(route) > 0:
        return RecoveryState(
            mode=RecoveryMode.FOLLOWING,
            route=route,
            planned_s=float(now_s),
            target=route.ids[min(1, len(route) - 1)],
        )
    if state.route is None:
        return RecoveryState()
    lost = state.lost_s if state.mode is RecoveryMode.RECOVERING else float(now_s)
    if now_s - lost > params.timeout_s:
        return RecoveryState()
    k = position_on_route(state.route, now_s - state.planned_s)
    return replace(state, mode=RecoveryMode.RECOVERING, lost_s=lost, target=state.route.ids[k])
