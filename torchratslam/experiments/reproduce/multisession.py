"""The multisession paper's experiments (Section 5) as ``torchratslam reproduce`` runs.

Each experiment maps a simulated tour like the paper's dataset with the shipped config
(the paper's Table 1, unmodified), session by session
(:func:`~torchratslam.experiments.multisession_tour.run_tour`), and reports the paper's
numbers beside ours:

* ``multisession/virtual-tour`` (Figs. 5, 9, 10) and ``multisession/lab-tour`` (Figs. 6,
  13, 14): with visual odometry (Table 1's, as the paper; the full versions drive the
  tours as it can measure, :data:`VO_TOUR_OPTIONS`, and add the recommended merge beside
  the paper's) and with the simulator's wheel odometry;
* ``multisession/irat`` (Figs. 7, 15, 16): five sessions, the fifth merging four maps;
* ``multisession/new-college`` (Figs. 8, 17, 18): three sessions, the third merging two
  stored maps;
* ``multisession/ablation`` (Fig. 12): the merge without the pose-cell shift;
* ``multisession/pose-cells`` (Fig. 11): the pose-cell associations before and after the
  merge.

The paper's merge (the authors' code) is used throughout; ``details`` holds every
report. The full virtual tour also maps the held-out seeds :data:`HELD_OUT_SEEDS` with
the recommended merge and reports their table. ``--quick`` runs a few dozen frames per
session (the merges still happen) and no held-out seeds.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from ratslam_graph.geometry import pc_distance
from torchratslam.config import RatSLAMConfig, load_config
from torchratslam.eval.icp import PAPER_ICP_MSE_M2
from torchratslam.experiments.multisession_seeds import (
    RECOMMENDED_MERGE_OPTIONS,
    RECOMMENDED_SESSION_OPTIONS,
    WRONG_PLACE_M,
    merge_distances,
    seed_table,
)
from torchratslam.experiments.multisession_tour import TOUR_CONFIG, run_tour
from torchratslam.experiments.reproduce.report import (
    Experiment,
    ExperimentContext,
    Report,
    Row,
)
from torchratslam.maps.state import PC_BEST, MapState

__all__ = [
    "EXPERIMENTS",
    "HELD_OUT_SEEDS",
    "PAPER_ODOMETRY",
    "QUICK_FRAMES",
    "held_out_rows",
    "tour_rows",
]

PAPER = "multisession"

PAPER_ODOMETRY = {
    "virtual_tour": "visual",
    "lab_tour": "visual",
    "irat_like": "wheel",
    "new_college": "wheel",
}
"""The odometry each of the paper's experiments used (Section 4: Table 1's visual
odometry for the Virtual and Lab Tours; the robots' wheel encoders for iRat and New
College)."""

QUICK_FRAMES = {
    "virtual_tour": 45,
    "lab_tour": 45,
    "irat_like": 10_000,  # whole sessions, at QUICK_TOUR_OPTIONS' frame rate
    "new_college": 130,
    "ablation": 175,
}
"""Frames per session of the ``--quick`` versions (each still reaches its merges)."""

_SIMULATED = (
    "The paper's datasets (videos of its virtual world, the RoboDeck lab, the iRat and "
    "New College recordings) are not available here: the tour is the simulator's "
    "stand-in with the same sessions (routes, laps, starts, camera), so counts and "
    "ICP figures compare in kind and units, not in value."
)


def _config(tour: str) -> RatSLAMConfig:
    return load_config(TOUR_CONFIG.get(tour, tour))


def _frames(ctx: ExperimentContext, key: str) -> int | None:
    return QUICK_FRAMES[key] if ctx.quick else None


QUICK_TOUR_OPTIONS: dict[str, dict[str, Any]] = {"irat_like": {"hz": 2.5}}
"""Tour options of the ``--quick`` versions whose merges lie too far into the sessions
for a frame limit (iRat: session 5 meets block 1 where session 1 ends its lap; at 2.5 Hz
instead of 10 every session has a quarter of the frames)."""


VO_TOUR_OPTIONS: dict[str, dict[str, Any]] = {
    "virtual_tour": {"frames_per_lap": 900},
    "lab_tour": {"speed": 0.03, "arc_points": 96},
}
"""Tour options of the full versions of the tours the paper mapped with Table 1's visual
odometry, so that the robot moves as that odometry can measure: Table 1 gives
``camera_hz`` 1 and ``vtrans_max`` 0.1 m/s, so a frame may cover at most 0.1 m, and the
rotation profile is searched 40 columns either way (3.1 degrees a frame for the Lab
Tour's 640-pixel, 50-degree camera). The virtual tour at 900 frames a lap (0.067 m a
frame, 1 Hz); the lab tour at 0.03 m/s (1 Hz) with its corner arcs drawn through 96
points (2.9 degrees a frame on a 0.6 m corner, in 0.9-degree steps; 24 points turned in
3.9-degree steps, beyond the search). Chosen on seed 0 (the first 300-900 frames of
each session); wheel odometry runs the same tour."""


def _run(ctx: ExperimentContext, tour_name: str, odometry: str, **kw: Any) -> dict[str, Any]:
    """:func:`run_tour` on the tour with its shipped config; ``odometry`` "visual"
    (Table 1's visual odometry from the images) or "wheel" (the simulator's noisy
    odometry)."""
    from torchratslam.sim import get_tour

    options = QUICK_TOUR_OPTIONS.get(tour_name, {}) if ctx.quick else {}
    if not ctx.quick:
        options = {**options, **VO_TOUR_OPTIONS.get(tour_name, {})}
    tour = get_tour(tour_name, seed=ctx.seed, **options)
    if odometry == "visual":
        kw["odometry"] = "visual"
    return run_tour(_config(tour_name), tour, **kw)


def _merge_table(result: dict[str, Any]) -> list[dict[str, Any]]:
    """Every merge: session, frame, stored map, match error, ground-truth distance of
    the two experiences it joined (m)."""
    merges = result["data"]["multi"]["merges"]
    dist = merge_distances(merges, result["data"]["groundtruth"])
    return [
        {
            "session": m["session"],
            "frame": m["frame"],
            "map": m["map_name"],
            "scenario": m["scenario"],
            "error": m["error"],
            "distance_m": d,
        }
        for m, d in zip(merges, dist)
    ]


def tour_rows(
    result: dict[str, Any],
    label: str,
    *,
    paper_merges: int | None,
    paper_icp: float | None,
    paper_diff: float | None = None,
) -> list[Row]:
    """The rows of one tour run: counts of the single-session and multisession maps,
    merges, the largest merge distance, the paper's ICP figure."""
    rep = result["report"]
    merges = _merge_table(result)
    worst = max((m["distance_m"] for m in merges), default=float("nan"))
    diff = rep["experiences_difference_relative"]
    return [
        Row(
            f"{label}: experiences, single session (continuous)", None, rep["single"]["experiences"]
        ),
        Row(f"{label}: experiences, multisession", None, rep["multi"]["experiences"]),
        Row(
            f"{label}: experiences, multisession vs single",
            paper_diff,
            None if diff is None else round(100.0 * diff, 1),
            "%",
        ),
        Row(f"{label}: links, multisession", None, rep["multi"]["links"]),
        Row(f"{label}: merges", paper_merges, len(merges)),
        Row(
            f"{label}: one connected map at the end",
            None if paper_merges is None else True,  # the paper's claim, beside its run
            bool(rep["multi"]["connected"]),
        ),
        Row(
            f"{label}: largest merge distance (ground truth)",
            None,
            None if math.isnan(worst) else round(worst, 3),
            "m",
        ),
        Row(
            f"{label}: ICP, LibICP residual (single-session map moved onto the multisession map)",
            paper_icp,
            rep["icp_libicp_mse_m2"],
            "m^2",
        ),
        Row(f"{label}: ATE, multisession map", None, rep["multi"]["ate_rmse_m"], "m"),
        Row(f"{label}: ATE, single-session map", None, rep["single"]["ate_rmse_m"], "m"),
    ]


