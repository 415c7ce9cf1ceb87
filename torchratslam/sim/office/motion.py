"""Local movement behaviours on the office's corridor graph.

The robot drives along the centre line of a passage from node ``u`` to node ``v``. The
behaviour it holds decides what it does on reaching ``v``:

* ``FOLLOW``: keep to the corridor (straight on, or round a bend with one way out);
* ``LEFT`` / ``RIGHT``: take the branch nearest to 90 degrees left / right;
* ``TURN_AROUND``: reverse at once, mid-corridor included.

At a node the robot first turns in place (at most ``turn_rate`` per tick), then drives
(at most ``speed`` per tick), so each tick's motion is rotate-then-translate, as the
odometry model of :mod:`torchratslam.sim.motion` integrates it.
:func:`local_paths` enumerates the path each behaviour would take from the robot's
position (for behaviour arbitration).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, replace

import numpy as np

from ratslam_graph.geometry import wrap_angle
from torchratslam.sim.office.builder import Office

__all__ = [
    "Behaviour",
    "MotionParams",
    "MotionState",
    "advance",
    "local_paths",
    "options",
    "resolve",
    "turn_around",
]


class Behaviour(enum.IntEnum):
    """Local movement behaviours (the environment's action indices)."""

    FOLLOW = 0
    LEFT = 1
    RIGHT = 2
    TURN_AROUND = 3


_FALLBACK = (Behaviour.FOLLOW, Behaviour.LEFT, Behaviour.RIGHT, Behaviour.TURN_AROUND)


@dataclass(frozen=True)
class MotionParams:
    """Robot kinematics.

    Attributes:
        speed: forward speed (m/s).
        turn_rate: turning speed in place (rad/s).
        rate_hz: control and sensing rate (the paper runs at 7 Hz).
        path_step: spacing of the points of :func:`local_paths` (m).
    """

    speed: float = 0.5
    turn_rate: float = math.pi / 2
    rate_hz: float = 7.0
    path_step: float = 0.25

    @property
    def dt(self) -> float:
        """Tick length (s)."""
        return 1.0 / self.rate_hz


@dataclass(frozen=True)
class MotionState:
    """Where the robot is on the graph.

    Attributes:
        u, v: the passage being driven, from node ``u`` towards node ``v``.
        s: distance travelled from ``u`` (m).
        heading: the robot's heading (rad).
        behaviour: the behaviour held for node ``v``.
    """

    u: int
    v: int
    s: float
    heading: float
    behaviour: Behaviour = Behaviour.FOLLOW

    def position(self, office: Office) -> np.ndarray:
        """``(x, y)`` of the robot (m), (2,)."""
        a, b = office.nodes[self.u], office.nodes[self.v]
        n = float(np.hypot(*(b - a)))
        return a + (b - a) * (self.s / n if n > 0 else 0.0)


def _bearing(office: Office, a: int, b: int) -> float:
    d = office.nodes[b] - office.nodes[a]
    return math.atan2(float(d[1]), float(d[0]))


def options(office: Office, u: int, v: int) -> dict[Behaviour, int]:
    """The node each behaviour leads to on arriving at ``v`` from ``u``."""
    out: dict[Behaviour, int] = {Behaviour.TURN_AROUND: u}
    ways = [int(w) for w in office.neighbours(v) if w != u]
    if not ways:
        return out
    arrive = _bearing(office, u, v)
    rel = np.array([wrap_angle(_bearing(office, v, w) - arrive) for w in ways])
    straight = int(np.argmin(np.abs(rel)))
    if abs(rel[straight]) < math.radians(30) or len(ways) == 1:
        out[Behaviour.FOLLOW] = ways[straight]
    left = int(np.argmin(np.abs(rel - math.pi / 2)))
    if math.radians(30) < rel[left] < math.radians(150):
        out[Behaviour.LEFT] = ways[left]
    right = int(np.argmin(np.abs(rel + math.pi / 2)))
    if -math.radians(150) < rel[right] < -math.radians(30):
        out[Behaviour.RIGHT] = ways[right]
    return out


def resolve(office: Office, u: int, v: int, behaviour: Behaviour) -> tuple[Behaviour, int]:
    """The behaviour executed at ``v`` (the held one, else the first available of
    follow, left, right, turn around) and the node it leads to."""
    opts = options(office, u, v)
    for b in (behaviour, *_FALLBACK):
        if b in opts:
            return b, opts[b]
    raise AssertionError("turning around is always available")


def turn_around(office: Office, m: MotionState) -> MotionState:
    """Reverse along the current passage (the robot then turns in place)."""
    n = float(np.hypot(*(office.nodes[m.v] - office.nodes[m.u])))
    return replace(m, u=m.v, v=m.u, s=max(0.0, n - m.s), behaviour=Behaviour.FOLLOW)


def advance(
    office: Office, m: MotionState, p: MotionParams
) -> tuple[MotionState, Behaviour | None]:
    """One tick: turn towards the passage's direction, else drive along it.

    Returns:
        The new state and the behaviour executed at a node reached this tick (None if
        no node was reached).
    """
    want = _bearing(office, m.u, m.v)
    err = wrap_angle(want - m.heading)
    if abs(err) > 1e-9:
        step = float(np.clip(err, -p.turn_rate * p.dt, p.turn_rate * p.dt))
        return replace(m, heading=float(wrap_angle(m.heading + step))), None
    n = float(np.hypot(*(office.nodes[m.v] - office.nodes[m.u])))
    s = m.s + p.speed * p.dt
    if s < n:
        return replace(m, s=s), None
    done, w = resolve(office, m.u, m.v, m.behaviour)
    new = MotionState(u=m.v, v=w, s=0.0, heading=want, behaviour=Behaviour.FOLLOW)
    return new, done


def _sample(a: np.ndarray, b: np.ndarray, step: float) -> np.ndarray:
    n = max(1, math.ceil(float(np.hypot(*(b - a))) / step))
    t = np.linspace(0.0, 1.0, n + 1)[1:, None]
    return a + t * (b - a)


def local_paths(office: Office, m: MotionState, p: MotionParams) -> dict[Behaviour, np.ndarray]:
    """The path each available behaviour takes from the robot's position.

    ``TURN_AROUND`` goes back to ``u``; the others run to ``v`` and on along the
    passage they choose there. Points every ``path_step`` metres.

    Shape:
        each path: (P, 2).
    """
    here = m.position(office)
    back = _sample(here, office.nodes[m.u], p.path_step)
    ahead = _sample(here, office.nodes[m.v], p.path_step)
    out: dict[Behaviour, np.ndarray] = {Behaviour.TURN_AROUND: back}
    for b, w in options(office, m.u, m.v).items():
        if b is not Behaviour.TURN_AROUND:
            out[b] = np.vstack([ahead, _sample(office.nodes[m.v], office.nodes[w], p.path_step)])
    return out
