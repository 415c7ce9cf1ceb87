"""``torchratslam run``: map a dataset and write the map, metrics, figures and state."""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

from torchratslam.graph.errors import ConfigError, InputError, RatSLAMError
from torchratslam.readers.limits import MAX_SPEED, MAX_TURN_RATE

DESCRIPTION = """Run RatSLAM on a dataset.

OUT receives: metrics.json (frames, templates, experiences, links, wall_s, per-module
mean/median ms per frame, ate_rmse_m when there is ground truth), experiences.csv
(id,x,y,th,created_frame; final poses), trajectory.csv (frame,t,experience_id,x,y,th:
the experience current after each frame, with its final pose), map.png,
pose_cells.png and the saved map state in OUT/state (load it with --load or
torchratslam.maps.state.load_state).

Everything that can be checked is checked before the first frame (OUT, the data's
counts, the device, the config's limits). One run writes to an OUT at a time (a lock).
When the run stops early (Ctrl-C, a bad frame, any error after frame N), the map as of
frame N is saved in OUT/state, marked partial (metrics.json "partial": true,
"stopped_at_frame": N), and the command exits non-zero; `run --resume OUT` continues it
and ends with the map an uninterrupted run makes, bit for bit. Files in OUT that
torchratslam did not write are never replaced."""

