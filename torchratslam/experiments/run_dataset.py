"""Mapping one dataset and writing what ``torchratslam run`` writes (the runner behind
that command): ``metrics.json``, ``experiences.csv``, ``trajectory.csv``, ``map.png``,
``pose_cells.png`` and the saved state.

Everything that can be checked is checked before the first frame (OUT, the data's
counts, the device, the config's limits). One run writes to an OUT at a time (a lock).
When the run stops early (Ctrl-C, a bad frame, any error after frame N), the map as of
frame N is saved in OUT/state, marked partial (metrics.json ``"partial": true``,
``"stopped_at_frame": N``), and the error is raised again; :func:`resume_run` continues
it and ends with the map an uninterrupted run makes, bit for bit. Files in OUT that
torchratslam did not write (its manifest) are never replaced.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from ratslam_graph.atomic import Manifest, atomic_write_text
from ratslam_graph.errors import InputError, RatSLAMError
from torchratslam.protocols import GroundTruthSource
from torchratslam.readers.limits import MAX_SPEED, MAX_TURN_RATE

__all__ = [
    "HISTORY",
    "OUTPUT_FILES",
    "RUN_RECORD",
    "STATE_DIR",
    "bag_topics",
    "check_device",
    "resume_run",
    "run_dataset",
    "summary_line",
    "write_outputs",
]

OUTPUT_FILES = ("metrics.json", "experiences.csv", "trajectory.csv", "map.png", "pose_cells.png")
TUM_FILES = ("tum_experience.txt", "tum_frame.txt", "tum_groundtruth.txt")
STATE_DIR = "state"
RUN_RECORD = "run.json"
HISTORY = "history.npz"


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


def _partial_metrics(metrics: dict[str, Any], slam: Any, info: dict[str, Any]) -> None:
    if info.get("partial"):
        metrics.update(
            partial=True,
            stopped_at_frame=int(info.get("stopped_at_frame", slam.frame_index)),
            reason=str(info.get("reason", "")),
        )


# ----------------------------------------------------------------------- history (resume)
def _history_writer(slam: Any) -> Any:
    """A writer of the per-frame history (trajectory, ground truth, odometry, pose-cell
    centres) that a resumed run needs to give the same outputs as one run."""
    core = getattr(slam, "slam", slam)
    gt = np.asarray(
        [(np.nan, np.nan, np.nan) if p is None else p for p in core._gt], np.float64
    ).reshape(-1, 3)
    arrays: dict[str, Any] = {
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
    core._gt[:] = [
        tuple(float(x) for x in g) if ok else None
        for g, ok in zip(a["gt"], a["gt_ok"], strict=True)
    ]
    core._odo[:] = [tuple(float(x) for x in o) for o in a["odo"]]
    core._pc[:] = [tuple(float(x) for x in c) for c in a["pc"]]


def _save_state(slam: Any, out: Path, record: dict[str, Any], info: dict[str, Any]) -> None:
    """OUT/state (with the history) and OUT/run.json, each atomically; state first."""
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
    metrics.json (last) for a run, finished or stopped (``info["partial"]``), each
    atomically and recorded in OUT's manifest before it is written. With ``record`` (the
    run's options) the state holds the history a resumed run needs and OUT/run.json the
    record. Returns the metrics."""
    info = dict(info or {"partial": False})
    info.setdefault("frames", int(slam.frame_index))
    out.mkdir(parents=True, exist_ok=True)
    if record is not None:
        _save_state(slam, out, record, info)
    else:
        from torchratslam.maps.state import save_state

        Manifest(out).add([STATE_DIR])
        save_state(slam, out / STATE_DIR)
    Manifest(out).add([*OUTPUT_FILES, STATE_DIR])
    poses, traj = _write_tables(slam, out)
    gt_xy, ate, dr = _groundtruth_errors(slam, data, traj)
    metrics = _metrics(slam, result, extra, ate, dr)
    _partial_metrics(metrics, slam, info)
    title = str(extra.get("data", "experience map"))
    _write_figures(slam, out, poses, traj, gt_xy, data, title)
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


