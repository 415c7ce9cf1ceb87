"""Route planning and behaviour arbitration on the experience map (Section IV).

:func:`plan_route` seeds the temporal map at the current (peak) experience (Eqs.
10-11) and climbs it from the goal, following the links the way they were driven and
turning at junctions from one representation onto another (:func:`turn_pairs`);
:func:`map_pose` is the robot's pose in the experience map (its current experience plus
the odometry since);
:func:`arbitrate` brings the local movement paths (egocentric, from the local movement
module) into the map's frame and chooses the one closest to the route (Fig. 7).

Example:
    >>> import numpy as np
    >>> from torchratslam.navigation.planner import to_map_frame
    >>> to_map_frame(np.array([[1.0, 0.0]]), np.zeros(3), np.array([5.0, 0.0, np.pi / 2])).round(6)
    array([[5., 1.]])
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ratslam_graph.errors import GraphError
from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.features import Route
from ratslam_graph.geometry import wrap_angle
from ratslam_graph.navigation.arbitration import choose_path, route_ahead
from ratslam_graph.navigation.route import climb_route
from ratslam_graph.navigation.temporal import TemporalMap, adjacency, temporal_map
from torchratslam.sim.office.builder import Office
from torchratslam.sim.office.motion import Behaviour, options

__all__ = [
    "Plan",
    "arbitrate",
    "back_steps",
    "local_options",
    "map_pose",
    "plan_route",
    "to_map_frame",
    "turn_pairs",
]


@dataclass(frozen=True)
class Plan:
    """A planned route.

    Attributes:
        route: from the current experience to the goal (None: the goal has no finite
            time stamp, the route is lost).
        tmap: the temporal map it was climbed on.
        ms: time to build the temporal map (ms).
    """

    route: Route | None
    tmap: TemporalMap
    ms: float


def plan_route(
    em: ExperienceMap,
    goal: int,
    *,
    radius_m: float = 1.0,
    speed: float = 0.5,
    turn_rate: float = np.pi / 2,
    directed: bool = True,
    turns: bool = False,
    min_turn: float = np.pi / 4,
    min_step_m: float = 0.05,
    turn_back: bool = False,
    goal_place: np.ndarray | None = None,
    back_step_m: float = 0.0,
) -> Plan:
    """The temporal map from the robot's place and the route to ``goal``.

    The temporal map is seeded at the current (peak) experience and at the experiences
    that overlap it in the map (other representations of the same place, within
    ``radius_m`` of the robot's map pose), each at the time it takes to get there
    (distance over ``speed`` plus the turn over ``turn_rate``); the goal is likewise
    reached at any experience overlapping the goal experience. Both are done with two
    extra nodes linked to those experiences (one way: out of the robot's place, into
    the goal), so Eqs. 10-11 and the climb run as they are.

    Args:
        em: the experience map.
        goal: the goal experience.
        radius_m: how close experiences overlap (m).
        speed, turn_rate: the robot's driving speed (m/s) and turning rate (rad/s).
        directed: each link leads only the way it was driven, from ``src`` with its
            behaviour to ``dst``: a route is then a chain of behaviours the robot has
            executed, each monitored by Eq. 9. False: links both ways.
        turns: True: a route may also turn from an experience onto one that overlaps it
            (within ``radius_m``) facing a crossing way (``min_turn`` to ``pi -
            min_turn`` rad away), at the time the turn takes: the grouping of the start
            and the goal, at the junctions along the route. A junction's
            representations (one per heading it was passed with) are then joined in
            every combination, not only in the ones driven. Experiences facing the same
            or the opposite way are not joined, nor two turns chained, so a route never
            steps along a corridor past a deleted link (see :func:`turn_pairs`).
        min_step_m: experiences with no link of at least this length (m) were learnt
            turning on the spot and take no turns.
        turn_back: True (with ``directed``): a route may also begin by turning around
            at the current (peak) experience (the turn from the robot's heading to the
            experience's reversed, at ``turn_rate``) and follow links against the way
            they were driven, turning around again anywhere (``pi / turn_rate`` s) onto
            links the way they were driven: the
            paper's links are traversable both ways, and turning around costs its time.
            Without it a route from a place driven one way only leads on that way (round
            a loop, or to where the robot once turned around) although the way back
            along the same links is the short one. The turn is taken where the robot is
            only: not at the other experiences near its map position (the map can hold
            another place there), nor ahead of it.
        goal_place: the experiences at which a route may end (of those within
            ``radius_m`` of the goal experience in the map; the goal experience always):
            the navigator's arrival rule's goal place. None: every experience within
            ``radius_m`` of the goal experience.
        back_step_m: above 0: a route may also follow, against its way, a link no
            longer than ``back_step_m`` (its odometric length) between two experiences
            facing the same way (within ``min_turn``), at the link's time. Such a link
            joins two representations of one place: an experience learnt a few
            centimetres behind the current one is linked from it, backwards, and the
            transition the robot then drove the other way is never learnt (a pair is
            linked once), so the chain of driven links ends there although the robot
            drove on. The step lands on the second layer, as a turn does, so two steps
            (or a step and a turn) never follow each other and no corridor is walked
            backwards a link at a time.
    """
    links = em.store
    n, e = links.n, links.e
    t0 = time.perf_counter()
    poses = em.poses
    here = map_pose(em)
    d = np.hypot(*(poses[:, :2] - here[:2]).T)
    turn = np.abs(wrap_angle(poses[:, 2] - here[2]))
    near = np.flatnonzero(d <= radius_m)
    near = np.union1d(near, [max(em.current_id, 0)]).astype(np.int64)
    dg = np.hypot(*(poses[:, :2] - poses[goal, :2]).T)
    ends = np.flatnonzero(dg <= radius_m)
    if goal_place is not None:
        ends = np.intersect1d(ends, np.asarray(goal_place, np.int64))
    at_goal = np.union1d(ends, [goal]).astype(np.int64)
    s, g = links.src[:e], links.dst[:e]
    w = links.link[:e, 3]
    if not directed:
        s, g, w = np.concatenate([s, g]), np.concatenate([g, s]), np.concatenate([w, w])
    layers = 2 if turns or back_step_m > 0 else 1
    if layers == 2:  # a turn (or a step) from one representation of a place onto another
        if turns:
            step = links.link[:e, 0] >= min_step_m
            moving = np.zeros(n, dtype=bool)
            moving[links.src[:e][step]] = True
            moving[links.dst[:e][step]] = True
            a, b = turn_pairs(poses[:n], radius_m, min_turn, moving)
        else:
            a = b = np.zeros(0, np.int64)
        w_ab = np.hypot(*(poses[a, :2] - poses[b, :2]).T) / speed
        w_ab += np.abs(wrap_angle(poses[a, 2] - poses[b, 2])) / turn_rate
        if back_step_m > 0:  # a short link between one place's representations, backwards
            short = back_steps(links, poses, back_step_m, min_turn)
            a = np.concatenate([a, links.dst[:e][short]])
            b = np.concatenate([b, links.src[:e][short]])
            w_ab = np.concatenate([w_ab, links.link[:e, 3][short]])
        # a turn lands on the second layer (n + j), which leads on by j's links only:
        # a route never turns twice in a row (never skips along a corridor by turning
        # round and back)
        s, g, w = (
            np.concatenate([s, s + n, a]),
            np.concatenate([g, g, b + n]),
            np.concatenate([w, w, w_ab]),
        )
        seeds = near + n  # the start is itself a turn onto the robot's place
        goals = np.concatenate([at_goal, at_goal + n])
    else:
        seeds, goals = near, at_goal
    seed_t = d[near] / speed + turn[near] / turn_rate
    if turn_back and directed:  # one more layer: the links against their way
        back = layers * n
        every = np.arange(n, dtype=np.int64)
        t_back = np.full(n, np.pi / turn_rate)
        s, g, w = (
            np.concatenate([s, links.dst[:e] + back, every + back]),
            np.concatenate([g, links.src[:e] + back, every]),
            np.concatenate([w, links.link[:e, 3], t_back]),
        )
        # turning around onto them only at the current (peak) experience: the robot
        # faces its way back by the turn from the robot's heading
        cur = np.array([max(em.current_id, 0)], dtype=np.int64)
        seeds = np.concatenate([seeds, cur + back])
        seed_t = np.concatenate([seed_t, d[cur] / speed + (np.pi - turn[cur]) / turn_rate])
        goals = np.concatenate([goals, at_goal + back])
        layers += 1
    m = layers * n
    src = np.concatenate([s, np.full(len(seeds), m), goals])
    dst = np.concatenate([g, seeds, np.full(len(goals), m + 1)])
    dgoal = dg[at_goal] / speed
    dt = np.concatenate([w, seed_t, np.tile(dgoal, len(goals) // len(at_goal))])
    # the two extra nodes are linked one way only: out of the robot's place, into the
    # goal (no shortcut through either)
    tmap = temporal_map(m + 2, start=m, adj=adjacency(m + 2, src, dst, dt, directed=True))
    ms = 1000.0 * (time.perf_counter() - t0)
    try:  # the climb follows the links into each experience
        full = climb_route(tmap, adjacency(m + 2, dst, src, dt, directed=True), m + 1)
        ids = [i % n for i in full.ids[1:-1]]
        route: Route | None = Route(ids=ids, times=full.times[1:-1])
    except GraphError:
        route = None
    if layers > 1:
        tmap = _fold(tmap, n, layers)
    return Plan(route, tmap, ms)


def _fold(tmap: TemporalMap, n: int, layers: int = 2) -> TemporalMap:
    """The layered temporal map as one time stamp per experience (the earliest of its
    ``layers`` nodes), then the start and goal nodes."""
    t, par = tmap.times, tmap.parent
    m = layers * n
    stack = t[:m].reshape(layers, n)
    k = np.argmin(stack, axis=0)  # the first layer on ties
    cols = np.arange(n)
    times = np.concatenate([stack[k, cols], t[m:]])
    parent = np.concatenate([par[:m].reshape(layers, n)[k, cols], par[m:]])
    # a layer's node j is j; the extras follow the experiences
    parent = np.where(parent >= m, parent - m + n, np.where(parent >= 0, parent % n, parent))
    return TemporalMap(start=n, times=times, parent=parent)


def turn_pairs(
    poses: np.ndarray,
    radius_m: float,
    min_turn: float,
    moving: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Ordered pairs ``(i, j)`` of experiences within ``radius_m`` of each other whose
    headings differ by more than ``min_turn`` and less than ``pi - min_turn`` (rad): the
    turns from one way onto a crossing one, where two ways meet.

    Turning around is left out, and so are experiences the robot did not drive through
    (``moving`` False: learnt while it turned on the spot, facing no way out): along a
    corridor driven both ways, turns around and back (or onto a half-turned experience
    and off it) would step the route along, up to ``radius_m`` at a time, where no link
    leads. Only where ways cross do experiences face across each other.

    Experiences are binned on a grid of ``radius_m`` cells and compared with the 9 cells
    around their own (one sorted search per neighbouring cell, no loop over experiences).

    Shape:
        poses: (N, 3) ``[x, y, th]``; moving: (N,) bool. Returns two (P,) int64 arrays.
    """
    xy = np.asarray(poses, np.float64).reshape(-1, 3)
    n = len(xy)
    cell = np.floor(xy[:, :2] / radius_m).astype(np.int64)
    cell -= cell.min(axis=0) if n else 0
    span = int(cell[:, 1].max()) + 3 if n else 3
    key = (cell[:, 0] + 1) * span + cell[:, 1] + 1
    order = np.argsort(key, kind="stable")
    sk = key[order]
    src, dst = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            want = key + dx * span + dy
            lo = np.searchsorted(sk, want, side="left")
            cnt = np.searchsorted(sk, want, side="right") - lo
            i = np.repeat(np.arange(n), cnt)
            first = np.repeat(np.cumsum(cnt) - cnt, cnt)
            j = order[np.repeat(lo, cnt) + np.arange(len(i)) - first]
            src.append(i)
            dst.append(j)
    a, b = np.concatenate(src), np.concatenate(dst)
    d = np.hypot(*(xy[a, :2] - xy[b, :2]).T)
    rot = np.abs(wrap_angle(xy[a, 2] - xy[b, 2]))
    keep = (a != b) & (d <= radius_m) & (rot > min_turn) & (rot < np.pi - min_turn)
    if moving is not None:
        keep &= moving[a] & moving[b]
    return a[keep], b[keep]


def back_steps(links: Any, poses: np.ndarray, max_m: float, min_turn: float) -> np.ndarray:
    """Which links may be followed against their way (``plan_route(...,
    back_step_m=max_m)``): those no longer than ``max_m`` (their odometric length)
    between experiences whose headings differ by ``min_turn`` rad or less.

    Shape:
        links: an experience map's link store (``src``, ``dst``, ``link``, ``e``);
        poses: (N, 3). Returns (E,) bool.
    """
    e = links.e
    src, dst = links.src[:e].astype(np.int64), links.dst[:e].astype(np.int64)
    rot = np.abs(wrap_angle(poses[src, 2] - poses[dst, 2]))
    return np.asarray((links.link[:e, 0] <= max_m) & (rot <= min_turn), dtype=bool)


def map_pose(em: ExperienceMap) -> np.ndarray:
    """The robot's ``[x, y, heading]`` in the experience map: the current experience's
    position plus the odometry accumulated since, heading the accumulated facing."""
    p = em.poses[max(em.current_id, 0)]
    return np.array([p[0] + em.accum_x, p[1] + em.accum_y, em.accum_facing])


def to_map_frame(points: np.ndarray, world_pose: np.ndarray, est_pose: np.ndarray) -> np.ndarray:
    """Points seen from the robot at ``world_pose`` placed around its map pose ``est_pose``.

    Shape:
        points: (P, 2); world_pose, est_pose: (3,). Returns (P, 2).
    """
    d = np.asarray(points, np.float64).reshape(-1, 2) - world_pose[:2]
    a = float(est_pose[2] - world_pose[2])
    c, s = np.cos(a), np.sin(a)
    return np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]], 1) + est_pose[:2]


