"""``torchratslam run``: map a dataset and write the map, metrics, figures and state."""

from __future__ import annotations

import argparse
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

from torchratslam.graph.errors import ConfigError, InputError

DESCRIPTION = """Run RatSLAM on a dataset.

OUT receives: metrics.json (frames, templates, experiences, links, wall_s, per-module
mean/median ms per frame, ate_rmse_m when there is ground truth), experiences.csv
(id,x,y,th,created_frame; final poses), trajectory.csv (frame,t,experience_id,x,y,th:
the experience current after each frame, with its final pose), map.png,
pose_cells.png and the saved map state in OUT/state (load it with --load or
torchratslam.maps.state.load_state)."""

EPILOG = """examples:
  torchratslam run --config configs/virtual_tour.yaml --data sim:virtual_tour --out out/vt
  torchratslam run --config irat --data irat_aus_28112011.bag --out out/irat --backend isam2
  torchratslam run --config irat --data my_ros2_bag/ --image-topic /camera/image_raw \
      --odom-topic /odom --out out/ros2 --tum
  torchratslam run --config lab_tour --data lab.mp4 --odometry lab_odometry.csv --out out/lab
  torchratslam run --config virtual_tour --data sim:virtual_tour/session2 --out out/s2 \\
      --load out/s1/state
"""


