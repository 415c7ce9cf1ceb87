"""Mapping one dataset and writing what ``torchratslam run`` writes (the runner behind
that command): ``metrics.json``, ``experiences.csv``, ``trajectory.csv``, ``map.png``,
``pose_cells.png`` and the saved state.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from torchratslam.graph.errors import InputError
from torchratslam.protocols import GroundTruthSource

__all__ = ["bag_topics", "run_dataset", "summary_line", "write_outputs"]


def _mirrored(data: Any) -> bool:
    """Whether the data's image columns turn counter-clockwise (the simulator's panoramas)."""
    if hasattr(data, "mirrored"):
        return bool(data.mirrored)
    camera = getattr(data, "camera", None)
    return getattr(camera, "kind", None) == "panoramic"


def bag_topics(config: Any, image_topic: str | None, odom_topic: str | None) -> tuple[str, str]:
    """Bag topics: the given ones, else the config's ``topic_root``, else the iRat's."""
    from torchratslam.readers.datasets import IRAT_IMAGE_TOPIC, IRAT_ODOM_TOPIC

    root = str(getattr(config.general, "topic_root", "") or "").strip("/")
    image = image_topic or (f"/{root}/camera/image/compressed" if root else IRAT_IMAGE_TOPIC)
    odom = odom_topic or (f"/{root}/odom" if root else IRAT_ODOM_TOPIC)
    return image, odom


def _atomic_text(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=path.suffix)
    try:
        with os.fdopen(fd, "w", newline="") as fh:
            fh.write(text)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _csv_text(header: list[str], rows: np.ndarray, int_cols: tuple[int, ...]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for row in rows.tolist():
        w.writerow([int(v) if i in int_cols else repr(float(v)) for i, v in enumerate(row)])
    return buf.getvalue()


def _created_frames(em: Any, n: int) -> np.ndarray:
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
    _atomic_text(
        out / "experiences.csv",
        _csv_text(["id", "x", "y", "th", "created_frame"], exp_rows, (0, 4)),
    )
    traj = slam.trajectory()
    _atomic_text(
        out / "trajectory.csv",
        _csv_text(["frame", "t", "experience_id", "x", "y", "th"], traj, (0, 2)),
    )
    return poses, traj


def _groundtruth_errors(
    slam: Any, data: Any, traj: np.ndarray
) -> tuple[np.ndarray | None, float | None, float | None]:
    """The ground truth along the trajectory, the map's ATE and dead reckoning's ATE
    (None where there is no ground truth)."""
    from torchratslam.eval.metrics import interpolate_groundtruth

    gt_xy = slam.groundtruth_poses()
    gt_table = data.groundtruth() if isinstance(data, GroundTruthSource) else None
    if gt_xy is None and gt_table is not None and len(gt_table) and traj.shape[0]:
        gt_xy = interpolate_groundtruth(gt_table, traj[:, 1])
    ate = dr = None
    if gt_xy is not None and traj.shape[0] >= 2:
        table = None if slam.groundtruth_poses() is not None else gt_table
        ate = slam.ate(table)
        dr = slam.dead_reckoning_ate(table)
    return gt_xy, ate, dr


def _metrics(
    slam: Any, result: Any, extra: dict[str, Any], ate: float | None, dr: float | None
) -> dict[str, Any]:
    summary = result.timings
    per_module = {
        name: {"mean_ms": s["mean_ms"], "median_ms": s["median_ms"]} for name, s in summary.items()
    }
    metrics: dict[str, Any] = {
        "frames": int(slam.frame_index),
        "frames_this_run": int(result.frames),
        "templates": int(result.templates),
        "experiences": int(result.experiences),
        "links": int(result.links),
        "wall_s": float(result.wall_s),
        "fps": float(result.fps),
        "ms_per_frame": per_module,
        "pipelined": bool(result.pipelined),
        "backend": slam.config.experience_map.exp_backend,
        "odometry": slam.odometry_name,
        **extra,
    }
    if ate is not None:
        metrics["ate_rmse_m"] = float(ate)
    if dr is not None:
        metrics["dead_reckoning_ate_m"] = float(dr)
    merges = getattr(slam, "merges", None)  # a multisession run
    if merges is not None:
        metrics["merges"] = _jsonable(merges)
    return metrics


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
    slam: Any, out: Path, result: Any, *, data: Any, extra: dict[str, Any]
) -> dict[str, Any]:
    """Write metrics.json, experiences.csv, trajectory.csv, map.png, pose_cells.png and
    state/ for a finished run. Returns the metrics."""
    from torchratslam.maps.state import save_state

    out.mkdir(parents=True, exist_ok=True)
    poses, traj = _write_tables(slam, out)
    gt_xy, ate, dr = _groundtruth_errors(slam, data, traj)
    metrics = _metrics(slam, result, extra, ate, dr)
    title = str(extra.get("data", "experience map"))
    _write_figures(slam, out, poses, traj, gt_xy, data, title)
    save_state(slam, out / "state")
    _atomic_text(out / "metrics.json", json.dumps(metrics, indent=2, default=_json_default) + "\n")
    return metrics


def _json_default(v: Any) -> Any:
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)


def _jsonable(v: Any) -> Any:
    return json.loads(json.dumps(v, default=_json_default))


def _odometry_source(config: Any, data: Any, data_spec: str, visual: bool) -> Any:
    """The visual odometry when asked for or when the data has none; else None (the
    config's choice)."""
    if not (visual or not getattr(data, "has_odometry", True)):
        return None
    from torchratslam.readers.visual_odometry import VisualOdometry

    if not visual:
        print(
            f"torchratslam run: {data_spec} has no odometry; using visual odometry",
            file=sys.stderr,
        )
    return VisualOdometry(config.visual_odometry, mirrored=_mirrored(data))


def _output_dir(out: Path) -> Path:
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a directory; choose another path")
    out.mkdir(parents=True, exist_ok=True)
    return out


def run_dataset(
    config_spec: str,
    data_spec: str,
    out: str | Path,
    *,
    overrides: dict[str, str] | None = None,
    odometry_file: str | None = None,
    groundtruth: str | None = None,
    image_topic: str | None = None,
    odom_topic: str | None = None,
    visual_odometry: bool = False,
    load: list[str] | tuple[str, ...] = (),
    device: str | None = None,
    pipelined: bool = False,
    max_frames: int | None = None,
    progress: bool = True,
    threads: int = 1,
) -> dict[str, Any]:
    """Map one dataset (localising in and merging with the ``load`` maps, if any) and
    write OUT; returns the metrics (what ``metrics.json`` holds).

    Args:
        config_spec: a config path or shipped name.
        data_spec: a directory, a video, a ROS bag or ``sim:NAME[/session]``.
        out: the output folder.
        overrides: flat config keys.
        odometry_file, groundtruth: CSVs for a video (or replacing a directory's).
        image_topic, odom_topic: a bag's topics (default from the config).
        visual_odometry: estimate odometry from the images even when the data has some.
        load: stored maps to localise in and merge with.
        device: the torch device of the local view and pose cells.
        pipelined: one worker thread per module.
        max_frames: stop after this many frames.
        progress: a progress bar.
        threads: torch intra-op threads.

    Raises:
        InputError: bad counts, unreadable data, no frames, OUT not a directory.
    """
    import torch

    from torchratslam.config import load_config
    from torchratslam.pipeline import RatSLAM
    from torchratslam.readers.datasets import open_data

    if threads < 1:
        raise InputError(f"--threads must be >= 1, got {threads}")
    torch.set_num_threads(threads)
    if max_frames is not None and max_frames <= 0:
        raise InputError(f"--max-frames must be a positive number of frames, got {max_frames}")
    config = load_config(config_spec, **(overrides or {}))
    image_topic, odom_topic = bag_topics(config, image_topic, odom_topic)
    data = open_data(
        data_spec,
        odometry=odometry_file,
        groundtruth=groundtruth,
        image_topic=image_topic,
        odom_topic=odom_topic,
    )
    odometry = _odometry_source(config, data, data_spec, visual_odometry)
    out = _output_dir(Path(out))
    kwargs: dict[str, Any] = {
        "odometry": odometry,
        "device": torch.device(device) if device else None,
        "pipelined": pipelined,
    }
    if load:
        from torchratslam.maps.io import load_state
        from torchratslam.multisession.session import MultiSessionRatSLAM

        slam: Any = MultiSessionRatSLAM(config, [load_state(p) for p in load], **kwargs)
    else:
        slam = RatSLAM(config, **kwargs)
    result = slam.run(data, max_frames=max_frames, progress=progress)
    if result.frames == 0:
        raise InputError(f"{data_spec}: no frames were read; check the dataset")
    extra: dict[str, Any] = {"data": str(data_spec), "config": str(config_spec)}
    if odometry is not None:
        extra["odometry"] = "visual"
    if load:
        extra["loaded"] = [str(p) for p in load]
    return write_outputs(slam, out, result, data=data, extra=extra)


def summary_line(metrics: dict[str, Any], out: Path) -> str:
    """The line ``torchratslam run`` prints."""
    line = (
        f"{metrics['frames_this_run']} frames in {metrics['wall_s']:.1f} s "
        f"({metrics['fps']:.1f} frames/s): {metrics['templates']} templates, "
        f"{metrics['experiences']} experiences, {metrics['links']} links"
    )
    if "ate_rmse_m" in metrics:
        ate = metrics["ate_rmse_m"]
        line += f", ATE {ate:.3f} m" if math.isfinite(ate) else ""
    return f"{line}; wrote {out}"