EPILOG = """examples:
  torchratslam run --config configs/virtual_tour.yaml --data sim:virtual_tour --out out/vt
  torchratslam run --config irat --data irat_aus_28112011.bag --out out/irat --backend isam2
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
        metavar="CONFIG",
        help="a YAML of configs/ (path or name, e.g. 'virtual_tour') or an OpenRatSLAM "
        ".txt config, e.g. --config configs/irat.yaml",
    )
    p.add_argument(
        "--data",
        metavar="DATA",
        help="dataset: a directory (frames/, odometry.csv, groundtruth.csv), a video "
        "(with --odometry), a ROS 1 .bag, or sim:NAME[/sessionK], e.g. --data sim:virtual_tour",
    )
    p.add_argument(
        "--out",
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
        help="ground-truth CSV (t,x,y,theta) for a video, or to replace a directory's "
        "groundtruth.csv, e.g. --groundtruth gt.csv",
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
        help="image topic of a .bag (CompressedImage or Image; default "
        "/<topic_root>/camera/image/compressed with the config's topic_root, else the "
        "iRat's /irat_red/camera/image/compressed), "
        "e.g. --image-topic /stlucia/camera/image/compressed",
    )
    p.add_argument(
        "--odom-topic",
        default=None,
        metavar="TOPIC",
        help="nav_msgs/Odometry topic of a .bag (default /<topic_root>/odom, else "
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
    p.add_argument("--no-progress", action="store_true", help="no progress bar, e.g. --no-progress")
    p.add_argument(
        "--checkpoint-every",
        type=int,
        default=None,
        metavar="K",
        help="save a loadable (partial) map in OUT/state every K frames, "
        "e.g. --checkpoint-every 500",
    )
    p.add_argument(
        "--resume",
        default=None,
        metavar="OUT",
        help="continue a run that stopped early, with its recorded options; the final map is "
        "the one an uninterrupted run makes, e.g. --resume out/vt",
    )
    p.add_argument(
        "--max-speed",
        type=float,
        default=None,
        metavar="M_PER_S",
        help=f"odometry rows faster than this are an error (default {MAX_SPEED:g} m/s), "
        "e.g. --max-speed 30",
    )
    p.add_argument(
        "--max-turn-rate",
        type=float,
        default=None,
        metavar="RAD_PER_S",
        help=f"odometry rows turning faster than this are an error (default {MAX_TURN_RATE:g} "
        "rad/s), e.g. --max-turn-rate 10",
    )
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


OUTPUT_FILES = ("metrics.json", "experiences.csv", "trajectory.csv", "map.png", "pose_cells.png")
STATE_DIR = "state"
RUN_RECORD = "run.json"
HISTORY = "history.npz"


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


# ----------------------------------------------------------------------- history (resume)
def _history_writer(slam: Any) -> Any:
    """A writer of the per-frame history (trajectory, ground truth, odometry, pose-cell
    centres) that ``--resume`` needs to give the same outputs as one run."""
    core = getattr(slam, "slam", slam)
    gt = np.asarray(
        [(np.nan, np.nan, np.nan) if p is None else p for p in core._gt], np.float64
    ).reshape(-1, 3)
    arrays = {
        "frames": np.asarray(core._frames, np.int64),
        "t": np.asarray(core._t, np.float64),
        "exp": np.asarray(core._exp, np.int64),
        "gt": gt,
        "gt_ok": np.asarray([p is not None for p in core._gt], bool),
        "odo": np.asarray(core._odo, np.float64).reshape(-1, 3),
        "pc": np.asarray(core._pc, np.float64).reshape(-1, 3),
    }
    return lambda fh: np.savez(fh, **arrays)


def _restore_history(slam: Any, path: Path) -> None:
    core = getattr(slam, "slam", slam)
    try:
        with np.load(path, allow_pickle=False) as h:
            a = {k: h[k] for k in h.files}
        n = a["frames"].shape[0]
        if any(a[k].shape[0] != n for k in a):
            raise ValueError("arrays of different lengths")
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(f"{path}: the run's history cannot be read ({exc}); re-run") from None
    core._frames[:] = [int(v) for v in a["frames"]]
    core._t[:] = [float(v) for v in a["t"]]
    core._exp[:] = [int(v) for v in a["exp"]]
    core._gt[:] = [tuple(float(x) for x in g) if ok else None for g, ok in zip(a["gt"], a["gt_ok"])]
    core._odo[:] = [tuple(float(x) for x in o) for o in a["odo"]]
    core._pc[:] = [tuple(float(x) for x in c) for c in a["pc"]]


def _save_state(slam: Any, out: Path, record: dict[str, Any], info: dict[str, Any]) -> None:
    """OUT/state (with the history) and OUT/run.json, each atomically; state first."""
    from torchratslam.graph.atomic import Manifest, atomic_write_text
    from torchratslam.maps.state import save_map, state_from_slam

    Manifest(out).add([STATE_DIR, RUN_RECORD])  # recorded before they are written
    save_map(
        state_from_slam(slam),
        out / STATE_DIR,
        info=info,
        extra_files={HISTORY: _history_writer(slam)},
    )
    atomic_write_text(out / RUN_RECORD, json.dumps(record, indent=1, default=_json_default))


def write_outputs(
    slam: Any,
    out: Path,
    result: Any,
    *,
    data: Any,
    extra: dict[str, Any],
    record: dict[str, Any] | None = None,
    info: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Write state/ (first), experiences.csv, trajectory.csv, map.png, pose_cells.png and
    metrics.json (last) for a run, finished or stopped (``info["partial"]``). Returns the
    metrics."""
    from torchratslam.eval.metrics import interpolate_groundtruth
    from torchratslam.graph.atomic import Manifest, atomic_write_text
    from torchratslam.viz.plots import plot_map, plot_pose_cells

    info = dict(info or {"partial": False})
    info.setdefault("frames", int(slam.frame_index))
    if record is not None:
        _save_state(slam, out, record, info)
    else:
        from torchratslam.maps.state import save_state

        save_state(slam, out / STATE_DIR)
    em = slam.experience_map
    poses = np.asarray(em.poses, dtype=np.float64).reshape(-1, 3)
    n = poses.shape[0]
    exp_rows = np.column_stack([np.arange(n), poses, _created_frames(em, n)])
    Manifest(out).add([*OUTPUT_FILES, STATE_DIR])
    atomic_write_text(
        out / "experiences.csv",
        _csv_text(["id", "x", "y", "th", "created_frame"], exp_rows, (0, 4)),
    )
    traj = slam.trajectory()
    atomic_write_text(
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
    if info.get("partial"):
        metrics.update(
            partial=True,
            stopped_at_frame=int(info.get("stopped_at_frame", slam.frame_index)),
            reason=str(info.get("reason", "")),
        )
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
    atomic_write_text(
        out / "metrics.json", json.dumps(metrics, indent=2, default=_json_default) + "\n"
    )
    return metrics


def _json_default(v: Any) -> Any:
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)