def register(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "run",
        help="map a dataset (directory, video, ROS bag or sim:NAME)",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--config",
        required=True,
        metavar="CONFIG",
        help="a YAML of configs/ (path or name, e.g. 'virtual_tour') or an OpenRatSLAM "
        ".txt config, e.g. --config configs/irat.yaml",
    )
    p.add_argument(
        "--data",
        required=True,
        metavar="DATA",
        help="dataset: a directory (frames/, odometry.csv, groundtruth.csv), a video "
        "(with --odometry), a ROS 1 .bag, a ROS 2 bag directory (sqlite3 or MCAP), or "
        "sim:NAME[/sessionK], e.g. --data sim:virtual_tour",
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="OUT",
        help="output directory (created; files in it are replaced), e.g. --out out/vt",
    )
    p.add_argument(
        "--backend",
        choices=("alpha", "alpha_reference", "gtsam", "isam2"),
        help="experience-map relaxation backend (overrides exp_backend), e.g. --backend isam2",
    )
    p.add_argument(
        "--max-frames",
        type=int,
        metavar="N",
        help="stop after N frames, e.g. --max-frames 500",
    )
    p.add_argument(
        "--odometry",
        metavar="FILE",
        help="odometry CSV (header t,vtrans,vrot; one row per frame) for a video, or to "
        "replace a directory's odometry.csv, e.g. --odometry lab_odometry.csv",
    )
    p.add_argument(
        "--groundtruth",
        metavar="FILE",
        help="ground-truth CSV (t,x,y,theta) for a video, e.g. --groundtruth gt.csv",
    )
    p.add_argument(
        "--visual-odometry",
        action="store_true",
        help="estimate odometry from the images (OpenRatSLAM's intensity profiles) even "
        "when the data has wheel odometry; used automatically when it has none, "
        "e.g. --visual-odometry",
    )
    p.add_argument(
        "--load",
        action="append",
        metavar="MAP",
        default=[],
        help="a stored map to localise in and merge with (repeatable): a saved state "
        "directory, a run's OUT directory, or a reference-format map, e.g. --load out/s1/state",
    )
    p.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        default=[],
        help="override one config key (repeatable), e.g. --set exp_loops=50",
    )
    p.add_argument(
        "--pipelined",
        action="store_true",
        help="one worker thread per module with bounded queues (same map), e.g. --pipelined",
    )
    p.add_argument(
        "--image-topic",
        default=None,
        metavar="TOPIC",
        help="image topic of a ROS 1 or ROS 2 bag (CompressedImage or Image; default "
        "/<topic_root>/camera/image/compressed with the config's topic_root, else the "
        "iRat's /irat_red/camera/image/compressed), "
        "e.g. --image-topic /stlucia/camera/image/compressed",
    )
    p.add_argument(
        "--odom-topic",
        default=None,
        metavar="TOPIC",
        help="nav_msgs/Odometry topic of a ROS 1 or ROS 2 bag (default /<topic_root>/odom, else "
        "/irat_red/odom), e.g. --odom-topic /irat_red/odom",
    )
    p.add_argument(
        "--device",
        default=None,
        metavar="DEVICE",
        help="torch device of the local view and pose cells, e.g. --device cuda",
    )
    p.add_argument(
        "--threads",
        type=int,
        default=1,
        metavar="N",
        help="torch intra-op threads (default 1: the per-frame work is small and extra "
        "threads mostly add overhead), e.g. --threads 4",
    )
    p.add_argument(
        "--tum",
        action="store_true",
        help="also write TUM trajectories for evo: OUT/tum_experience.txt (the current "
        "experience, as OpenRatSLAM publishes), OUT/tum_frame.txt (experience + odometry "
        "since it) and OUT/tum_groundtruth.txt; then evo_ape tum OUT/tum_groundtruth.txt "
        "OUT/tum_frame.txt -a, e.g. --tum",
    )
    p.add_argument(
        "--rerun",
        action="store_true",
        help="watch the run live in a rerun viewer (needs torchratslam[viewer]), e.g. --rerun",
    )
    p.add_argument(
        "--rerun-save",
        metavar="FILE",
        default=None,
        help="record the run for the rerun viewer into FILE.rrd (open it with: rerun "
        "FILE.rrd), e.g. --rerun-save out/run.rrd",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar, e.g. --no-progress")
    p.set_defaults(func=main)
    return p


def _mirrored(data: Any) -> bool:
    """Whether the data's image columns turn counter-clockwise (the simulator's panoramas)."""
    if hasattr(data, "mirrored"):
        return bool(data.mirrored)
    camera = getattr(data, "camera", None)
    return getattr(camera, "kind", None) == "panoramic"


def _topics(args: argparse.Namespace, config: Any) -> tuple[str, str]:
    """Bag topics: the options, else the config's ``topic_root``, else the iRat's."""
    from torchratslam.readers.datasets import IRAT_IMAGE_TOPIC, IRAT_ODOM_TOPIC

    root = str(getattr(config.general, "topic_root", "") or "").strip("/")
    image = args.image_topic or (f"/{root}/camera/image/compressed" if root else IRAT_IMAGE_TOPIC)
    odom = args.odom_topic or (f"/{root}/odom" if root else IRAT_ODOM_TOPIC)
    return image, odom


def _overrides(items: list[str]) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in items:
        if "=" not in item:
            raise ConfigError(f"--set {item!r}: expected KEY=VALUE, e.g. --set exp_loops=50")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out


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


def write_outputs(
    slam: Any, out: Path, result: Any, *, data: Any, extra: dict[str, Any]
) -> dict[str, Any]:
    """Write metrics.json, experiences.csv, trajectory.csv, map.png, pose_cells.png and
    state/ for a finished run. Returns the metrics."""
    from torchratslam.eval.metrics import interpolate_groundtruth
    from torchratslam.viz.plots import plot_map, plot_pose_cells

    out.mkdir(parents=True, exist_ok=True)
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
    gt_xy = slam.groundtruth_poses()
    gt_table = data.groundtruth() if hasattr(data, "groundtruth") else None
    if gt_xy is None and gt_table is not None and len(gt_table) and traj.shape[0]:
        gt_xy = interpolate_groundtruth(gt_table, traj[:, 1])
    ate = dr = None
    if gt_xy is not None and traj.shape[0] >= 2:
        table = None if slam.groundtruth_poses() is not None else gt_table
        ate = slam.ate(table)
        dr = slam.dead_reckoning_ate(table)
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
    if hasattr(slam, "merges"):
        metrics["merges"] = _jsonable(slam.merges)
    plot_map(
        out / "map.png",
        poses,
        _links(em),
        trajectory_xy=traj[:, 3:5] if gt_xy is not None else None,
        groundtruth_xy=None if gt_xy is None else np.asarray(gt_xy)[:, :2],
        world=getattr(data, "world", None),
        title=str(extra.get("data", "experience map")),
    )
    centres = slam.pc_log() if hasattr(slam, "pc_log") else None
    plot_pose_cells(out / "pose_cells.png", slam.activity, centres=centres)
    from torchratslam.maps.state import save_state

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


def _write_tum(slam: Any, out: Path, recorder: Any, data: Any) -> dict[str, Any]:
    """The TUM files of ``--tum`` and the ATE of each estimate on them (for metrics.json)."""
    from torchratslam.eval.tum import tum_ate, write_tum_files

    table = data.groundtruth() if hasattr(data, "groundtruth") else None
    files = write_tum_files(slam, out, recorder=recorder, groundtruth=table)
    extra: dict[str, Any] = {"tum": {k: p.name for k, p in files.items()}}
    if "groundtruth" in files and slam.trajectory().shape[0] >= 2:
        for name in ("experience", "frame"):
            if name in files:
                extra[f"ate_{name}_rmse_m"] = tum_ate(files["groundtruth"], files[name])
    return extra


def main(args: argparse.Namespace) -> int:
    import torch

    from torchratslam.config import load_config
    from torchratslam.pipeline import RatSLAM
    from torchratslam.readers.datasets import open_data

    if args.threads < 1:
        raise InputError(f"--threads must be >= 1, got {args.threads}")
    torch.set_num_threads(args.threads)
    if args.max_frames is not None and args.max_frames <= 0:
        raise InputError(f"--max-frames must be a positive number of frames, got {args.max_frames}")
    overrides = _overrides(args.set)
    if args.backend:
        overrides["exp_backend"] = args.backend
    config = load_config(args.config, **overrides)
    image_topic, odom_topic = _topics(args, config)
    data = open_data(
        args.data,
        odometry=args.odometry,
        groundtruth=args.groundtruth,
        image_topic=image_topic,
        odom_topic=odom_topic,
    )
    odometry: Any = None  # the config's choice (default: the data's odometry)
    odometry_label = None
    if args.visual_odometry or not getattr(data, "has_odometry", True):
        from torchratslam.readers.visual_odometry import VisualOdometry

        odometry = VisualOdometry(config.visual_odometry, mirrored=_mirrored(data))
        odometry_label = "visual"
        if not args.visual_odometry:
            print(
                f"torchratslam run: {args.data} has no odometry; using visual odometry",
                file=sys.stderr,
            )
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a directory; choose another path")
    out.mkdir(parents=True, exist_ok=True)
    device = torch.device(args.device) if args.device else None
    kwargs: dict[str, Any] = {"odometry": odometry, "device": device, "pipelined": args.pipelined}
    if args.load:
        from torchratslam.maps.state import load_state
        from torchratslam.multisession.session import MultiSessionRatSLAM

        stored = [load_state(p) for p in args.load]
        slam = MultiSessionRatSLAM(config, stored, **kwargs)
    else:
        slam = RatSLAM(config, **kwargs)
    from torchratslam.eval.tum import FramePoseRecorder

    recorder = FramePoseRecorder()
    callback: Any = recorder
    frames: Any = data
    observer = None
    if args.rerun or args.rerun_save:
        from torchratslam.viz.rerun_viewer import RerunObserver

        observer = RerunObserver(slam, spawn=args.rerun, save=args.rerun_save)
        frames = observer.frames(data)

        def callback(r: Any) -> None:
            recorder(r)
            observer(r)

    try:
        result = slam.run(
            frames, max_frames=args.max_frames, progress=not args.no_progress, callback=callback
        )
    finally:
        if observer is not None:
            observer.close()
    if result.frames == 0:
        raise InputError(f"{args.data}: no frames were read; check the dataset")
    extra: dict[str, Any] = {"data": str(args.data), "config": str(args.config)}
    if args.tum:
        extra.update(_write_tum(slam, out, recorder, data))
    if odometry_label:
        extra["odometry"] = odometry_label
    if args.load:
        extra["loaded"] = [str(p) for p in args.load]
    metrics = write_outputs(slam, out, result, data=data, extra=extra)
    line = (
        f"{metrics['frames_this_run']} frames in {metrics['wall_s']:.1f} s "
        f"({metrics['fps']:.1f} frames/s): {metrics['templates']} templates, "
        f"{metrics['experiences']} experiences, {metrics['links']} links"
    )
    if "ate_rmse_m" in metrics:
        ate = metrics["ate_rmse_m"]
        line += f", ATE {ate:.3f} m" if math.isfinite(ate) else ""
        if "ate_frame_rmse_m" in metrics:
            line += f" (per-frame pose {metrics['ate_frame_rmse_m']:.3f} m)"
        dr = metrics.get("dead_reckoning_ate_m")
        if dr is not None and math.isfinite(dr):
            line += f" vs dead reckoning {dr:.3f} m"
    if args.load:
        merges = metrics.get("merges")
        n_merges = len(merges) if isinstance(merges, (list, dict)) else 0
        line += f", {n_merges} merge{'s' if n_merges != 1 else ''}"
    print(f"{line}; wrote {out}")
    return 0