def _details(result: dict[str, Any]) -> dict[str, Any]:
    rep = dict(result["report"])
    rep["merge_table"] = _merge_table(result)
    return rep


MAIN_FIGURES = ("fig9e_final.png", "fig10_icp.png", "fig9d_after_merge.png")
"""The figures a tour's report lists first (the final map, the ICP overlay, the map just
after the merge); the others follow in the order they are drawn."""


def _figures(result: dict[str, Any], out: Path) -> tuple[str, ...]:
    from torchratslam.viz.multisession import write_figures

    names = [p.name for p in write_figures(result, out)]
    return (*[n for n in MAIN_FIGURES if n in names], *[n for n in names if n not in MAIN_FIGURES])


def _tour_experiment(
    ctx: ExperimentContext,
    exp_id: str,
    title: str,
    tour: str,
    *,
    paper_merges: int,
    odometries: tuple[str, ...],
    differences: tuple[str, ...],
    paper_diff: float | None = None,
) -> Report:
    """One tour, mapped with each odometry; figures of the paper's odometry's run."""
    paper_odo = PAPER_ODOMETRY[tour]
    paper_icp = PAPER_ICP_MSE_M2.get(tour)
    rows: list[Row] = [
        Row("odometry (the paper's; ours: what these rows ran)", paper_odo, ", ".join(odometries)),
    ]
    details: dict[str, Any] = {"tour": tour, "paper_odometry": paper_odo}
    figures: tuple[str, ...] = ()
    runs: list[tuple[str, str, dict[str, Any]]] = [(odo, "", {}) for odo in odometries]
    if not ctx.quick and paper_odo == "visual":  # the recommended merge beside the paper's
        runs.insert(
            1,
            (
                paper_odo,
                "recommended",
                {
                    "merge_options": RECOMMENDED_MERGE_OPTIONS,
                    "session_options": RECOMMENDED_SESSION_OPTIONS,
                },
            ),
        )
    for odo, merge, kw in runs:
        result = _run(ctx, tour, odo, max_frames=_frames(ctx, tour), **kw)
        ours_paper = odo == paper_odo and not merge
        label = (
            f"{odo} odometry"
            + (" (the paper's)" if odo == paper_odo else "")
            + (", recommended merge" if merge else "")
        )
        rows += tour_rows(
            result,
            label,
            paper_merges=paper_merges if ours_paper else None,
            paper_icp=paper_icp if ours_paper else None,
            paper_diff=paper_diff if ours_paper else None,
        )
        vo = result["report"].get("visual_odometry")
        if vo:
            rows += _vo_rows(vo, label)
        details[odo + (f" {merge} merge" if merge else "")] = _details(result)
        if ours_paper:
            figures = _figures(result, ctx.out)
    if paper_odo == "visual":
        differences = (_visual_note(ctx.quick), *differences)
        if not ctx.quick:
            differences += (
                "The recommended merge (the rotated pose-cell shift, a match confirmed by "
                "the next new template, the earlier matching templates absorbed) runs "
                "beside the paper's with the paper's visual odometry; the paper's figures "
                "stand beside the paper's merge only."
                + (
                    " This run's seed is the one the tour settings were chosen on."
                    if ctx.seed == 0
                    else f" Seed {ctx.seed} was not used to choose anything."
                ),
            )
    return Report(
        experiment=exp_id,
        paper=PAPER,
        title=title,
        rows=tuple(rows),
        figures=figures,
        differences=(_SIMULATED, *differences),
        details=details,
        quick=ctx.quick,
        seed=ctx.seed,
    )