def _jsonable(v: Any) -> Any:
    return json.loads(json.dumps(v, default=_json_default))


# ----------------------------------------------------------------------- checks
def _device(spec: str | None) -> Any:
    """The torch device of ``--device``, checked against this torch build and machine."""
    if spec is None:
        return None
    import torch

    try:
        dev = torch.device(spec)
    except (RuntimeError, ValueError, TypeError):
        raise InputError(
            f"--device {spec!r} is not a torch device; use cpu, cuda, cuda:N or mps"
        ) from None
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            why = "has no CUDA" if torch.version.cuda is None else "sees no GPU"
            raise InputError(
                f"--device {spec}: this torch ({torch.__version__}) {why}; use --device cpu"
            )
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise InputError(
                f"--device {spec}: only {torch.cuda.device_count()} CUDA device(s) are visible"
            )
    elif dev.type == "mps":
        if not torch.backends.mps.is_available():
            raise InputError(f"--device {spec}: MPS is not available here; use --device cpu")
    elif dev.type != "cpu":
        raise InputError(f"--device {spec}: {dev.type} devices are not supported; use cpu or cuda")
    return dev


def _data_kind(spec: str) -> str:
    if spec.startswith("sim:"):
        return "sim"
    p = Path(spec)
    if p.is_dir():
        return "directory"
    return "bag" if p.suffix.lower() == ".bag" else "video"


def _check_applicable(opts: dict[str, Any]) -> None:
    """Every option given must apply to the data: an option that would be ignored is an
    error, not a silent no-op."""
    kind = _data_kind(str(opts["data"]))
    wrong = {
        "sim": (
            "odometry",
            "groundtruth",
            "image_topic",
            "odom_topic",
            "max_speed",
            "max_turn_rate",
        ),
        "directory": ("image_topic", "odom_topic"),
        "video": ("image_topic", "odom_topic"),
        "bag": ("odometry", "groundtruth", "max_speed", "max_turn_rate"),
    }[kind]
    given = [f"--{k.replace('_', '-')}" for k in wrong if opts.get(k)]
    if given:
        raise InputError(
            f"{' and '.join(given)} do{'es' if len(given) == 1 else ''} not apply to "
            f"{kind} data ({opts['data']}); remove {'it' if len(given) == 1 else 'them'}"
        )


def _check_out(out: Path, *, resume: bool) -> None:
    """OUT must be a writable directory (or creatable), with no file where a directory
    goes and no file of ours' names that torchratslam did not write."""
    from torchratslam.graph.atomic import Manifest

    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a directory; choose another path")
    if out.exists():
        state = out / STATE_DIR
        if state.exists() and not state.is_dir():
            raise InputError(
                f"{state} exists and is not a directory (the map goes there); move it away"
            )
        for name in OUTPUT_FILES:
            if (out / name).is_dir():
                raise InputError(f"{out / name} is a directory (a file goes there); move it away")
        own = Manifest(out).entries()
        theirs = [n for n in (*OUTPUT_FILES, STATE_DIR, RUN_RECORD) if (out / n).exists()]
        theirs = [n for n in theirs if n not in own]
        if theirs and not resume:
            raise InputError(
                f"{out} holds {', '.join(theirs)} that torchratslam did not write (or wrote "
                "before it kept a manifest); refusing to replace them: choose another --out "
                "or move them away"
            )
        probe = out
    else:
        probe = next((q for q in out.parents if q.exists()), Path("."))
        if not probe.is_dir():
            raise InputError(f"--out {out}: {probe} is not a directory")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise InputError(f"--out {out}: {probe} is not writable; choose another --out")
    state = out / STATE_DIR
    if state.is_dir() and not os.access(state, os.W_OK | os.X_OK):
        raise InputError(f"{state} is not writable, so the map cannot be replaced")