def _ahead_of_robot(
    route_xy: np.ndarray, here: np.ndarray, window: int = 6, *, from_robot: bool = False
) -> np.ndarray:
    """The route from its node nearest the robot (among the first ``window``) on, with
    the robot's position first; ``from_robot``: moved so that node lies on the robot's
    position (the route's shape ahead of the robot, not its offset in the map)."""
    k = int(np.argmin(np.hypot(*(route_xy[:window] - here).T)))
    if from_robot:
        return route_xy[k:] - route_xy[k] + here
    return np.vstack([here[None, :], route_xy[k + 1 :]]) if k + 1 < len(route_xy) else here[None]


def local_options(
    office: Office, sim_paths: Mapping[Behaviour, np.ndarray], u: int, v: int, step: float
) -> list[tuple[Behaviour, np.ndarray]]:
    """The local movement paths as ``(behaviour, path)`` pairs: the simulator's, with the
    turn-around continued past ``u`` along each way out there (one pair each)."""
    out: list[tuple[Behaviour, np.ndarray]] = [
        (b, p) for b, p in sim_paths.items() if b is not Behaviour.TURN_AROUND
    ]
    back = sim_paths[Behaviour.TURN_AROUND]
    ways = [w for b, w in options(office, v, u).items() if b is not Behaviour.TURN_AROUND]
    for w in ways or [v]:
        a, b = office.nodes[u], office.nodes[w]
        n = max(1, int(np.ceil(np.hypot(*(b - a)) / step)))
        more = a + np.linspace(0.0, 1.0, n + 1)[1:, None] * (b - a)
        out.append((Behaviour.TURN_AROUND, np.vstack([back, more])))
    return out