def _vo_rows(vo: dict[str, Any], label: str) -> list[Row]:
    """The visual odometry's limits and scale over the continuous run."""
    rows = [
        Row(
            f"{label}: frames at vtrans_max / at the rotation search limit (continuous run)",
            None,
            f"{100 * vo['vtrans_max']:.1f}% / {100 * vo['vrot_limit']:.1f}% of {vo['frames']}",
        )
    ]
    if "true_mean_translation_m" in vo:
        rows.append(
            Row(
                f"{label}: translation per frame, visual odometry / ground truth (mean)",
                None,
                f"{vo['mean_translation_m']:.4f} / {vo['true_mean_translation_m']:.4f} m",
            )
        )
    return rows


def _visual_note(quick: bool) -> str:
    if quick:
        return (
            "Quick version: the tour at its default speed (0.25-0.4 m a frame), which "
            "Table 1's visual odometry cannot measure (at most 0.1 m a frame): it sits on "
            "vtrans_max (the limit rows) and its map shrinks; the full version drives the "
            "tour as that odometry can measure (VO_TOUR_OPTIONS)."
        )
    return (
        "Visual odometry uses Table 1's parameters unchanged (vtrans_scaling 10, vtrans_max "
        "0.1 m/s, camera_hz 1): the tour is driven so that they can measure it (the "
        "virtual tour at 900 frames a lap, 0.067 m a frame; the lab tour at 0.03 m/s with "
        "corner arcs turning at most 2.9 degrees a frame, inside the 40-column rotation "
        "search), settings chosen on seed 0; the limit rows give how often it was clamped "
        "all the same. The scale rows compare its translation with the ground truth's: "
        "the virtual tour's smooth textures change the intensity profile less than the "
        "lab's per metre, so with vtrans_scaling 10 it reads about half the distance. "
        "Wheel-odometry rows: the same tour with the simulator's noisy odometry."
    )