# ----------------------------------------------------------------------- the frames
class _Frames:
    """The data's frames from ``skip`` on, stopping cleanly between two frames on the
    first Ctrl-C (a second one stops at once)."""

    def __init__(self, data: Any, skip: int) -> None:
        self.data, self.skip = data, skip
        self.interrupted = False
        self._old: Any = None

    def __len__(self) -> int:
        return max(len(self.data) - self.skip, 0) if hasattr(self.data, "__len__") else 0

    def frames(self) -> Any:
        it = iter(self.data.frames())
        for k, frame in enumerate(it):
            if k < self.skip:
                continue
            if self.interrupted:
                raise KeyboardInterrupt
            yield frame

    def _on_sigint(self, signum: int, stack: Any) -> None:
        if self.interrupted:
            raise KeyboardInterrupt
        self.interrupted = True
        print(
            "\ntorchratslam run: stopping after this frame (Ctrl-C again to stop at once)",
            file=sys.stderr,
        )

    def __enter__(self) -> _Frames:
        import signal
        import threading

        if threading.current_thread() is threading.main_thread():
            self._old = signal.signal(signal.SIGINT, self._on_sigint)
        return self

    def __exit__(self, *exc: Any) -> None:
        import signal

        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)


def _options(args: argparse.Namespace) -> dict[str, Any]:
    """The options that define a run (recorded in OUT/run.json for --resume)."""

    def path(v: Any) -> Any:
        return str(Path(v).resolve()) if v and Path(v).exists() else v

    return {
        "config": path(args.config),
        "data": str(path(args.data)),
        "backend": args.backend,
        "max_frames": args.max_frames,
        "odometry": path(args.odometry),
        "groundtruth": path(args.groundtruth),
        "visual_odometry": bool(args.visual_odometry),
        "load": [path(p) for p in args.load],
        "set": list(args.set),
        "pipelined": bool(args.pipelined),
        "image_topic": args.image_topic,
        "odom_topic": args.odom_topic,
        "max_speed": args.max_speed,
        "max_turn_rate": args.max_turn_rate,
    }


def _read_record(out: Path) -> dict[str, Any]:
    p = out / RUN_RECORD
    if not p.is_file():
        raise InputError(
            f"--resume {out}: no {RUN_RECORD} there; only a run of this torchratslam that "
            "stopped early can be resumed"
        )
    try:
        record = json.loads(p.read_text())
        if not isinstance(record, dict) or not isinstance(record.get("options"), dict):
            raise ValueError("no options")
        if not isinstance(record.get("config_flat"), dict):
            raise ValueError("no config")
    except (OSError, ValueError) as exc:
        raise InputError(f"{p}: cannot be read ({exc}); start the run again") from None
    return record