# ----------------------------------------------------------------------- checks
def check_device(spec: str | None) -> Any:
    """The torch device ``spec``, checked against this torch build and machine (None:
    the default).

    Raises:
        InputError: not a device, or not usable here.
    """
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
    """The kind of data: sim, bag (ROS 1 or 2, a file or a bag directory), directory, video."""
    from torchratslam.readers.bags import is_bag

    if spec.startswith("sim:"):
        return "sim"
    p = Path(spec)
    if is_bag(p):
        return "bag"
    return "directory" if p.is_dir() else "video"


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
        names = (*OUTPUT_FILES, *TUM_FILES, STATE_DIR, RUN_RECORD)
        theirs = [n for n in names if (out / n).exists()]
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
class _IterSource:
    """An iterable of frames as a reader (``frames()``)."""

    def __init__(self, frames: Any) -> None:
        self._frames = frames

    def frames(self) -> Any:
        return iter(self._frames)


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


# ----------------------------------------------------------------------- the run
def _path_option(v: Any) -> Any:
    return str(Path(v).resolve()) if v and Path(v).exists() else v


def _write_tum(slam: Any, out: Path, recorder: Any, data: Any) -> dict[str, Any]:
    """The TUM files of ``--tum`` and the ATE of each estimate on them (for metrics.json)."""
    from torchratslam.eval.tum import tum_ate, write_tum_files

    table = data.groundtruth() if isinstance(data, GroundTruthSource) else None
    files = write_tum_files(slam, out, recorder=recorder, groundtruth=table)
    extra: dict[str, Any] = {"tum": {k: p.name for k, p in files.items()}}
    if "groundtruth" in files and slam.trajectory().shape[0] >= 2:
        for name in ("experience", "frame"):
            if name in files:
                extra[f"ate_{name}_rmse_m"] = tum_ate(files["groundtruth"], files[name])
    return extra


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
    scale_report: bool = False,
    tum: bool = False,
    rerun: bool = False,
    rerun_save: str | Path | None = None,
    checkpoint_every: int | None = None,
    max_speed: float | None = None,
    max_turn_rate: float | None = None,
) -> dict[str, Any]:
    """Map one dataset (localising in and merging with the ``load`` maps, if any) and
    write OUT; returns the metrics (what ``metrics.json`` holds).

    Everything that can be checked is checked before the first frame. When the run stops
    early after frame N (Ctrl-C, a bad frame, any error), the map as of frame N is saved
    in OUT/state marked partial and the error is raised again; :func:`resume_run`
    continues it.

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
        scale_report: record the cost per frame as the map grows (OUT/scale.json,
            scale.md, scale.png; :mod:`torchratslam.eval.scale`).
        tum: also write TUM trajectories for evo (``tum_experience.txt``,
            ``tum_frame.txt``, ``tum_groundtruth.txt``; :mod:`torchratslam.eval.tum`)
            and the ATE of each estimate on them.
        rerun: watch the run live in a rerun viewer
            (:class:`torchratslam.viz.rerun_viewer.RerunObserver`; extra ``viewer``).
        rerun_save: record the run for rerun into this ``.rrd`` file.
        checkpoint_every: save a loadable partial map in OUT/state every this many frames.
        max_speed, max_turn_rate: odometry rows faster than these (m/s, rad/s) are an
            error (default :mod:`torchratslam.readers.limits`).

    Raises:
        InputError: bad counts, unreadable data, no frames, OUT not usable, options that
            do not apply to the data.
        ConfigError: a bad config or override.
    """
    from torchratslam.config import load_config

    overrides = dict(overrides or {})
    opts: dict[str, Any] = {
        "config": _path_option(config_spec),
        "data": str(_path_option(data_spec)),
        "overrides": overrides,
        "max_frames": max_frames,
        "odometry": _path_option(odometry_file),
        "groundtruth": _path_option(groundtruth),
        "visual_odometry": bool(visual_odometry),
        "load": [_path_option(p) for p in load],
        "pipelined": bool(pipelined),
        "image_topic": image_topic,
        "odom_topic": odom_topic,
        "max_speed": max_speed,
        "max_turn_rate": max_turn_rate,
        "tum": bool(tum),
        "rerun": bool(rerun),
        "rerun_save": None if rerun_save is None else str(rerun_save),
    }
    _check_counts(threads, max_frames, checkpoint_every)
    config = load_config(config_spec, **overrides)
    return _start(
        opts,
        config,
        Path(out),
        device=device,
        resume=False,
        progress=progress,
        threads=threads,
        scale_report=scale_report,
        checkpoint_every=checkpoint_every,
    )