HELD_OUT_SEEDS = tuple(range(4000, 4010))
"""Virtual-tour seeds on which nothing was chosen: seeds 0-19 chose the recommended merge,
20-39, 1000-1009 and 3000-3009 were used to find why it missed; these were run once,
after the last change (docs/multisession.md, "Held-out seeds")."""


def held_out_rows(table: dict[str, Any]) -> list[Row]:
    """The held-out seed table as rows: per seed the recommended merge's experiences
    against the continuous single session's (the paper: "the same") and the largest merge
    distance; then the seeds within one experience and the merges more than
    :data:`WRONG_PLACE_M` off.

    Args:
        table: a :func:`~torchratslam.experiments.multisession_seeds.seed_table` result.
    """
    rows: list[Row] = []
    for seed in table["seeds"]:
        r = table["rows"][seed]
        worst = max((m["distance_m"] for m in r["merges"]), default=float("nan"))
        rows += [
            Row(
                f"seed {seed}: experiences, recommended merge / continuous single session",
                "the same",
                f"{r['multi']} / {r['single']}",
            ),
            Row(
                f"seed {seed}: largest merge distance (ground truth)",
                None,
                None if math.isnan(worst) else round(worst, 2),
                "m",
            ),
        ]
    n = len(table["seeds"])
    rows += [
        Row(
            "held-out seeds within one experience of the continuous single session",
            f"{n}/{n} (the same number)",
            f"{table['within_one']}/{n}",
        ),
        Row(
            f"held-out seeds: merges more than {WRONG_PLACE_M:g} m off (ground truth)",
            0,
            table["wrong_merges"],
        ),
    ]
    if "ablation_above" in table:
        rows.append(
            Row(
                "held-out seeds: without the pose-cell shift at least 10% more experiences",
                "more",
                f"{table['ablation_above']}/{n} (the partial map allows it on "
                f"{table['ablation_reachable']}/{n})",
            )
        )
    return rows


def _virtual_tour(ctx: ExperimentContext) -> Report:
    report = _virtual_tour_runs(ctx)
    if ctx.quick:
        return report
    table = seed_table(
        "sim:virtual_tour",
        HELD_OUT_SEEDS,
        merge_options=RECOMMENDED_MERGE_OPTIONS,
        **RECOMMENDED_SESSION_OPTIONS,
    )
    note = (
        f"Held-out seeds {HELD_OUT_SEEDS[0]}-{HELD_OUT_SEEDS[-1]} (wheel odometry, the "
        "recommended merge: the rotated pose-cell shift, a match confirmed by the next new "
        "template, the maps joined where the view matches best (the frames passed since "
        "the first match included), the earlier matching templates absorbed): "
        "the paper ran one tour; these seeds were run once, after the recommended merge "
        "was final (chosen on seeds 0-19, its misses traced on 20-39, 1000-1009 and "
        "3000-3009). A count one off is the 2% granularity of a 30-50-experience map; the "
        "per-seed table is in details['held_out_seeds'], and why seeds can miss (either "
        "map re-making places where its packet arrives just over exp_delta_pc_threshold "
        "from a lap earlier) in docs/multisession.md, 'Held-out seeds'."
    )
    return dataclasses.replace(
        report,
        rows=(*report.rows, *held_out_rows(table)),
        differences=(*report.differences, note),
        details={**report.details, "held_out_seeds": table},
    )


def _virtual_tour_runs(ctx: ExperimentContext) -> Report:
    return _tour_experiment(
        ctx,
        "multisession/virtual-tour",
        "Virtual Tour: two sessions on an ellipse, merged (Figs. 5, 9, 10)",
        "virtual_tour",
        paper_merges=1,
        odometries=("visual", "wheel"),
        paper_diff=0.0,  # "the number of EM nodes in the single and multiple sessions is the same"
        differences=(
            "The paper's second session replays the first session's video after the "
            "merge point, frame for frame; the simulator renders the same poses, but "
            "its odometry noise differs between the sessions.",
            "The paper reports no experience or link counts, only that the single and "
            "multisession maps have the same number of experiences; the rows give ours.",
        ),
    )