# ----------------------------------------------------------------------- main
def main(args: argparse.Namespace) -> int:
    import torch

    from torchratslam.config import RatSLAMConfig, check_config_limits, load_config
    from torchratslam.graph.atomic import LOCK_NAME, DirectoryLock, make_dirs

    if args.threads < 1:
        raise InputError(f"--threads must be >= 1, got {args.threads}")
    torch.set_num_threads(args.threads)
    if args.max_frames is not None and args.max_frames <= 0:
        raise InputError(f"--max-frames must be a positive number of frames, got {args.max_frames}")
    if args.checkpoint_every is not None and args.checkpoint_every <= 0:
        raise InputError(f"--checkpoint-every must be >= 1 frame, got {args.checkpoint_every}")
    resume = args.resume is not None
    if resume:
        given = [
            f"--{k.replace('_', '-')}"
            for k in ("config", "data", "out", "backend", "max_frames", "odometry", "groundtruth")
            if getattr(args, k) is not None
        ]
        given += [f"--{k}" for k in ("set", "load") if getattr(args, k)]
        if given:
            raise InputError(
                f"--resume takes the stopped run's options from {RUN_RECORD}; "
                f"do not give {', '.join(given)}"
            )
        out = Path(args.resume)
        if not out.is_dir():
            raise InputError(f"--resume {out}: not a directory")
        record = _read_record(out)
        opts = record["options"]
        config = RatSLAMConfig.from_flat(record["config_flat"], source=str(out / RUN_RECORD))
        if opts.get("load"):
            raise InputError(f"--resume {out}: runs with --load cannot be resumed yet; re-run")
    else:
        missing = [f"--{k}" for k in ("config", "data", "out") if not getattr(args, k)]
        if missing:
            raise InputError(f"the following arguments are required: {', '.join(missing)}")
        opts = _options(args)
        overrides = _overrides(args.set)
        if args.backend:
            overrides["exp_backend"] = args.backend
        config = load_config(args.config, **overrides)
        out = Path(args.out)
    if opts["pipelined"] and (args.checkpoint_every or resume):
        raise InputError(
            "--checkpoint-every and --resume need the sequential mode (no --pipelined)"
        )
    check_config_limits(config)
    device = _device(args.device)
    _check_applicable(opts)
    _check_out(out, resume=resume)
    try:
        created = make_dirs(out)
    except OSError as exc:
        raise InputError(f"--out {out}: cannot be created ({exc.strerror or exc})") from None
    had_lock = (out / LOCK_NAME).exists()
    lock = DirectoryLock(out, f"torchratslam run --out {out}").acquire()
    status = {"wrote": False}
    try:
        _run(args, opts, config, out, device, resume, status)
    finally:
        lock.release()
        if not status["wrote"]:  # a run that failed before its first frame leaves OUT as it was
            if not had_lock:
                (out / LOCK_NAME).unlink(missing_ok=True)
            for d in reversed(created):
                try:
                    d.rmdir()
                except OSError:
                    break
    return 0


