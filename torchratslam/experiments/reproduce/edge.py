"""The experience-map paper's experiments (Sections V and VI) on the simulated office.

``edge/goal-recall``: explore while mapping with RatSLAM, then navigate to six goals,
once with each pose-cell matrix. ``edge/adaptation``: explore, block the best route,
navigate twice, remove the obstacle, explore, navigate again; links are deleted by
Eq. 9 fed with the executed behaviours and relearnt when the path is driven again.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from torchratslam.experiments.reproduce.report import Experiment, ExperimentContext, Report, Row
from torchratslam.navigation.agent import Goal, NavigationAgent, Trial
from torchratslam.navigation.params import NavParams, office_config
from torchratslam.navigation.planner import plan_route
from torchratslam.navigation.plots import (
    plot_experience_map,
    plot_pc_path,
    plot_temporal_map,
    plot_trial_on_floor,
)
from torchratslam.navigation.robot import MappingRobot
from torchratslam.sim.office.builder import build_office
from torchratslam.sim.office.plan import OFFICE_FLOOR, SMALL_FLOOR, FloorPlan

__all__ = ["EXPERIMENTS"]

PAPER = "edge"


@dataclass(frozen=True)
class _Setup:
    plan: FloorPlan
    matrices: tuple[tuple[str, int], ...]
    goals: tuple[str, ...]
    explore_s: float
    max_explore_s: float
    obstacle: tuple[float, float, float, float]
    start: str
    goal: str
    reexplore_s: float


FULL = _Setup(
    plan=OFFICE_FLOOR,
    matrices=(("100x40x36", 64), ("40x20x36", 28)),
    goals=("E", "H", "W", "X", "C", "A"),
    explore_s=500.0,
    max_explore_s=1200.0,
    obstacle=(19.5, 2.0, 0.6, 1.8),
    start="B",
    goal="D",
    reexplore_s=300.0,
)
QUICK = _Setup(
    plan=SMALL_FLOOR,
    matrices=(("100x40x36", 16), ("40x20x36", 10)),
    goals=("C", "E"),
    explore_s=150.0,
    max_explore_s=200.0,
    obstacle=(8.5, 1.0, 0.4, 1.6),
    start="A",
    goal="C",
    reexplore_s=60.0,
)


def _edge_crossings(pc: np.ndarray, dim: int) -> int:
    """Frames where the packet crossed the matrix's x' or y' edge."""
    d = np.abs(np.diff(np.asarray(pc, np.float64)[:, :2], axis=0))
    return int(((d > dim / 2) & (d < dim)).any(axis=1).sum())


def _explore_to_goals(robot: MappingRobot, agent: NavigationAgent, s: _Setup) -> list[Goal]:
    robot.explore(s.explore_s)
    while True:
        try:
            return [agent.mark_goal(g) for g in s.goals]
        except Exception:
            if robot.time >= s.max_explore_s:
                raise
            robot.explore(50.0)


