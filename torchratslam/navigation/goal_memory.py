"""Goal recall with goal memory: the baseline the experience-map paper compares with.

:class:`GoalMemoryAgent` learns a :class:`~ratslam_graph.navigation.goal_memory.GoalMemory`
from the packet's path (every frame the robot maps, exploration and trials alike) and
navigates by it: every time the packet's cell changes (and every ``replan_s``) the route
is the fastest chain of learnt cell-to-cell links from the packet's cell to the goal's
cell; the cells' centres, unwrapped into one path and scaled to metres, are the route in
the pose cells' own frame, with the robot at the packet's centre facing its theta'.
Arbitration picks the behaviour whose local path is closest to that route, as the
experience map's navigation does (:func:`~torchratslam.navigation.planner.arbitrate`).
Without a route the robot explores. A trial ends when the packet is in the goal's cell
or a neighbour, or at the time limit; it succeeded when the ground truth is then within
``reach_m`` of the goal.

Example:
    >>> agent = GoalMemoryAgent(robot)  # doctest: +SKIP
    >>> agent.navigate(agent.mark_goal("C")).reached  # doctest: +SKIP
    True
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from ratslam_graph.navigation.goal_memory import GoalMemory
from torchratslam.navigation.agent import Goal, Trial, shortest_path_m
from torchratslam.navigation.params import NavParams
from torchratslam.navigation.planner import arbitrate, local_options
from torchratslam.navigation.robot import MappingRobot
from torchratslam.sim.office.motion import Behaviour

__all__ = ["GoalMemoryAgent"]

log = logging.getLogger(__name__)


class GoalMemoryAgent:
    """Goal navigation on goal memory.

    Args:
        robot: the mapping robot (its pose cells: ``pc_dim_x`` x ``pc_dim_y``).
        params: the navigator's settings (``replan_s``, ``reach_m``, ``lookahead_m``,
            ``turn_margin_m``, ``turn_cooldown_s``, ``blocked_cooldown_s``, the time
            limit's ``time_factor`` and ``time_slack_s``).
    """

    def __init__(self, robot: MappingRobot, params: NavParams | None = None) -> None:
        self.robot = robot
        self.params = params if params is not None else NavParams()
        pcp = robot.slam.config.pose_cells
        self.cell_m = float(pcp.pc_cell_x_size)
        self.n_th = int(pcp.pc_dim_th)
        self.memory = GoalMemory((pcp.dim_x, pcp.dim_y))
        self._seen = 0
        self.learn()

    def learn(self) -> None:
        """Learn from the frames the robot mapped since the last call."""
        pc = self.robot.slam.pc_log()
        t = self.robot.slam.history.times()
        for k in range(self._seen, len(pc)):  # one call per mapped frame, not per cell
            self.memory.observe(pc[k, :2], float(t[k]))
        self._seen = len(pc)

    def mark_goal(self, name: str) -> Goal:
        """The goal at node ``name``: the packet's cell when the robot last passed
        nearest it (``exp`` holds the cell).

        Raises:
            InputError: the robot never came within ``reach_m`` of it.
        """
        from torchratslam.errors import InputError

        r = self.robot
        xy = r.office.nodes[r.office.node(name)]
        d = np.hypot(*(r.trajectory()[:, :2] - xy).T)
        k = int(np.flatnonzero(d <= d.min() + 0.05)[-1])
        if d[k] > self.params.reach_m:
            raise InputError(f"the robot has not been within {self.params.reach_m} m of {name}")
        cell = self.memory.cell_of(r.slam.pc_log()[k, :2])
        return Goal(name, (float(xy[0]), float(xy[1])), cell)

    def _packet(self) -> np.ndarray:
        return np.asarray(self.robot.slam.pc_log()[-1], np.float64)

    def navigate(self, goal: Goal) -> Trial:
        """Drive to ``goal`` by goal memory (see the module docstring)."""
        p, r = self.params, self.robot
        sim, o, gm = r.sim, r.office, self.memory
        m = sim.state
        shortest = shortest_path_m(o, sim.pose[:2].copy(), m.u, m.v, o.node(goal.name))
        limit = p.time_factor * shortest / sim.params.motion.speed + p.time_slack_s
        t0, f0 = r.time, len(r.poses)
        last_cell, last_plan, turn_ok = -2, -np.inf, -np.inf
        route: list[int] | None = None
        first: tuple[int, ...] | None = None
        ms: list[float] = []
        lost = 0.0
        while r.time - t0 < limit:
            self.learn()
            pc = self._packet()
            cell = gm.cell_of(pc[:2])
            if cell == goal.exp or gm.neighbours(cell, goal.exp):
                break
            now = r.time
            if cell != last_cell or now - last_plan >= p.replan_s:
                t1 = time.perf_counter()
                route = gm.route(cell, goal.exp)
                ms.append((time.perf_counter() - t1) * 1000.0)
                last_cell, last_plan = cell, now
                if first is None and route is not None:
                    first = tuple(route)
            if route is None or len(route) < 2:
                lost += sim.params.motion.dt
                b = sim.explore()
            else:
                here = pc[:2] * self.cell_m
                centre = (math.floor(pc[0]) + 0.5, math.floor(pc[1]) + 0.5)
                xy = gm.positions(route, centre) * self.cell_m  # the packet's frame (m)
                est = np.array([here[0], here[1], pc[2] * 2.0 * math.pi / self.n_th])
                m = sim.state
                opts = local_options(o, sim.local_paths(), m.u, m.v, sim.params.motion.path_step)
                b, _ = arbitrate(
                    opts,
                    sim.pose,
                    est,
                    xy,
                    lookahead_m=p.lookahead_m,
                    turn_margin_m=p.turn_margin_m,
                    allow_turn=now >= turn_ok,
                )
                if b is Behaviour.TURN_AROUND:
                    turn_ok = now + p.turn_cooldown_s
            tick = r.tick(int(b))
            if tick.step.blocked:
                turn_ok = now + p.blocked_cooldown_s
        self.learn()
        path = r.trajectory()[f0 - 1 :, :2]
        driven = float(np.hypot(*np.diff(path, axis=0).T).sum())
        reached = bool(np.hypot(*(sim.pose[:2] - np.asarray(goal.xy))) <= p.reach_m)
        log.info("goal memory, goal %s: reached=%s in %.0f s", goal.name, reached, r.time - t0)
        return Trial(
            goal=goal,
            reached=reached,
            path_m=driven,
            shortest_m=shortest,
            time_s=r.time - t0,
            first_route=first or (),
            routes_xy=np.zeros((0, 2)),
            path_xy=path,
            planning_ms=tuple(ms),
            lost_s=lost,
        )