def _run(
    args: argparse.Namespace,
    opts: dict[str, Any],
    config: Any,
    out: Path,
    device: Any,
    resume: bool,
    status: dict[str, bool],
) -> None:
    """Open the data, run, write the outputs (``status["wrote"]`` once anything is)."""
    import time

    from torchratslam.pipeline import RatSLAM, RunResult
    from torchratslam.readers.datasets import open_data

    limits = {
        "max_speed": opts.get("max_speed") or MAX_SPEED,
        "max_turn_rate": opts.get("max_turn_rate") or MAX_TURN_RATE,
    }
    image_topic, odom_topic = _topics(argparse.Namespace(**opts), config)
    data = open_data(
        opts["data"],
        odometry=opts["odometry"],
        groundtruth=opts["groundtruth"],
        image_topic=image_topic,
        odom_topic=odom_topic,
        **limits,
    )
    odometry: Any = None  # the config's choice (default: the data's odometry)
    odometry_label = None
    if opts["visual_odometry"] or not getattr(data, "has_odometry", True):
        from torchratslam.readers.visual_odometry import VisualOdometry

        odometry = VisualOdometry(config.visual_odometry, mirrored=_mirrored(data))
        odometry_label = "visual"
        if not opts["visual_odometry"]:
            print(
                f"torchratslam run: {opts['data']} has no odometry; using visual odometry",
                file=sys.stderr,
            )
    kwargs: dict[str, Any] = {
        "odometry": odometry,
        "device": device,
        "pipelined": opts["pipelined"],
    }
    if opts["load"]:
        from torchratslam.maps.state import load_state
        from torchratslam.multisession.session import MultiSessionRatSLAM

        stored = [load_state(p) for p in opts["load"]]
        slam = MultiSessionRatSLAM(config, stored, **kwargs)
    else:
        slam = RatSLAM(config, **kwargs)
    skip = 0
    if resume:
        from torchratslam.maps.state import apply_state, load_state, read_map_info

        info = read_map_info(out / STATE_DIR)
        if not info.get("partial"):
            raise InputError(
                f"--resume {out}: the run finished ({info.get('frames', '?')} frames); "
                "nothing to resume"
            )
        apply_state(load_state(out / STATE_DIR), slam)
        _restore_history(slam, out / STATE_DIR / HISTORY)
        skip = int(slam.frame_index)
        if len(slam.trajectory()) != skip:
            raise InputError(f"{out / STATE_DIR}: history and map disagree; start the run again")
    remaining = None if opts["max_frames"] is None else opts["max_frames"] - skip
    record = {
        "format": "torchratslam-run",
        "version": 1,
        "options": opts,
        "config_flat": config.to_flat(),
    }
    extra = {"data": str(opts["data"]), "config": str(opts["config"])}
    if odometry_label:
        extra["odometry"] = odometry_label
    if opts["load"]:
        extra["loaded"] = [str(p) for p in opts["load"]]
    if resume:
        extra["resumed_at_frame"] = skip
    every = args.checkpoint_every
    t0 = time.perf_counter()

    def checkpoint(r: Any) -> None:
        if every and slam.frame_index % every == 0:
            info = {
                "partial": True,
                "stopped_at_frame": int(slam.frame_index),
                "reason": "checkpoint",
            }
            status["wrote"] = True
            _save_state(slam, out, record, info)

    frames = _Frames(data, skip)
    try:
        with frames:
            if remaining is not None and remaining <= 0:
                result = RunResult(0, 0.0, *slam.counts(), slam.timings.summary(), False)
            else:
                result = slam.run(
                    frames,
                    max_frames=remaining,
                    progress=not args.no_progress,
                    callback=checkpoint if every else None,
                )
    except BaseException as exc:
        done = int(slam.frame_index)
        if done <= skip:
            raise  # nothing was mapped: nothing to keep
        reason = "interrupted (Ctrl-C)" if isinstance(exc, KeyboardInterrupt) else _one_line(exc)
        result = RunResult(
            done - skip,
            time.perf_counter() - t0,
            *slam.counts(),
            slam.timings.summary(),
            bool(opts["pipelined"]),
        )
        info = {"partial": True, "stopped_at_frame": done, "reason": reason}
        status["wrote"] = True
        try:
            write_outputs(slam, out, result, data=data, extra=extra, record=record, info=info)
        except (RatSLAMError, OSError) as save_exc:
            print(
                f"torchratslam run: stopped at frame {done} ({reason}) and the map could not "
                f"be saved: {_one_line(save_exc)}",
                file=sys.stderr,
            )
            raise exc from None
        print(
            f"torchratslam run: stopped at frame {done} ({reason}); the map as of frame "
            f"{done} is saved in {out / STATE_DIR} (partial); continue with: "
            f"torchratslam run --resume {out}",
            file=sys.stderr,
        )
        raise
    if result.frames == 0 and not resume:
        raise InputError(f"{opts['data']}: no frames were read; check the dataset")
    status["wrote"] = True
    metrics = write_outputs(
        slam, out, result, data=data, extra=extra, record=record, info={"partial": False}
    )
    line = (
        f"{metrics['frames_this_run']} frames in {metrics['wall_s']:.1f} s "
        f"({metrics['fps']:.1f} frames/s): {metrics['templates']} templates, "
        f"{metrics['experiences']} experiences, {metrics['links']} links"
    )
    if "ate_rmse_m" in metrics:
        ate = metrics["ate_rmse_m"]
        line += f", ATE {ate:.3f} m" if math.isfinite(ate) else ""
    print(f"{line}; wrote {out}")


def _one_line(exc: BaseException) -> str:
    return " ".join(f"{exc}".split()) or type(exc).__name__