def _goal_recall(ctx: ExperimentContext) -> Report:
    s = QUICK if ctx.quick else FULL
    office = build_office(s.plan, seed=ctx.seed)
    trials: list[dict[str, Any]] = []
    rows: list[Row] = []
    figures: list[str] = []
    per: dict[str, Any] = {}
    fig12 = None
    for label, xy in s.matrices:
        t0 = time.perf_counter()
        robot = MappingRobot(office_config(xy), office=office, seed=ctx.seed)
        agent = NavigationAgent(robot)
        goals = _explore_to_goals(robot, agent, s)
        explored_s = robot.time
        n_explore = len(robot.slam.experience_map)
        results: list[Trial] = []
        for g in goals:
            results.append(agent.navigate(g))
        for k, tr in enumerate(results):
            trials.append(
                {
                    "matrix": label,
                    "goal": k + 1,
                    "reached": tr.reached,
                    "path_m": round(tr.path_m, 2),
                    "shortest_m": round(tr.shortest_m, 2),
                    "time_s": round(tr.time_s, 1),
                }
            )
        em = agent.em
        pc = robot.slam.pc_log()
        ms = [m for tr in results for m in tr.planning_ms]
        per[label] = {
            "pc_dims": [xy, xy, 36],
            "explore_s": round(explored_s, 1),
            "experiences_created": len(em),
            "experiences_after_exploration": n_explore,
            "links": em.num_links,
            "links_deleted": robot.links.deleted,
            "links_relearnt": robot.links.relearnt,
            "pose_cell_wraps_crossed": _edge_crossings(pc, xy),
            "temporal_map_ms": round(float(np.median(ms)), 2) if ms else None,
            "ate_m": robot.slam.ate(),
            "dead_reckoning_ate_m": robot.slam.dead_reckoning_ate(),
            "wall_s": round(time.perf_counter() - t0, 1),
        }
        tag = "fig8" if label == s.matrices[0][0] else "fig9"
        plot_pc_path(
            pc,
            xy,
            f"Packet path, {xy}x{xy}x36 (for the paper's {label})",
            ctx.out / f"{tag}_pc_path.png",
        )
        tag2 = "fig10" if tag == "fig8" else "fig11"
        plot_experience_map(
            em, f"Experience map, {xy}x{xy}x36 pose cells", ctx.out / f"{tag2}_experience_map.png"
        )
        figures += [f"{tag}_pc_path.png", f"{tag2}_experience_map.png"]
        if len(goals) >= 2:
            fig12 = (robot, agent, goals)
    if fig12 is not None:  # a temporal map between two goals (Fig. 12: goal 4 to goal 5)
        robot, agent, goals = fig12
        plan = plan_route(agent.em, goals[-1].exp)
        route = plan.route.ids if plan.route is not None else []
        plot_temporal_map(
            agent.em,
            plan.tmap.times,
            route,
            f"Temporal map to goal {len(goals)} from the last goal",
            ctx.out / "fig12_temporal_map.png",
        )
        figures.append("fig12_temporal_map.png")
    n_ok = sum(t["reached"] for t in trials)
    ratios = [t["path_m"] / max(t["shortest_m"], 1e-9) for t in trials if t["reached"]]
    labels = [m for m, _ in s.matrices]
    rows = [
        Row(
            "trials reaching the goal",
            f"{2 * len(s.goals)}/{2 * len(s.goals)}" if not ctx.quick else None,
            f"{n_ok}/{len(trials)}",
        ),
        *[
            Row(f"experiences created ({m} matrix)", 5900, per[m]["experiences_created"])
            for m in labels
        ],
        *[
            Row(f"exploration time ({m} matrix)", 70, round(per[m]["explore_s"] / 60, 1), "min")
            for m in labels
        ],
        *[
            Row(f"temporal map, median ({m} matrix)", 10, per[m]["temporal_map_ms"], "ms")
            for m in labels
        ],
        *[
            Row(f"pose-cell wraps crossed ({m} matrix)", None, per[m]["pose_cell_wraps_crossed"])
            for m in labels
        ],
        Row(
            "median path / shortest path (reached)",
            None,
            round(float(np.median(ratios)), 2) if ratios else None,
        ),
    ]
    diffs = (
        "The pose-cell network is square in (x', y'): the 100x40x36 matrix is replaced by "
        f"{s.matrices[0][1]}x{s.matrices[0][1]}x36 and 40x20x36 by {s.matrices[1][1]}x"
        f"{s.matrices[1][1]}x36 (the nearest square with about as many cells), 0.25 m "
        "cells as the paper's, so the network spans "
        f"{s.matrices[0][1] / 4:g} x {s.matrices[0][1] / 4:g} m and "
        f"{s.matrices[1][1] / 4:g} x {s.matrices[1][1] / 4:g} m (the paper's 25 x 10 m and "
        "10 x 5 m).",
        "A simulated office floor (torchratslam.sim.office) replaces the real building; "
        "exploration runs minutes, not 70 minutes, so far fewer experiences are created.",
        "Goals are floor-plan places marked during exploration (the experience current when the "
        "robot passed nearest); a trial succeeds when the robot believes it has arrived and the "
        f"ground truth is then within {agent.params.reach_m} m of the goal.",
        "The temporal map is seeded at the current experience and the experiences overlapping "
        "it in the map (within 1 m), and the goal is reached at any experience overlapping the "
        "goal experience: multiple representations of a place are grouped as in the paper's map. "
        "Links are followed the way they were driven (a route is a chain of executed behaviours); "
        "the paper's links are traversable both ways.",
        "Temporal-map times are this implementation's on a shared CPU (a Dijkstra over the "
        "links, compiled with numba); the paper's 10 ms was on a 1.1 GHz Pentium III with "
        "about 5900 experiences.",
    )
    return Report(
        experiment="edge/goal-recall",
        paper=PAPER,
        title="Goal recall on the experience map with two pose-cell matrix sizes",
        rows=tuple(rows),
        figures=tuple(figures),
        differences=diffs,
        details={"trials": trials, "matrices": per},
        quick=ctx.quick,
        seed=ctx.seed,
    )


def _near(xy: np.ndarray, box: tuple[float, float, float, float], r: float) -> bool:
    return bool(len(xy) and (np.hypot(xy[:, 0] - box[0], xy[:, 1] - box[1]) <= r).any())