def _lab_tour(ctx: ExperimentContext) -> Report:
    return _tour_experiment(
        ctx,
        "multisession/lab-tour",
        "Lab Tour: a figure-eight lab mapped in two sessions (Figs. 6, 13, 14)",
        "lab_tour",
        paper_merges=1,
        odometries=("visual", "wheel"),
        differences=(
            "The RoboDeck's lab is a simulated room with desks inside two rectangles; "
            "the robot drives the paper's laps (two of the small rectangle, 1.9 of the "
            "large one) with a 640x480 forward camera.",
        ),
    )


def _irat(ctx: ExperimentContext) -> Report:
    return _tour_experiment(
        ctx,
        "multisession/irat",
        "iRat: five sessions, the fifth merging four stored maps (Figs. 7, 15, 16)",
        "irat_like",
        paper_merges=4,
        odometries=("wheel",),
        differences=(
            "irat_like is an iRat-scale road network (2 x 2 blocks, 2.4 x 1.6 m): "
            "sessions 1-4 lap one block each, session 5 the outer loop joining them.",
            "The continuous single session drives between the sessions along the roads "
            "(the paper's continuous run follows the robot's own route), so it maps "
            "views no session sees.",
            "--quick: the tour at 2.5 Hz instead of 10 (a quarter of the frames, whole "
            "sessions), so its counts are not the full tour's.",
        ),
    )


# ------------------------------------------------------------------ New College
def _new_college(ctx: ExperimentContext) -> Report:
    result = _run(ctx, "new_college", "wheel", max_frames=_frames(ctx, "new_college"))
    merges = _merge_table(result)
    rows = [
        Row("odometry (the paper's; ours: what these rows ran)", "wheel", "wheel"),
        Row("sessions", 3, len(result["report"]["sessions"])),
        *tour_rows(
            result, "wheel odometry", paper_merges=2, paper_icp=PAPER_ICP_MSE_M2["new_college"]
        ),
    ]
    for i, m in enumerate(merges):
        rows.append(
            Row(
                f"merge {i + 1}: {m['session']} frame {m['frame']} with {m['map']}, "
                "distance between the joined experiences",
                None,
                None if math.isnan(m["distance_m"]) else round(m["distance_m"], 3),
                "m",
            )
        )
    return Report(
        experiment="multisession/new-college",
        paper=PAPER,
        title="New College: three sessions, the third merging two stored maps (Figs. 8, 17, 18)",
        rows=tuple(rows),
        figures=_figures(result, ctx.out),
        differences=(
            _SIMULATED,
            "new_college is a small campus (two 24 x 16 m quads joined by a lane, 0.5 m "
            "per frame, panoramic 256x64 images, smooth textures) instead of the "
            "Oxford college's 2.2 km of recordings; sessions 1 and 2 lap one quad each, "
            "session 3 starts at a known place of session 1's map (the paper's yellow "
            "cross) and drives through the north lane into session 2's quad. Every session "
            "drives clockwise: the paper's third session drives counter-clockwise, but on "
            "the simulator a place seen the other way round differs by 0.09 (at the best "
            "turn) against the 0.059 threshold, and would never merge.",
            "The paper's ICP figure (85.47 m^2) comes from a map bent by an inconsistent "
            "correction after its second merge over a far larger area; ours is for a "
            "map a few tens of metres across.",
            "The continuous single session has about twice the experiences and a worse map "
            "(measured, seed 0): on its drive from session 1 to session 2 it recognises "
            "an old view turned by 60 degrees, and OpenRatSLAM's pose cells keep that "
            "view's angle (vt_delta_pc_th, -5.83 cells) until the next view older than "
            "the ten newest is injected, a lap later; meanwhile every frame's packet is "
            "compared with the experiences 5.83 cells off in theta (the threshold is 4), "
            "so every frame of session 2's first lap makes an experience (149 in 150 "
            "frames, 87 when session 2 is mapped alone). The multisession run starts "
            "each session afresh and does not meet it.",
        ),
        details={"report": _details(result)},
        quick=ctx.quick,
        seed=ctx.seed,
    )


