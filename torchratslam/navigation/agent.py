"""Exploration and navigation trials of the office robot (Sections IV-VI).

A goal is marked during exploration: the experience current when the robot passed
nearest the goal's place. A trial then repeats, every frame: find the route from the
current experience (afresh when the experience changes, else every ``replan_s``; the
route being followed is kept unless the fresh one is faster by ``route_keep_s``), keep
the last good one through route loss (:func:`~ratslam_graph.navigation.recovery.track_route`)
and explore once it times out, choose the behaviour whose local path is closest to the
route, drive, and map the frame with the behaviour it executed. The trial ends when the
robot believes it is at the goal (its map position within ``arrive_m`` of the goal
experience, and its current experience the goal's place: the goal experience or one
with its view template) or at the time limit; it succeeded when the ground truth is then within
``reach_m`` of the goal.

Example:
    >>> from torchratslam.navigation.agent import NavigationAgent  # doctest: +SKIP
    >>> agent = NavigationAgent(robot)  # doctest: +SKIP
    >>> agent.navigate(agent.mark_goal("r2")).reached  # doctest: +SKIP
    True
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import networkx as nx
import numpy as np

from ratslam_graph.errors import InputError
from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.features import Route
from ratslam_graph.geometry import wrap_angle
from ratslam_graph.link_learning import count_transition
from ratslam_graph.navigation.recovery import (
    RecoveryMode,
    RecoveryParams,
    RecoveryState,
    track_route,
)
from ratslam_graph.navigation.route import joined_positions
from torchratslam.navigation.params import NavParams
from torchratslam.navigation.planner import (
    Plan,
    arbitrate,
    back_steps,
    local_options,
    map_pose,
    plan_route,
)
from torchratslam.navigation.robot import MappingRobot
from torchratslam.sim.office.builder import Office
from torchratslam.sim.office.motion import Behaviour

__all__ = ["Goal", "NavigationAgent", "Trial", "shortest_path_m"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Goal:
    """A goal: a place on the floor and the experience marked for it.

    Attributes:
        name: the floor-plan node.
        xy: its position (m).
        exp: the goal experience.
    """

    name: str
    xy: tuple[float, float]
    exp: int


@dataclass(frozen=True)
class Trial:
    """One navigation trial.

    Attributes:
        goal: the goal.
        reached: the ground truth ended within ``reach_m`` of the goal.
        path_m: distance driven (m).
        shortest_m: the shortest path on the floor from the start (m).
        time_s: the trial's duration (s).
        first_route: the experiences of the first route planned.
        routes_xy: ground-truth places of the first route's experiences, (R, 2).
        path_xy: the ground-truth path driven, (T, 2).
        planning_ms: temporal-map times of the trial (ms).
        lost_s: time spent without a route (recovering or exploring, s).
        deleted, relearnt: links deleted and relearnt during the trial.
    """

    goal: Goal
    reached: bool
    path_m: float
    shortest_m: float
    time_s: float
    first_route: tuple[int, ...]
    routes_xy: np.ndarray
    path_xy: np.ndarray
    planning_ms: tuple[float, ...] = field(default=())
    lost_s: float = 0.0
    deleted: int = 0
    relearnt: int = 0


def shortest_path_m(office: Office, xy: np.ndarray, u: int, v: int, goal: int) -> float:
    """Length of the shortest way along the passages from ``xy`` (on passage ``u-v``) to
    node ``goal`` (m)."""
    g = nx.Graph()
    for a, b in office.edges.tolist():
        g.add_edge(a, b, weight=float(np.hypot(*(office.nodes[a] - office.nodes[b]))))
    g.add_edge("here", u, weight=float(np.hypot(*(office.nodes[u] - xy))))
    g.add_edge("here", v, weight=float(np.hypot(*(office.nodes[v] - xy))))
    return float(nx.shortest_path_length(g, "here", goal, weight="weight"))


class NavigationAgent:
    """Goal navigation on the robot's experience map.

    Args:
        robot: the mapping robot.
        params: the navigator's settings.
    """

    def __init__(self, robot: MappingRobot, params: NavParams | None = None) -> None:
        self.robot = robot
        self.params = params if params is not None else NavParams()

    @property
    def em(self) -> ExperienceMap:
        """The robot's experience map."""
        return self.robot.slam.experience_map  # type: ignore[return-value]

    def mark_goal(self, name: str) -> Goal:
        """The goal at node ``name``: the experience current when the robot last passed
        nearest it (within 5 cm of its nearest) so far.

        Raises:
            InputError: the robot never came within ``reach_m`` of it.
        """
        r = self.robot
        xy = r.office.nodes[r.office.node(name)]
        traj = r.trajectory()
        d = np.hypot(*(traj[:, :2] - xy).T)
        k = int(np.flatnonzero(d <= d.min() + 0.05)[-1])  # the latest of the nearest passes
        if d[k] > self.params.reach_m:
            raise InputError(f"the robot has not been within {self.params.reach_m} m of {name}")
        return Goal(name, (float(xy[0]), float(xy[1])), int(r.exp_ids[k]))

    def goal_place(self, goal: Goal) -> np.ndarray:
        """The experiences that stand for the goal's place (``arrive_at_place``): the goal
        experience, those learnt with its view template and those within
        ``arrive_links`` links of it (either way); sorted ids."""
        store = self.em.store
        n, e = store.n, store.e
        place = np.zeros(n, dtype=bool)
        place[goal.exp] = True
        if store.vt[goal.exp] >= 0:  # -1: learnt without a template
            place |= store.vt[:n] == store.vt[goal.exp]
        src, dst = store.src[:e], store.dst[:e]
        near = np.zeros(n, dtype=bool)
        near[goal.exp] = True
        for _ in range(self.params.arrive_links):  # a few hops, each over all links at once
            step = near.copy()
            step[dst[near[src]]] = True
            step[src[near[dst]]] = True
            near = step
        return np.flatnonzero(place | near)

    def _arrived(self, goal: Goal) -> bool:
        """The robot believes it is at the goal: its map position within ``arrive_m`` of
        the goal experience's and (``arrive_at_place``) its current experience one of
        :meth:`goal_place`."""
        em, p = self.em, self.params
        here = map_pose(em)[:2]
        if np.hypot(*(em.poses[goal.exp, :2] - here)) > p.arrive_m:
            return False
        if not p.arrive_at_place:
            return True
        cur = em.current_id
        if cur == goal.exp:
            return True
        return bool(cur >= 0 and np.isin(cur, self.goal_place(goal)))

    def keep_route(self, old: Route, plan: Plan) -> Route:
        """Route hysteresis (``route_keep_s``): the route to follow, ``old`` (rejoined)
        or ``plan``'s fresh one.

        The part of ``old`` still intact (each step a link the way it was driven, or,
        with ``junction_turns``, a turn onto a crossing way within ``overlap_m``, with
        ``back_step_m``, a short link followed against its way) is
        rejoined at its node the robot reaches soonest (``plan``'s temporal map, whose
        way there is taken) and followed on by its own times. The fresh route
        wins when it is faster by ``route_keep_s`` or more, or when nothing of ``old``
        is intact and reachable.
        """
        new = plan.route
        assert new is not None
        store, tm = self.em.store, plan.tmap
        n, e = store.n, store.e
        ids = np.asarray(old.ids, np.int64)
        ts = np.asarray(old.times, np.float64)
        if len(ids) == 0 or ids.max() >= n:
            return new
        keys = store.src[:e].astype(np.int64) * (n + 1) + store.dst[:e]
        a, b = ids[:-1], ids[1:]
        ok = (a == b) | np.isin(a * (n + 1) + b, keys)
        if self.params.turn_back:  # a link followed against its way
            ok |= np.isin(b * (n + 1) + a, keys)
        if self.params.back_step_m > 0:  # a short link against its way (planner.back_steps)
            short = back_steps(store, store.pose, self.params.back_step_m, np.pi / 4)
            ok |= np.isin(b * (n + 1) + a, keys[short])
        if self.params.junction_turns:  # a turn onto a crossing way (planner.turn_pairs)
            gap = np.hypot(*(store.pose[a, :2] - store.pose[b, :2]).T)
            rot = np.abs(wrap_angle(store.pose[a, 2] - store.pose[b, 2]))
            ok |= (gap <= self.params.overlap_m) & (rot > np.pi / 4) & (rot < 3 * np.pi / 4)
        first = int(np.flatnonzero(~ok)[-1]) + 1 if (~ok).any() else 0
        reach = tm.times[ids[first:]]
        if not np.isfinite(reach).any():
            return new
        j = first + int(np.argmin(reach))  # the intact node nearest the robot (in time)
        if new.total_time <= float(reach[j - first] + ts[-1] - ts[j]) - self.params.route_keep_s:
            return new
        head = [int(ids[j])]  # the temporal map's way from the robot's place to ids[j]
        while tm.parent[head[-1]] >= 0 and tm.parent[head[-1]] < n and len(head) <= n:
            head.append(int(tm.parent[head[-1]]))
        head.reverse()
        t_head = [float(tm.times[i]) for i in head]
        t_head = [t - t_head[0] for t in t_head]
        tail = (ts[j + 1 :] - ts[j] + t_head[-1]).tolist()
        return Route(ids=head + ids[j + 1 :].tolist(), times=t_head + tail)

    def _count_blocked(self, pose: np.ndarray, behaviour: int) -> None:
        """A blocked transition counts against the links of the place's other
        representations too (Eq. 9).

        The planner treats the experiences overlapping the robot's place as where it is;
        obstacle avoidance turning the robot around means ``behaviour`` did not take it
        where their links said, so each of those facing the robot's way (within
        ``overlap_m`` and 45 degrees of its map pose ``pose``) counts the transition to
        the current experience (links whose confidence falls below the threshold are
        deleted).
        """
        em = self.em
        cur = em.current_id
        d = np.hypot(*(em.poses[:, :2] - pose[:2]).T)
        turn = np.abs(wrap_angle(em.poses[:, 2] - pose[2]))
        group = np.flatnonzero((d <= self.params.overlap_m) & (turn <= np.pi / 4))
        for x in group[group != cur].tolist():  # the few experiences overlapping one place
            count_transition(em.store, em.params, x, cur, behaviour)

    def navigate(self, goal: Goal) -> Trial:
        """Drive to ``goal`` (see the module docstring)."""
        p, r = self.params, self.robot
        sim, o = r.sim, r.office
        m = sim.state
        start_xy = sim.pose[:2].copy()
        shortest = shortest_path_m(o, start_xy, m.u, m.v, o.node(goal.name))
        limit = p.time_factor * shortest / sim.params.motion.speed + p.time_slack_s
        t0, f0 = r.time, len(r.poses)
        del0, rel0 = r.links.deleted, r.links.relearnt
        rec = RecoveryParams(timeout_s=p.recovery_timeout_s)
        state = RecoveryState()
        last_exp, last_plan, turn_ok = -2, -np.inf, -np.inf
        first: tuple[int, ...] | None = None
        ms: list[float] = []
        lost = 0.0
        truth = r.experience_truth()
        first_xy = np.zeros((0, 2))
        while r.time - t0 < limit and not self._arrived(goal):
            now = r.time
            if r.exp_id != last_exp or now - last_plan >= p.replan_s:
                plan = plan_route(
                    self.em,
                    goal.exp,
                    turns=p.junction_turns,
                    turn_back=p.turn_back,
                    goal_place=self.goal_place(goal) if p.turn_back and p.arrive_at_place else None,
                    back_step_m=p.back_step_m,
                )
                ms.append(plan.ms)
                route = plan.route
                if (
                    route is not None
                    and p.route_keep_s > 0
                    and state.mode is RecoveryMode.FOLLOWING
                    and state.route is not None
                ):
                    route = self.keep_route(state.route, plan)
                state = track_route(state, route, now, rec)
                last_exp, last_plan = r.exp_id, now
                if first is None and plan.route is not None:
                    first = tuple(plan.route.ids)
                    truth = r.experience_truth()
                    first_xy = truth[np.asarray(first, dtype=np.int64)]
            if state.mode is RecoveryMode.EXPLORING or state.route is None:
                lost += sim.params.motion.dt
                b = sim.explore()
            else:
                route = state.route
                if state.mode is RecoveryMode.RECOVERING:
                    lost += sim.params.motion.dt
                    k = route.ids.index(state.target)
                    ids = route.ids[max(k - 1, 0) :]
                else:
                    ids = route.ids
                links = self.em.store
                xy = joined_positions(
                    self.em.poses, np.asarray(ids), links.src[: links.e], links.dst[: links.e]
                )
                m = sim.state
                opts = local_options(o, sim.local_paths(), m.u, m.v, sim.params.motion.path_step)
                b, _ = arbitrate(
                    opts,
                    sim.pose,
                    map_pose(self.em),
                    xy,
                    lookahead_m=p.lookahead_m,
                    turn_margin_m=p.turn_margin_m,
                    allow_turn=now >= turn_ok,
                    from_robot=p.junction_turns,
                )
                if b is Behaviour.TURN_AROUND:
                    turn_ok = now + p.turn_cooldown_s
            pose_before = map_pose(self.em)
            tick = r.tick(int(b))
            if tick.step.blocked:  # obstacle avoidance turned: no turning back at once
                turn_ok = now + p.blocked_cooldown_s
                self._count_blocked(pose_before, tick.label)
        path = r.trajectory()[f0 - 1 :, :2]
        driven = float(np.hypot(*np.diff(path, axis=0).T).sum())
        reached = bool(np.hypot(*(sim.pose[:2] - np.asarray(goal.xy))) <= p.reach_m)
        log.info("goal %s: reached=%s in %.0f s", goal.name, reached, r.time - t0)
        return Trial(
            goal=goal,
            reached=reached,
            path_m=driven,
            shortest_m=shortest,
            time_s=r.time - t0,
            first_route=first or (),
            routes_xy=first_xy,
            path_xy=path,
            planning_ms=tuple(ms),
            lost_s=lost,
            deleted=r.links.deleted - del0,
            relearnt=r.links.relearnt - rel0,
        )