def resume_run(
    out: str | Path,
    *,
    device: str | None = None,
    progress: bool = True,
    threads: int = 1,
    scale_report: bool = False,
    checkpoint_every: int | None = None,
) -> dict[str, Any]:
    """Continue a run that stopped early in ``out``, with the options recorded in
    OUT/run.json; the final map is the one an uninterrupted run makes, bit for bit.
    Returns the metrics.

    Raises:
        InputError: nothing to resume in ``out`` (no record, a finished run, a run with
            loaded maps).
    """
    from torchratslam.config import RatSLAMConfig

    _check_counts(threads, None, checkpoint_every)
    out = Path(out)
    if not out.is_dir():
        raise InputError(f"--resume {out}: not a directory")
    record = _read_record(out)
    opts = record["options"]
    config = RatSLAMConfig.from_flat(record["config_flat"], source=str(out / RUN_RECORD))
    if opts.get("load"):
        raise InputError(f"--resume {out}: runs with --load cannot be resumed yet; re-run")
    return _start(
        opts,
        config,
        out,
        device=device,
        resume=True,
        progress=progress,
        threads=threads,
        scale_report=scale_report,
        checkpoint_every=checkpoint_every,
    )


def _check_counts(threads: int, max_frames: int | None, checkpoint_every: int | None) -> None:
    if threads < 1:
        raise InputError(f"--threads must be >= 1, got {threads}")
    if max_frames is not None and max_frames <= 0:
        raise InputError(f"--max-frames must be a positive number of frames, got {max_frames}")
    if checkpoint_every is not None and checkpoint_every <= 0:
        raise InputError(f"--checkpoint-every must be >= 1 frame, got {checkpoint_every}")


def _start(
    opts: dict[str, Any],
    config: Any,
    out: Path,
    *,
    device: str | None,
    resume: bool,
    progress: bool,
    threads: int,
    scale_report: bool,
    checkpoint_every: int | None,
) -> dict[str, Any]:
    """The checks before the work, OUT's lock, then the run; a run that fails before its
    first frame leaves OUT as it was."""
    import torch

    from torchratslam.config import check_config_limits
    from ratslam_graph.atomic import LOCK_NAME, DirectoryLock, make_dirs

    torch.set_num_threads(threads)
    if opts["pipelined"] and (checkpoint_every or resume):
        raise InputError(
            "--checkpoint-every and --resume need the sequential mode (no --pipelined)"
        )
    check_config_limits(config)
    dev = check_device(device)
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
        return _run(
            opts,
            config,
            out,
            dev,
            resume,
            status,
            progress=progress,
            scale_report=scale_report,
            checkpoint_every=checkpoint_every,
        )
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