# ------------------------------------------------------------------ Fig. 12
def _ablation(ctx: ExperimentContext) -> Report:
    result = _run(ctx, "virtual_tour", "wheel", ablation=True, max_frames=_frames(ctx, "ablation"))
    rep = result["report"]
    multi, abl = rep["multi"], rep["ablation_no_pc_shift"]
    single = rep["single"]["experiences"]
    extra = abl["experiences"] - multi["experiences"]
    rows = (
        Row("experiences, single session (continuous)", None, single),
        Row("experiences, multisession with the pose-cell shift", None, multi["experiences"]),
        Row("experiences, multisession without the pose-cell shift", None, abl["experiences"]),
        Row(
            "new experiences without the shift (the paper: 'new experiences were created')",
            "more",
            extra,
        ),
        Row("links, with / without the shift", None, f"{multi['links']} / {abl['links']}"),
        Row("ATE with the shift", None, multi["ate_rmse_m"], "m"),
        Row("ATE without the shift", None, abl["ate_rmse_m"], "m"),
    )
    figures = tuple(n for n in _figures(result, ctx.out) if n.startswith("fig12"))
    return Report(
        experiment="multisession/ablation",
        paper=PAPER,
        title="Ablation: the merge without shifting the pose cells (Fig. 12)",
        rows=rows,
        figures=figures,
        differences=(
            _SIMULATED,
            "Wheel odometry (the simulator's): the ablation concerns the pose cells, "
            "and visual odometry would add its own scale error.",
            "Without the shift the partial map's views, seen again a lap later, inject "
            "energy where the partial network had them; the robot's packet is elsewhere "
            "and experiences are made again. The partial map holds the 19 frames before "
            "session 1's start, so at most its few experiences can be made again "
            "(docs/multisession.md, 'The ablation's ceiling').",
        ),
        details={"report": rep},
        quick=ctx.quick,
        seed=ctx.seed,
    )


# ------------------------------------------------------------------ Fig. 11
def _layers(state: MapState) -> int:
    """How many heading layers hold a template association (of the network's TH)."""
    if state.n_templates == 0:
        return 0
    th = np.floor(np.asarray(state.template_pc)[:, 2]).astype(np.int64) % int(state.pc_dims[2])
    return int(np.unique(th).size)


def _draw_cells(ax: Any, pcs: np.ndarray, colour: str, label: str, **kw: Any) -> None:
    p = np.asarray(pcs, np.float64).reshape(-1, 3)
    ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=kw.pop("s", 6), color=colour, label=label, **kw)


def _pose_cell_figure(
    single: MapState,
    loaded: MapState,
    partial: MapState,
    merged: MapState,
    final: MapState,
    merge: dict[str, Any],
    path: Path,
) -> None:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from torchratslam.viz.plots import save_figure

    dims = np.asarray(single.pc_dims)
    fig = plt.figure(figsize=(15, 5))
    n_l = loaded.n_templates
    u = int(merge["loaded_template"])
    panels = (
        (
            "a) single session: template associations",
            ((single.template_pc, "tab:purple", "single session"),),
        ),
        (
            "b) before the merge: loaded and partial maps",
            (
                (loaded.template_pc, "tab:blue", "loaded map (session 1)"),
                (partial.template_pc, "gold", "partial map (session 2)"),
            ),
        ),
        (
            "c) after the merge and session 2",
            (
                (final.template_pc[:n_l], "tab:blue", "loaded map's"),
                (merged.template_pc[n_l:], "tab:orange", "partial map's, shifted"),
                (final.template_pc[merged.n_templates :], "tab:green", "learnt after the merge"),
            ),
        ),
    )
    for i, (title, sets) in enumerate(panels):
        ax = fig.add_subplot(1, 3, i + 1, projection="3d")
        for pcs, colour, label in sets:
            _draw_cells(ax, pcs, colour, f"{label} ({len(pcs)})")
        if i == 1:
            _draw_cells(ax, loaded.template_pc[u], "red", "P_u (start of the loaded map)", s=60)
            _draw_cells(ax, partial.template_pc[-1], "black", "P_z (partial map's last)", s=60)
        if i == 2:
            _draw_cells(ax, merged.template_pc[u], "red", "P_u = shifted P_z", s=60)
        ax.set_xlim(0, dims[0])
        ax.set_ylim(0, dims[1])
        ax.set_zlim(0, dims[2])
        ax.set_xlabel("x (cells)")
        ax.set_ylabel("y (cells)")
        ax.set_zlabel("theta (cells)")
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=6, loc="upper left")
    fig.suptitle("Pose-cell network: where templates are associated (Fig. 11)")
    save_figure(fig, path, dpi=90, tight=False)