def _adaptation(ctx: ExperimentContext) -> Report:
    s = QUICK if ctx.quick else FULL
    office = build_office(s.plan, seed=ctx.seed)
    _, xy = s.matrices[0]
    robot = MappingRobot(office_config(xy), office=office, seed=ctx.seed)
    agent = NavigationAgent(robot, NavParams(junction_turns=True))
    robot.explore(s.explore_s)
    while True:
        try:
            agent.mark_goal(s.start)  # the robot has been at both places
            goal = agent.mark_goal(s.goal)
            break
        except Exception:
            if robot.time >= s.max_explore_s:
                raise
            robot.explore(50.0)
    box = s.obstacle
    reach = max(box[2], box[3]) / 2 + 1.0
    rows_t: list[dict[str, Any]] = []
    figures: list[str] = []
    oid = -1
    for k in (1, 2, 3):
        if k == 3:  # the path is open again: driven along it both ways, then exploration
            robot.sim.remove_obstacle(oid)
            robot.drive_to(s.start)
            robot.drive_to(s.goal)
            robot.explore(s.reexplore_s)
        robot.drive_to(s.start)  # back to the start, steered round the obstacle
        if k == 1:
            oid = robot.sim.place_obstacle(*box)
        tr = agent.navigate(goal)
        rows_t.append(
            {
                "trial": k,
                "planned_through_obstacle": _near(tr.routes_xy, box, reach),
                "reached": tr.reached,
                "links_deleted": tr.deleted,
                "links_relearned": tr.relearnt,
                "route": "short" if _near(tr.path_xy, box, 0.5) else "long",
                "path_m": round(tr.path_m, 2),
                "shortest_m": round(tr.shortest_m, 2),
                "time_s": round(tr.time_s, 1),
            }
        )
        name = f"fig{13 + k}_trial{k}.png"
        plot_trial_on_floor(
            office,
            tr.routes_xy,
            tr.path_xy,
            f"Trial {k}: planned route and path driven",
            ctx.out / name,
            box if k < 3 else None,
        )
        figures.append(name)
    t1, t2, t3 = rows_t
    rows = (
        Row("trial 1 planned through the obstacle", "yes", t1["planned_through_obstacle"]),
        Row("trial 1 links deleted near the obstacle", "yes", t1["links_deleted"]),
        Row(
            "trial 1 goal reached by the other route",
            "yes",
            t1["reached"] and t1["route"] == "long",
        ),
        Row("trial 2 planned the long route at once", "yes", not t2["planned_through_obstacle"]),
        Row("trial 2 goal reached", "yes", t2["reached"]),
        Row(
            "trial 3 took the short route after re-exploration",
            "yes",
            t3["reached"] and t3["route"] == "short",
        ),
        Row("trial 3 links relearnt (since trial 2)", None, t3["links_relearned"]),
    )
    diffs = (
        f"Pose cells {xy}x{xy}x36 (square; see edge/goal-recall) on the simulated office.",
        "Links are deleted when their Eq. 9 confidence falls below 0.5; transitions are "
        "labelled with the executed behaviour (follow, branch near a junction, a deliberate "
        "turn-around); a turn forced by obstacle avoidance keeps the label the robot moved "
        "with, so it counts as a failure of the link it was following, and also of the links "
        "of the experiences overlapping the robot's place facing its way (the planner treats "
        "them as where it is).",
        "Routes follow links the way they were driven (a chain of executed behaviours), and may "
        "turn at a junction onto another representation of it (within 1 m, facing a crossing "
        "way; never two turns in a row, never a turn-around), so a blocked corridor is not "
        "bypassed by turning; arbitration compares the local paths with the route's shape "
        "from the robot on (each turn closed up), as the map can hold a junction's "
        "representations metres apart.",
        "Before every trial the robot is steered back to the start the shortest way round the "
        "obstacle (ground truth, as by an operator; mapped, not counted). After the removal it "
        "is steered along the open path both ways, then explores; the paper's robot explored "
        "for 20 and 6 minutes.",
    )
    return Report(
        experiment="edge/adaptation",
        paper=PAPER,
        title="Adapting the experience map to an obstacle placed and removed",
        rows=rows,
        figures=tuple(figures),
        differences=diffs,
        details={
            "trials": rows_t,
            "obstacle": list(box),
            "links_deleted_total": robot.links.deleted,
            "links_relearnt_total": robot.links.relearnt,
        },
        quick=ctx.quick,
        seed=ctx.seed,
    )


EXPERIMENTS: tuple[Experiment, ...] = (
    Experiment(
        "edge/goal-recall",
        "Goal recall with an overloaded pose-cell matrix (Section V)",
        _goal_recall,
    ),
    Experiment(
        "edge/adaptation", "Experience-map adaptation to an obstacle (Section VI)", _adaptation
    ),
)
