"""What a dataset run writes to OUT: ``metrics.json``, ``experiences.csv``,
``trajectory.csv``, ``map.png``, ``pose_cells.png``, the saved state, and on request the
TUM trajectories and the scale report; and the line ``torchratslam run`` prints.

A run with stored maps (``--load``) whose maps did not all merge with its own writes
each map that never merged to ``OUT/unmerged/mapK`` (K: its place among the ``--load``
options), says so in a warning and lists it in ``metrics.json`` (``"unmerged"``); the
run's map in ``OUT/state`` holds the merged maps only.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ratslam_graph.atomic import Manifest, atomic_write_text
from torchratslam.experiments import run_state
from torchratslam.experiments.run_state import STATE_DIR, RunRecord, json_default
from torchratslam.protocols import GroundTruthSource

__all__ = [
    "OUTPUT_FILES",
    "SCALE_FILES",
    "TUM_FILES",
    "UNMERGED_DIR",
    "RunExtras",
    "RunMetrics",
    "summary_line",
    "write_outputs",
    "write_scale_report",
    "write_tum",
    "write_unmerged",
]

log = logging.getLogger(__name__)

UNMERGED_DIR = "unmerged"
RUN_ATE_OVER = "the experience current after each frame, at the frame's time"
"""What a run's ATE compares with the ground truth (``compare-maps`` and the multisession
report compare each experience at its creation time: another figure)."""
OUTPUT_FILES = ("metrics.json", "experiences.csv", "trajectory.csv", "map.png", "pose_cells.png")
TUM_FILES = ("tum_experience.txt", "tum_frame.txt", "tum_groundtruth.txt")
SCALE_FILES = ("scale.json", "scale.md", "scale.png")


@dataclass(frozen=True)
class RunExtras:
    """What metrics.json says of a run besides its counts (None: not said).

    Attributes:
        data: the data spec.
        config: the config spec.
        odometry: ``"visual"`` when the run estimated odometry from the images.
        loaded: the stored maps the run localised in.
        resumed_at_frame: the frame a resumed run went on from.
        tum: the TUM files written, by estimate.
        tum_ate_poses: what the TUM ATEs are taken over: their alignment, and per estimate
            the poses matched to ground truth (under 3: that ATE is undefined, None).
        ate_experience_rmse_m: the ATE of ``tum_experience.txt``.
        ate_frame_rmse_m: the ATE of ``tum_frame.txt``.
    """

    data: str
    config: str
    odometry: str | None = None
    loaded: tuple[str, ...] | None = None
    resumed_at_frame: int | None = None
    tum: dict[str, str] | None = None
    tum_ate_poses: dict[str, Any] | None = None
    ate_experience_rmse_m: float | None = None
    ate_frame_rmse_m: float | None = None


@dataclass(frozen=True)
class RunMetrics:
    """A run's metrics: what ``metrics.json`` holds (fields that are None are left out),
    plus the scale report's summary.

    Attributes:
        frames: frames mapped in all (a resumed run counts the first part too).
        frames_this_run: frames this process mapped.
        templates: the map's templates.
        experiences: the map's experiences.
        links: the map's links.
        wall_s: this process's time.
        fps: this process's frames per second, the start-up left out (the frames after
            the first over the time after it).
        startup_s: this process's time to its first frame's result (numba compiling its
            kernels on the first use after installing, caches warming), kept out of
            ``fps``.
        ms_per_frame: per module, mean and median milliseconds per frame.
        pipelined: whether the run used one thread per module.
        backend: the experience map's relaxation backend.
        odometry: the odometry source.
        data: the data spec.
        config: the config spec.
        loaded: the stored maps the run localised in.
        resumed_at_frame: the frame a resumed run went on from.
        tum: the TUM files written, by estimate.
        tum_ate_poses: what the TUM ATEs are taken over: their alignment, and per estimate
            the poses matched to ground truth (under 3: that ATE is undefined, None).
        ate_experience_rmse_m: the ATE of ``tum_experience.txt``.
        ate_frame_rmse_m: the ATE of ``tum_frame.txt``.
        ate_rmse_m: the map's ATE (with ground truth).
        dead_reckoning_ate_m: dead reckoning's ATE (with ground truth).
        ate_frames: the frames with a ground-truth pose, which both ATEs are taken over
            (after a rigid SE(2) alignment); under 3 the ATEs are None (undefined).
        ate_frame_pose_m: the ATE of every frame's pose estimate (the experience current
            after it plus the odometry since), SE(2)-aligned, over the same frames (not
            on a resumed run).
        ate_note: why the map's ATE is above dead reckoning's, measured (None: it is not).
        merges: a multisession run's merges.
        unmerged: the stored maps that never merged with the run's map: per map its
            ``--load`` option (``map``) and where it was written (``written``).
        input_warnings: what the reader found wrong with the input (gaps, repeats or
            backward steps in the frame numbering), one line each.
        partial: True for a run that stopped early.
        stopped_at_frame: the frame a run that stopped early stopped at.
        reason: why a run stopped early.
        scale: the scale report's summary (``last_over_first``, ``peak_memory_mb``);
            not in metrics.json.
    """

    frames: int
    frames_this_run: int
    templates: int
    experiences: int
    links: int
    wall_s: float
    fps: float
    ms_per_frame: dict[str, dict[str, float]]
    pipelined: bool
    backend: str
    odometry: str
    data: str
    config: str
    startup_s: float | None = None
    loaded: tuple[str, ...] | None = None
    resumed_at_frame: int | None = None
    tum: dict[str, str] | None = None
    tum_ate_poses: dict[str, Any] | None = None
    ate_experience_rmse_m: float | None = None
    ate_frame_rmse_m: float | None = None
    ate_rmse_m: float | None = None
    dead_reckoning_ate_m: float | None = None
    merges: Any = None
    unmerged: list[dict[str, str]] | None = None
    ate_frames: int | None = None
    ate_frame_pose_m: float | None = None
    ate_note: str | None = None
    input_warnings: list[str] | None = None
    partial: bool | None = None
    stopped_at_frame: int | None = None
    reason: str | None = None
    scale: dict[str, Any] | None = None

    def to_json(self) -> dict[str, Any]:
        """What metrics.json holds: the fields that are not None, but the scale summary."""
        out = {k: v for k, v in asdict(self).items() if v is not None and k != "scale"}
        if self.ate_frames is not None:  # which ATE this is: the alignment and the poses
            from torchratslam.eval.metrics import ATE_ALIGNMENT

            out["ate_alignment"] = ATE_ALIGNMENT
            out["ate_over"] = RUN_ATE_OVER
        if self.ate_frames is not None and self.ate_rmse_m is None:
            out["ate_rmse_m"] = None  # undefined, and said why
            out["ate_undefined"] = (
                f"{self.ate_frames} frames have both a map pose and ground truth; an ATE needs 3"
            )
        return out


def _csv_text(header: list[str], rows: np.ndarray, int_cols: tuple[int, ...]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for row in rows.tolist():
        w.writerow([int(v) if i in int_cols else repr(float(v)) for i, v in enumerate(row)])
    return buf.getvalue()


def _created_frames(em: Any, n: int) -> np.ndarray:
    """Each experience's creation frame: from the map's arrays where it keeps them (no
    networkx graph built for it), else from its graph (-1 where a node has none)."""
    store = getattr(em, "store", None)
    frame = getattr(store, "frame", None)
    if isinstance(frame, np.ndarray) and getattr(store, "n", None) == n:
        return frame[:n].astype(np.int64)
    g = em.graph
    return np.asarray([int(g.nodes[i].get("frame", -1)) for i in range(n)], dtype=np.int64)


def _links(em: Any) -> np.ndarray:
    if hasattr(em, "links") and callable(em.links):
        lk = em.links()
        return np.stack([lk["src"], lk["dst"]], axis=1).astype(np.int64)
    return np.asarray(list(em.graph.edges()), dtype=np.int64).reshape(-1, 2)


def _write_tables(slam: Any, out: Path) -> tuple[np.ndarray, np.ndarray]:
    """``experiences.csv`` (final poses) and ``trajectory.csv``; returns both arrays."""
    em = slam.experience_map
    poses = np.asarray(em.poses, dtype=np.float64).reshape(-1, 3)
    n = poses.shape[0]
    exp_rows = np.column_stack([np.arange(n), poses, _created_frames(em, n)])
    atomic_write_text(
        out / "experiences.csv",
        _csv_text(["id", "x", "y", "th", "created_frame"], exp_rows, (0, 4)),
    )
    traj = slam.trajectory()
    atomic_write_text(
        out / "trajectory.csv",
        _csv_text(["frame", "t", "experience_id", "x", "y", "th"], traj, (0, 2)),
    )
    return poses, traj


def _groundtruth_errors(
    slam: Any, data: Any, traj: np.ndarray
) -> tuple[np.ndarray | None, float | None, float | None, int | None]:
    """The ground truth along the trajectory, the map's ATE and dead reckoning's ATE
    (None where there is no ground truth, or fewer than 3 frames have it) and the
    number of frames with ground truth the ATEs are taken over."""
    from torchratslam.eval.metrics import interpolate_groundtruth

    gt_xy = slam.groundtruth_poses()
    gt_table = data.groundtruth() if isinstance(data, GroundTruthSource) else None
    if gt_xy is None and gt_table is not None and len(gt_table) and traj.shape[0]:
        gt_xy = interpolate_groundtruth(gt_table, traj[:, 1])
    ate = dr = None
    frames = None
    if gt_xy is not None and traj.shape[0]:
        table = None if slam.groundtruth_poses() is not None else gt_table
        ate = slam.ate(table)
        dr = slam.dead_reckoning_ate(table)
        frames = slam.history.ate_frames(slam.experience_map.poses, table)
    return gt_xy, ate, dr, frames


def _jsonable(v: Any) -> Any:
    return json.loads(json.dumps(v, default=json_default))


def _metrics(
    slam: Any,
    result: Any,
    extras: RunExtras,
    ate: float | None,
    dr: float | None,
    info: dict[str, Any],
) -> RunMetrics:
    summary = result.timings
    per_module = {
        name: {"mean_ms": s["mean_ms"], "median_ms": s["median_ms"]} for name, s in summary.items()
    }
    merges = getattr(slam, "merges", None)  # a multisession run
    partial = bool(info.get("partial"))
    unmerged = info.get("unmerged")
    return RunMetrics(
        frames=int(slam.frame_index),
        frames_this_run=int(result.frames),
        templates=int(result.templates),
        experiences=int(result.experiences),
        links=int(result.links),
        wall_s=float(result.wall_s),
        fps=float(result.fps),
        startup_s=float(getattr(result, "startup_s", 0.0)),
        ms_per_frame=per_module,
        pipelined=bool(result.pipelined),
        backend=slam.config.experience_map.exp_backend,
        odometry=extras.odometry or slam.odometry_name,
        data=extras.data,
        config=extras.config,
        loaded=extras.loaded,
        resumed_at_frame=extras.resumed_at_frame,
        tum=extras.tum,
        tum_ate_poses=extras.tum_ate_poses,
        ate_experience_rmse_m=extras.ate_experience_rmse_m,
        ate_frame_rmse_m=extras.ate_frame_rmse_m,
        ate_rmse_m=None if ate is None else float(ate),
        dead_reckoning_ate_m=None if dr is None else float(dr),
        merges=None if merges is None else _jsonable(merges),
        unmerged=unmerged,
        input_warnings=info.get("input_warnings"),
        partial=True if partial else None,
        stopped_at_frame=int(info.get("stopped_at_frame", slam.frame_index)) if partial else None,
        reason=str(info.get("reason", "")) if partial else None,
    )


def _write_figures(
    slam: Any, out: Path, poses: np.ndarray, traj: np.ndarray, gt_xy: Any, data: Any, title: str
) -> None:
    """``map.png`` (with the aligned ground truth) and ``pose_cells.png``."""
    from torchratslam.viz.plots import plot_map, plot_pose_cells

    plot_map(
        out / "map.png",
        poses,
        _links(slam.experience_map),
        trajectory_xy=traj[:, 3:5] if gt_xy is not None else None,
        groundtruth_xy=None if gt_xy is None else np.asarray(gt_xy)[:, :2],
        world=getattr(data, "world", None),
        title=title,
    )
    plot_pose_cells(out / "pose_cells.png", slam.activity, centres=slam.pc_log())


def write_outputs(
    slam: Any,
    out: Path,
    result: Any,
    *,
    data: Any,
    extras: RunExtras,
    record: RunRecord | None = None,
    info: dict[str, Any] | None = None,
    frame_poses: np.ndarray | None = None,
) -> RunMetrics:
    """Write state/ (first), experiences.csv, trajectory.csv, map.png, pose_cells.png and
    metrics.json (last) for a run, finished or stopped (``info["partial"]``), each
    atomically and recorded in OUT's manifest before it is written. With ``record`` (the
    run's options) the state holds the history a resumed run needs and OUT/run.json the
    record; with ``frame_poses`` (every frame's pose estimate) metrics.json holds their
    ATE too, and says why when the map's ATE is above dead reckoning's. Returns the
    metrics."""
    info = dict(info or {"partial": False})
    info.setdefault("frames", int(slam.frame_index))
    out.mkdir(parents=True, exist_ok=True)
    if record is not None:
        run_state.save_run_state(slam, out, record, info)
    else:
        from torchratslam.maps.running import save_state

        Manifest(out).add([STATE_DIR])
        save_state(slam, out / STATE_DIR)
    Manifest(out).add([*OUTPUT_FILES, STATE_DIR])
    poses, traj = _write_tables(slam, out)
    gt_xy, ate, dr, ate_frames = _groundtruth_errors(slam, data, traj)
    unmerged = write_unmerged(slam, out, extras.loaded or (), partial=bool(info.get("partial")))
    if unmerged is not None:
        info["unmerged"] = unmerged
    info["input_warnings"] = list(getattr(data, "input_warnings", ())) or None
    metrics = replace(_metrics(slam, result, extras, ate, dr, info), ate_frames=ate_frames)
    if ate is not None:
        from torchratslam.experiments import run_ate

        frame_ate = run_ate.frame_pose_ate(slam, data, frame_poses)
        note = run_ate.ate_note(
            ate, dr, frame_ate, run_ate.mean_link_length(slam), run_ate.loop_closures(slam)
        )
        metrics = replace(metrics, ate_frame_pose_m=frame_ate, ate_note=note)
    _write_figures(slam, out, poses, traj, gt_xy, data, extras.data)
    atomic_write_text(
        out / "metrics.json",
        json.dumps(metrics.to_json(), indent=2, default=json_default) + "\n",
    )
    return metrics


def write_unmerged(
    slam: Any, out: Path, loaded: tuple[str, ...] | Any, *, partial: bool = False
) -> list[dict[str, str]] | None:
    """Write each stored map that never merged with the run's map to
    ``OUT/unmerged/mapK`` and say so (a warning); returns the list for metrics.json
    (None for a run without stored maps)."""
    from ratslam_graph.atomic import make_dirs
    from torchratslam.maps.native import save_map

    pending = getattr(slam, "pending", None)
    stored = getattr(slam, "stored", None)
    if pending is None or stored is None or not loaded:
        return None
    rows: list[dict[str, str]] = []
    if pending:
        Manifest(out).add([UNMERGED_DIR])
        make_dirs(out / UNMERGED_DIR)
    for k in pending:
        name = f"{UNMERGED_DIR}/map{k}"
        save_map(stored[k], out / name)
        source = str(loaded[k]) if k < len(loaded) else f"map{k}"
        rows.append({"map": source, "written": name})
        log.warning(
            "the loaded map %s never merged with this run's map (none of its templates was "
            "seen%s); %s holds the run's map alone, and the loaded map is written unchanged "
            "to %s",
            source,
            " before the run stopped" if partial else "",
            out / STATE_DIR,
            out / name,
        )
    return rows


def write_tum(slam: Any, out: Path, recorder: Any, data: Any) -> dict[str, Any]:
    """The TUM files of ``--tum``; returns their :class:`RunExtras` fields (the files and
    the ATE of each estimate on them)."""
    from torchratslam.eval.tum import (
        TUM_ATE_ALIGNMENT,
        TUM_ATE_OVER,
        tum_ate,
        tum_matched,
        write_tum_files,
    )

    table = data.groundtruth() if isinstance(data, GroundTruthSource) else None
    files = write_tum_files(slam, out, recorder=recorder, groundtruth=table)
    fields: dict[str, Any] = {"tum": {k: p.name for k, p in files.items()}}
    if "groundtruth" in files:
        poses: dict[str, Any] = {"alignment": TUM_ATE_ALIGNMENT, "over": TUM_ATE_OVER}
        for name in ("experience", "frame"):
            if name in files:
                n = tum_matched(files["groundtruth"], files[name])
                poses[name] = n  # an ATE needs 3 matched poses: under 3 it is undefined
                if n >= 3:
                    fields[f"ate_{name}_rmse_m"] = tum_ate(files["groundtruth"], files[name])
        fields["tum_ate_poses"] = poses
    return fields


def write_scale_report(recorder: Any, slam: Any, out: Path, label: str) -> dict[str, Any]:
    """OUT/scale.json, scale.md and scale.png of a run recorded with ``scale_report``;
    returns the summary (``last_over_first``, ``peak_memory_mb``)."""
    from torchratslam.eval.scale import format_scale_table
    from torchratslam.viz.scale import plot_scale

    report = recorder.report(slam.timings, parts=min(10, len(recorder.templates)))
    atomic_write_text(out / "scale.json", json.dumps(report, indent=2) + "\n")
    atomic_write_text(out / "scale.md", format_scale_table(report, title=label) + "\n")
    plot_scale(out / "scale.png", {"torchratslam": report}, title=label)
    return {k: report[k] for k in ("last_over_first", "peak_memory_mb")}


def _startup(seconds: float) -> str:
    """The start-up beside the frames/s it is left out of, when it is worth saying."""
    return f" after a start-up of {seconds:.1f} s" if seconds >= 1.0 else ""


def summary_line(metrics: RunMetrics, out: Path) -> str:
    """The line ``torchratslam run`` prints."""
    m = metrics
    line = (
        f"{m.frames_this_run} frames in {m.wall_s:.1f} s "
        f"({m.fps:.1f} frames/s{_startup(m.startup_s or 0.0)}): {m.templates} templates, "
        f"{m.experiences} experiences, {m.links} links"
    )
    if m.ate_rmse_m is None and m.ate_frames is not None:
        line += (
            f", ATE undefined ({m.ate_frames} of {m.frames} frames have a map pose and "
            "ground truth; it needs 3)"
        )
    if m.ate_rmse_m is not None:
        ate = m.ate_rmse_m
        line += f", ATE {ate:.3f} m" if math.isfinite(ate) else ""
        if m.ate_frames is not None:
            line += f" (SE(2)-aligned, over {m.ate_frames} of {m.frames} frames with ground truth)"
        if m.ate_frame_rmse_m is not None:
            line += f" (per-frame pose {m.ate_frame_rmse_m:.3f} m)"
        dr = m.dead_reckoning_ate_m
        if dr is not None and math.isfinite(dr):
            line += f" vs dead reckoning {dr:.3f} m"
    if m.loaded is not None:  # a multisession run
        merges = m.merges
        n_merges = len(merges) if isinstance(merges, (list, dict)) else 0
        line += f", {n_merges} merge{'s' if n_merges != 1 else ''}"
        if m.unmerged:
            n = len(m.unmerged)
            line += (
                f" ({n} loaded map{'s' if n != 1 else ''} never merged: written to "
                f"{out / UNMERGED_DIR})"
            )
    return f"{line}; wrote {out}"