def _pose_cells(ctx: ExperimentContext) -> Report:
    result = _run(ctx, "virtual_tour", "wheel", max_frames=_frames(ctx, "ablation"))
    data = result["data"]
    multi = data["multi"]
    single: MapState = data["single"]
    loaded: MapState = multi["session_maps"][0]
    final: MapState = multi["maps"][-1]
    dims = int(single.pc_dims[2])
    rows: list[Row] = [
        Row("heading layers used, single session", dims, _layers(single), f"of {dims}"),
        Row(
            "heading layers used, loaded map (3/4 lap; the paper: 'partially filled')",
            None,
            _layers(loaded),
            f"of {dims}",
        ),
        Row("heading layers used, final multisession map", dims, _layers(final), f"of {dims}"),
        Row("merges", 1, len(multi["merges"])),
    ]
    figures: tuple[str, ...] = ()
    details: dict[str, Any] = {"report": result["report"]}
    if multi["snapshots"]:
        snap, merge = multi["snapshots"][0], multi["merges"][0]
        partial: MapState = snap["partial_state"]
        merged: MapState = snap["merged_state"]
        u = int(merge["loaded_template"])
        packet = np.asarray(merged.extra.get(PC_BEST, loaded.template_pc[u]), np.float64)
        gap = pc_distance(packet[None], loaded.template_pc[u], merged.pc_dims)
        shift = np.asarray(merge["pc_shift"], np.float64)
        moved = np.mod(partial.template_pc[:-1] + shift, np.asarray(partial.pc_dims))
        rows += [
            Row(
                "pose-cell shift P_u - P_z (x, y, theta)",
                None,
                str(np.round(shift, 2).tolist()),
                "cells",
            ),
            Row(
                "activity packet after the merge, from P_u",
                0.0,
                round(float(gap[0]), 3),
                "cells",
            ),
            Row(
                "partial associations moved by the shift (all but z)",
                None,
                bool(np.allclose(merged.template_pc[loaded.n_templates :], moved)),
            ),
        ]
        _pose_cell_figure(
            single, loaded, partial, merged, final, merge, ctx.out / "fig11_pose_cells.png"
        )
        figures = ("fig11_pose_cells.png",)
        details["pc_shift"] = shift
    return Report(
        experiment="multisession/pose-cells",
        paper=PAPER,
        title="Pose-cell network before and after the merge (Fig. 11)",
        rows=tuple(rows),
        figures=figures,
        differences=(
            _SIMULATED,
            "The paper draws the activated cells; the figure draws every template's "
            "pose-cell association (the cells the views inject into), which is what the "
            "merge shifts (Eqs. 10-12).",
            "Wheel odometry (the simulator's); with fewer frames (--quick) session 2 "
            "does not complete its lap and fewer layers are used.",
            "Heading layers hold templates, not activity: the virtual tour's maps have "
            "about 37 templates for 35 layers, so the full tour uses 27 of them (measured, "
            "seed 0) where the paper's drawing of activity fills the axis.",
            "The activity packet is moved by whole cells (it keeps its shape), so it lies "
            "up to about 0.87 cells (half a cell on each axis) from P_u after the merge.",
        ),
        details=details,
        quick=ctx.quick,
        seed=ctx.seed,
    )


EXPERIMENTS: tuple[Experiment, ...] = (
    Experiment(
        "multisession/virtual-tour",
        "Virtual Tour, visual and wheel odometry (Figs. 9, 10)",
        _virtual_tour,
    ),
    Experiment(
        "multisession/lab-tour", "Lab Tour, visual and wheel odometry (Figs. 13, 14)", _lab_tour
    ),
    Experiment("multisession/irat", "iRat, five sessions (Figs. 15, 16)", _irat),
    Experiment(
        "multisession/new-college", "New College, three sessions (Figs. 17, 18)", _new_college
    ),
    Experiment("multisession/ablation", "no pose-cell shift (Fig. 12)", _ablation),
    Experiment(
        "multisession/pose-cells", "pose cells before and after a merge (Fig. 11)", _pose_cells
    ),
)