def arbitrate(
    paths: Sequence[tuple[Behaviour, np.ndarray]],
    world_pose: np.ndarray,
    est_pose: np.ndarray,
    route_xy: np.ndarray,
    *,
    lookahead_m: float,
    turn_margin_m: float,
    allow_turn: bool = True,
    from_robot: bool = False,
) -> tuple[Behaviour, dict[Behaviour, float]]:
    """The behaviour whose local path is closest to the route (Fig. 7).

    Every path and the route are cut to their first ``lookahead_m`` metres (from the
    robot); a behaviour offered with several paths counts its closest; turning around
    must be closer by ``turn_margin_m`` than the best forward path. Ties go to the
    first path offered.

    Args:
        paths: ``(behaviour, path)`` pairs in the world frame, as the local movement
            module sees them (:func:`local_options`).
        world_pose: the robot's pose in the paths' frame.
        est_pose: its pose in the experience map (:func:`map_pose`).
        route_xy: the route's experience positions.
        lookahead_m: length compared.
        turn_margin_m: the turn-around's handicap (m).
        allow_turn: False rules turning around out (unless nothing else is offered).
        from_robot: compare with the route's shape from the robot on (its experience
            nearest the robot moved onto the robot's map position), not with its map
            positions: the map can hold two representations of a junction metres
            apart, and a turn held behind the robot then looks like a route back.

    Shape:
        route_xy: (R, 2).

    Returns:
        The behaviour and each behaviour's distance (m, the handicap included).
    """
    route = route_ahead(
        _ahead_of_robot(np.asarray(route_xy, np.float64), est_pose[:2], from_robot=from_robot),
        lookahead_m,
    )
    here = world_pose[:2][None, :]
    offered = [(b, p) for b, p in paths if allow_turn or b is not Behaviour.TURN_AROUND]
    offered = offered or list(paths)  # a dead end: turning around is all there is
    mapped = [
        to_map_frame(route_ahead(np.vstack([here, p]), lookahead_m), world_pose, est_pose)
        for _, p in offered
    ]
    d = choose_path(mapped, route).distances
    best: dict[Behaviour, float] = {}
    for (b, _), v in zip(offered, d.tolist()):
        v += turn_margin_m if b is Behaviour.TURN_AROUND else 0.0
        best[b] = min(best.get(b, np.inf), v)
    return min(best, key=lambda b: best[b]), best
