"""``edge/goal-memory``: goal memory, the paper's baseline, beside the experience map.

The experience-map paper (Section II, Figs. 3-4) argues that goal memory, a temporal map
spread over a copy of the pose-cell matrix (its reference [6]; this project's reading in
:mod:`ratslam_graph.navigation.goal_memory`), fails when the matrix is small, because the
pose cells' collisions and discontinuities are its own. This experiment runs the same
exploration as ``edge/goal-recall`` (the same seed, the paper's map and matrices), then
navigates to the same six goals by goal memory
(:class:`~torchratslam.navigation.goal_memory.GoalMemoryAgent`) and, on a second run of
the same exploration, by the experience map, and reports both side by side with the
packet's collisions (Fig. 3) and goal memory's temporal map (Fig. 4).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ratslam_graph.navigation.goal_memory import collisions
from torchratslam.errors import InputError
from torchratslam.experiments.reproduce.edge import (
    FULL,
    PAPER,
    PAPER_MAP,
    QUICK,
    _config,
    _recall,
    _Setup,
)
from torchratslam.experiments.reproduce.report import Experiment, ExperimentContext, Report, Row
from torchratslam.navigation.agent import Goal, Trial
from torchratslam.navigation.goal_memory import GoalMemoryAgent
from torchratslam.navigation.plots import plot_goal_memory, plot_pc_path
from torchratslam.navigation.robot import MappingRobot
from torchratslam.sim.office.builder import build_office

__all__ = ["COLLISION_M", "EXPERIMENTS", "goal_memory_explore", "summary"]

COLLISION_M = 2.0
"""A cell whose visits lie more than this apart (m, the diagonal of the box round them)
stands for two places: a collision."""


def _explore(robot: MappingRobot, agent: GoalMemoryAgent, s: _Setup) -> list[Goal]:
    """``edge/goal-recall``'s exploration (the same calls, so the same frames)."""
    robot.explore(s.explore_s)
    while True:
        try:
            goals = [agent.mark_goal(g) for g in s.goals]
            agent.learn()
            return goals
        except InputError:
            if robot.time >= s.max_explore_s:
                raise
            robot.explore(50.0)


def goal_memory_explore(
    office: Any, s: _Setup, dims: tuple[int, int], seed: int
) -> tuple[MappingRobot, GoalMemoryAgent, list[Goal]]:
    """``edge/goal-recall``'s exploration (the paper's map, ``dims`` pose cells) with
    goal memory learning from it, and the goals marked on goal memory:
    ``(robot, agent, goals)``."""
    robot = MappingRobot(_config(dims, PAPER_MAP), office=office, seed=seed)
    agent = GoalMemoryAgent(robot)
    return robot, agent, _explore(robot, agent, s)


def summary(results: list[Trial]) -> dict[str, Any]:
    """Goals reached, the median path / shortest over those reached, and each trial (a
    trial that starts at its goal, shortest path 0, has no ratio)."""
    ratios = [t.path_m / t.shortest_m for t in results if t.reached and t.shortest_m > 0]
    return {
        "reached": sum(t.reached for t in results),
        "goals": len(results),
        "median_path_ratio": round(float(np.median(ratios)), 2) if ratios else None,
        "trials": [
            {
                "goal": t.goal.name,
                "reached": t.reached,
                "path_m": round(t.path_m, 2),
                "shortest_m": round(t.shortest_m, 2),
                "time_s": round(t.time_s, 1),
                "no_route_s": round(t.lost_s, 1),
            }
            for t in results
        ],
    }