def _run(
    opts: dict[str, Any],
    config: Any,
    out: Path,
    device: Any,
    resume: bool,
    status: dict[str, bool],
    *,
    progress: bool,
    scale_report: bool,
    checkpoint_every: int | None,
) -> dict[str, Any]:
    """Open the data, run, write the outputs (``status["wrote"]`` once anything is)."""
    from torchratslam.pipeline import RatSLAM, RunResult
    from torchratslam.readers.datasets import open_data

    image_topic, odom_topic = bag_topics(config, opts["image_topic"], opts["odom_topic"])
    data = open_data(
        opts["data"],
        odometry=opts["odometry"],
        groundtruth=opts["groundtruth"],
        image_topic=image_topic,
        odom_topic=odom_topic,
        max_speed=float(opts.get("max_speed") or MAX_SPEED),
        max_turn_rate=float(opts.get("max_turn_rate") or MAX_TURN_RATE),
    )
    odometry = _odometry_source(config, data, opts["data"], opts["visual_odometry"])
    kwargs: dict[str, Any] = {
        "odometry": odometry,
        "device": device,
        "pipelined": opts["pipelined"],
    }
    if opts["load"]:
        from torchratslam.maps.io import load_state
        from torchratslam.multisession.session import MultiSessionRatSLAM

        slam: Any = MultiSessionRatSLAM(config, [load_state(p) for p in opts["load"]], **kwargs)
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
    extra: dict[str, Any] = {"data": str(opts["data"]), "config": str(opts["config"])}
    if odometry is not None:
        extra["odometry"] = "visual"
    if opts["load"]:
        extra["loaded"] = [str(p) for p in opts["load"]]
    if resume:
        extra["resumed_at_frame"] = skip
    recorder = None
    if scale_report:
        from torchratslam.eval.scale import ScaleRecorder

        recorder = ScaleRecorder(links_of=lambda: slam.experience_map.num_links)
    from torchratslam.eval.tum import FramePoseRecorder

    poses = FramePoseRecorder()  # every frame's pose estimate, for the TUM files
    observer = None
    source: Any = data
    if opts.get("rerun") or opts.get("rerun_save"):
        from torchratslam.viz.rerun_viewer import RerunObserver

        observer = RerunObserver(slam, spawn=bool(opts.get("rerun")), save=opts.get("rerun_save"))
        source = observer.frames(data)
        if not hasattr(source, "frames"):
            source = _IterSource(source)
    every = checkpoint_every
    t0 = time.perf_counter()

    def on_step(r: Any) -> None:
        poses(r)
        if observer is not None:
            observer(r)
        if recorder is not None:
            recorder.on_step(r)
        if every and slam.frame_index % every == 0:
            info = {
                "partial": True,
                "stopped_at_frame": int(slam.frame_index),
                "reason": "checkpoint",
            }
            status["wrote"] = True
            _save_state(slam, out, record, info)

    frames = _Frames(source, skip)
    try:
        with frames:
            if remaining is not None and remaining <= 0:
                n_t, n_e, n_l = slam.counts()
                result = RunResult(0, 0.0, n_t, n_e, n_l, slam.timings.summary(), False)
            else:
                result = slam.run(
                    frames,
                    max_frames=remaining,
                    progress=progress,
                    callback=on_step,
                )
    except BaseException as exc:
        done = int(slam.frame_index)
        if done <= skip:
            raise  # nothing was mapped: nothing to keep
        reason = "interrupted (Ctrl-C)" if isinstance(exc, KeyboardInterrupt) else _one_line(exc)
        n_t, n_e, n_l = slam.counts()
        result = RunResult(
            done - skip,
            time.perf_counter() - t0,
            n_t,
            n_e,
            n_l,
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
    finally:
        if observer is not None:
            observer.close()
    if result.frames == 0 and not resume:
        raise InputError(f"{opts['data']}: no frames were read; check the dataset")
    status["wrote"] = True
    if opts.get("tum"):
        Manifest(out).add(list(TUM_FILES))  # recorded before they are written
        extra.update(_write_tum(slam, out, poses, data))
    metrics = write_outputs(
        slam, out, result, data=data, extra=extra, record=record, info={"partial": False}
    )
    if recorder is not None and len(recorder.templates):
        Manifest(out).add(["scale.json", "scale.md", "scale.png"])
        metrics["scale"] = _write_scale_report(recorder, slam, out, str(opts["data"]))
    return metrics


def _one_line(exc: BaseException) -> str:
    return " ".join(f"{exc}".split()) or type(exc).__name__


def _write_scale_report(recorder: Any, slam: Any, out: Path, label: str) -> dict[str, Any]:
    """OUT/scale.json, scale.md and scale.png of a run recorded with ``scale_report``."""
    from torchratslam.eval.scale import format_scale_table
    from torchratslam.viz.scale import plot_scale

    report = recorder.report(slam.timings, parts=min(10, len(recorder.templates)))
    atomic_write_text(out / "scale.json", json.dumps(report, indent=2) + "\n")
    atomic_write_text(out / "scale.md", format_scale_table(report, title=label) + "\n")
    plot_scale(out / "scale.png", {"torchratslam": report}, title=label)
    return {k: report[k] for k in ("last_over_first", "peak_memory_mb")}


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
        if "ate_frame_rmse_m" in metrics:
            line += f" (per-frame pose {metrics['ate_frame_rmse_m']:.3f} m)"
        dr = metrics.get("dead_reckoning_ate_m")
        if dr is not None and math.isfinite(dr):
            line += f" vs dead reckoning {dr:.3f} m"
    if "loaded" in metrics:  # a multisession run
        merges = metrics.get("merges")
        n_merges = len(merges) if isinstance(merges, (list, dict)) else 0
        line += f", {n_merges} merge{'s' if n_merges != 1 else ''}"
    return f"{line}; wrote {out}"