def _goal_memory(ctx: ExperimentContext) -> Report:
    s = QUICK if ctx.quick else FULL
    office = build_office(s.plan, seed=ctx.seed)
    per: dict[str, Any] = {}
    figures: list[str] = []
    for label, dims in s.matrices:
        t0 = time.perf_counter()
        robot, agent, goals = goal_memory_explore(office, s, dims, ctx.seed)
        pc, truth = robot.slam.pc_log(), robot.trajectory()
        hit, cells = collisions(pc[:, :2], truth[:, :2], COLLISION_M)
        gm = agent.memory
        start_cell = gm.cell_of(pc[0, :2])
        reach = np.isfinite(gm.temporal_map(start_cell).times)
        tag = "small" if label == s.matrices[-1][0] else "large"
        plot_pc_path(
            pc,
            dims,
            f"Packet path, {dims[0]}x{dims[1]}x36: {hit} of {cells} cells collide",
            ctx.out / f"fig3_pc_path_{tag}.png",
        )
        plot_goal_memory(
            gm.temporal_map(start_cell).times,
            dims,
            f"Goal memory's temporal map from the start, {dims[0]}x{dims[1]}x36",
            ctx.out / f"fig4_goal_memory_{tag}.png",
            "time from the start's cell (s)",
        )
        figures += [f"fig3_pc_path_{tag}.png", f"fig4_goal_memory_{tag}.png"]
        gm_results = [agent.navigate(g) for g in goals]
        _, _, _, em_results, _, _ = _recall(office, s, dims, PAPER_MAP, ctx.seed)
        per[label] = {
            "pc_dims": [dims[0], dims[1], 36],
            "cells_visited": cells,
            "cells_colliding": hit,
            "packet_jumps": gm.jumps,
            "goal_memory_links": gm.num_links,
            "cells_reachable_from_start": int(reach.sum()),
            "goal_memory": summary(gm_results),
            "experience_map": summary(em_results),
            "wall_s": round(time.perf_counter() - t0, 1),
        }
    labels = [m for m, _ in s.matrices]

    def count(m: str, system: str) -> str:
        return f"{per[m][system]['reached']}/{per[m][system]['goals']}"

    rows = [
        *[
            Row(
                f"goals reached by goal memory ({m} matrix)",
                "unreliable" if m == labels[-1] else None,
                count(m, "goal_memory"),
            )
            for m in labels
        ],
        *[
            Row(
                f"goals reached by the experience map ({m} matrix)",
                None,
                count(m, "experience_map"),
            )
            for m in labels
        ],
        *[
            Row(
                f"median path / shortest, goal memory / experience map ({m} matrix)",
                None,
                f"{per[m]['goal_memory']['median_path_ratio']} / "
                f"{per[m]['experience_map']['median_path_ratio']}",
            )
            for m in labels
        ],
        *[
            Row(
                f"cells standing for places over {COLLISION_M:g} m apart ({m} matrix)",
                "many" if m == labels[-1] else None,
                f"{per[m]['cells_colliding']} of {per[m]['cells_visited']}",
            )
            for m in labels
        ],
        *[
            Row(
                f"packet jumps between non-neighbouring cells ({m} matrix)",
                None,
                per[m]["packet_jumps"],
            )
            for m in labels
        ],
    ]
    diffs = (
        "Goal memory as this project reads the paper's one paragraph and its reference [6]: "
        "a copy of the pose cells' (x', y') plane; a change of the packet's cell to a "
        "neighbouring cell learns a timed link, a jump learns nothing; the temporal map "
        "spreads from the robot's cell, the route is the chain of cells to the goal's, "
        "followed by the same arbitration as the experience map's (its cells' centres in "
        "the pose cells' own frame). The paper shows goal memory's failure as a temporal map "
        "(Fig. 4) and in words; it gives no goal count for it, so its cells are words.",
        "Both systems start from the same exploration (same seed and calls); goal memory's "
        "goals are the packet's cells where the robot passed nearest the places; a goal "
        "memory trial ends when the packet is in the goal's cell or a neighbour.",
        f"A collision is a cell whose frames' true places spread over more than "
        f"{COLLISION_M:g} m (the diagonal of the box round them).",
    )
    return Report(
        experiment="edge/goal-memory",
        paper=PAPER,
        title="Goal memory, the paper's baseline, beside the experience map",
        rows=tuple(rows),
        figures=tuple(figures),
        differences=diffs,
        details={"matrices": per, "collision_m": COLLISION_M},
        quick=ctx.quick,
        seed=ctx.seed,
    )


EXPERIMENTS: tuple[Experiment, ...] = (
    Experiment(
        "edge/goal-memory",
        "Goal memory (the paper's baseline) beside the experience map (Section II, Figs. 3-4)",
        _goal_memory,
    ),
)
