"""Mapping one dataset and writing what ``torchratslam run`` writes (the runner behind
that command): ``metrics.json``, ``experiences.csv``, ``trajectory.csv``, ``map.png``,
``pose_cells.png`` and the saved state (:mod:`torchratslam.experiments.run_outputs`).

Everything that can be checked is checked before the first frame (OUT, the data's
counts, the device, the config's limits; :mod:`torchratslam.experiments.run_checks`). One
run writes to an OUT at a time (a lock). The run saves a checkpoint (a loadable partial
map) every :data:`DEFAULT_CHECKPOINT_EVERY` frames unless told otherwise, so a crash, an
out-of-memory kill or a power cut loses at most that many frames. When the run stops
early (Ctrl-C, a bad frame, any error after frame N), the map as of frame N is saved in
OUT/state, marked partial (metrics.json ``"partial": true``, ``"stopped_at_frame": N``),
and the error is raised again; :func:`resume_run` continues a stopped or killed run and
ends with the map an uninterrupted run makes, bit for bit
(:mod:`torchratslam.experiments.run_state`). A new run refuses an OUT that holds a
run, stopped or finished, unless told to overwrite it. Files in OUT that torchratslam did not write
(its manifest) are never replaced.
"""

from __future__ import annotations

import dataclasses
import logging
import sys
import time
from pathlib import Path
from typing import Any

from ratslam_graph.atomic import Manifest
from torchratslam.errors import InputError, RatSLAMError, option
from torchratslam.experiments import run_state
from torchratslam.experiments.run_checks import (
    check_applicable,
    check_counts,
    check_device,
    check_inputs_apart,
    check_out,
)
from torchratslam.experiments.run_options import RunOptions, RunSettings
from torchratslam.experiments.run_outputs import (
    SCALE_FILES,
    TUM_FILES,
    RunExtras,
    RunMetrics,
    write_outputs,
    write_scale_report,
    write_tum,
)
from torchratslam.experiments.run_state import (
    HISTORY,
    RUN_RECORD,
    STATE_DIR,
    RunRecord,
    SaveError,
    finished_run,
    new_run_id,
    stopped_run,
    write_record,
)
from torchratslam.readers.limits import MAX_SPEED, MAX_TURN_RATE

__all__ = ["DEFAULT_CHECKPOINT_EVERY", "bag_topics", "resume_run", "run_dataset"]

log = logging.getLogger(__name__)

DEFAULT_CHECKPOINT_EVERY = 1000
"""Frames between two checkpoints when the settings do not say (0 turns them off)."""


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


# ----------------------------------------------------------------------- the run
def _path_option(v: Any) -> Any:
    return str(Path(v).resolve()) if v and Path(v).exists() else v


def run_dataset(
    options: RunOptions, out: str | Path, settings: RunSettings | None = None
) -> RunMetrics:
    """Map one dataset (localising in and merging with the ``options.load`` maps, if any)
    and write OUT; returns the metrics (what ``metrics.json`` holds).

    Everything that can be checked is checked before the first frame. A checkpoint is
    saved every ``settings.checkpoint_every`` frames (default
    :data:`DEFAULT_CHECKPOINT_EVERY`; 0: none). When the run stops early after frame N
    (Ctrl-C, a bad frame, any error), the map as of frame N is saved in OUT/state marked
    partial and the error is raised again; :func:`resume_run` continues it, or a run
    killed without a word (from its last checkpoint).

    Args:
        options: what to map and how (recorded in OUT/run.json; existing paths in it are
            recorded resolved).
        out: the output folder.
        settings: how this process runs it (default :class:`RunSettings`).

    Raises:
        InputError: bad counts, unreadable data, no frames, OUT not usable (or holding a
            stopped run, unless ``settings.overwrite``), options that do not apply to
            the data.
        ConfigError: a bad config or override.
        SaveError: a checkpoint or an output could not be written (the message names
            the file and says how to resume).
    """
    from torchratslam.config import load_config

    settings = settings or RunSettings()
    overrides = dict(options.overrides or {})
    opts = dataclasses.replace(
        options,
        config=_path_option(options.config),
        data=str(_path_option(options.data)),
        overrides=overrides,
        odometry=_path_option(options.odometry),
        groundtruth=_path_option(options.groundtruth),
        visual_odometry=bool(options.visual_odometry),
        load=tuple(_path_option(p) for p in options.load),
        pipelined=bool(options.pipelined),
        tum=bool(options.tum),
        rerun=bool(options.rerun),
        rerun_save=None if options.rerun_save is None else str(options.rerun_save),
    )
    check_counts(settings.threads, options.max_frames, settings.checkpoint_every)
    config = load_config(options.config, **overrides)
    return _start(opts, config, Path(out), settings, run_id=new_run_id(), resume=False)


def resume_run(out: str | Path, settings: RunSettings | None = None) -> RunMetrics:
    """Continue a run that stopped early in ``out`` (stopped with a message, or killed:
    from its last checkpoint, or from the first frame when it saved none), with the
    options recorded in OUT/run.json; the final map is the one an uninterrupted run
    makes, bit for bit. Returns the metrics.

    Raises:
        InputError: nothing to resume in ``out`` (no record, a finished run).
    """
    from torchratslam.config import RatSLAMConfig

    settings = settings or RunSettings()
    check_counts(settings.threads, None, settings.checkpoint_every)
    out = Path(out)
    if not out.is_dir():
        raise InputError(f"--resume {out}: not a directory")
    record = run_state.read_record(out)
    if stopped_run(out) is None:
        frames = _finished_frames(out)
        raise InputError(f"--resume {out}: the run finished ({frames} frames); nothing to resume")
    opts = RunOptions.from_record(record["options"])
    flat = dict(record["config_flat"])
    if "dtype" not in flat:  # recorded before the key existed, when float32 was the default
        flat["dtype"] = "float32"
        log.warning(
            "%s: the run began before double precision became the default; it goes on in "
            "float32, as it began",
            out,
        )
    config = RatSLAMConfig.from_flat(flat, source=str(out / RUN_RECORD))
    run_id = str(record.get("run_id") or "")
    return _start(opts, config, out, settings, run_id=run_id, resume=True)


def _finished_frames(out: Path) -> Any:
    from torchratslam.maps.native import read_map_info

    try:
        return read_map_info(out / STATE_DIR).get("frames", "?")
    except (RatSLAMError, OSError):
        return "?"


def _checkpoint_every(opts: RunOptions, settings: RunSettings) -> int:
    """Frames between checkpoints (0: none): the settings', else the default; a
    pipelined run saves none unless asked (and then refuses)."""
    if settings.checkpoint_every is not None:
        return int(settings.checkpoint_every)
    return 0 if opts.pipelined else DEFAULT_CHECKPOINT_EVERY


def _start(
    opts: RunOptions,
    config: Any,
    out: Path,
    settings: RunSettings,
    *,
    run_id: str,
    resume: bool,
) -> RunMetrics:
    """The checks before the work, OUT's lock, then the run; a run that fails before its
    first frame leaves OUT as it was."""
    import torch

    from ratslam_graph.atomic import LOCK_NAME, DirectoryLock, make_dirs
    from torchratslam.config import check_config_limits

    torch.set_num_threads(settings.threads)
    if opts.pipelined and (settings.checkpoint_every or resume):
        raise InputError(
            "--checkpoint-every and --resume need the sequential mode (no --pipelined)"
        )
    check_config_limits(config)
    dev = check_device(settings.device)
    check_applicable(opts)
    check_inputs_apart(out, opts)
    check_out(out, resume=resume)
    try:
        created = make_dirs(out)
    except OSError as exc:
        raise InputError(f"--out {out}: cannot be created ({exc.strerror or exc})") from None
    had_lock = (out / LOCK_NAME).exists()
    lock = DirectoryLock(out, f"torchratslam run --out {out}").acquire()
    status = {"wrote": False}
    try:
        if not resume and not settings.overwrite:
            if finished_run(out):
                raise InputError(
                    f"{out} holds a finished run; choose another {option('--out', 'out')}, or "
                    f"replace it with {option('--overwrite', 'RunSettings(overwrite=True)')}"
                )
            stopped = stopped_run(out)
            if stopped is not None:
                raise InputError(
                    f"{out} holds a run that {stopped}; continue it with: "
                    f"{option(f'torchratslam run --resume {out}', f'resume_run({str(out)!r})')}"
                    f" (or start it again with "
                    f"{option('--overwrite', 'RunSettings(overwrite=True)')})"
                )
        record = RunRecord(options=opts, config_flat=config.to_flat(), run_id=run_id)
        return _run(opts, config, out, dev, resume, status, settings, record)
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


def _own_state_info(out: Path, run_id: str) -> dict[str, Any] | None:
    """The info of OUT/state when it is a state this run saved (None: no state, or one
    of another run)."""
    from torchratslam.maps.native import read_map_info

    if not (out / STATE_DIR).is_dir():
        return None
    info = read_map_info(out / STATE_DIR)
    if "run_id" in info and run_id and info["run_id"] != run_id:
        return None
    return info


def _open(
    opts: RunOptions, config: Any, out: Path, device: Any, resume: bool, run_id: str
) -> tuple[Any, Any, Any, int]:
    """The data, the odometry source (None: the config's), the mapper (its state and
    history restored on ``resume``) and the frames already mapped."""
    from torchratslam.pipeline import RatSLAM
    from torchratslam.readers.datasets import open_data

    image_topic, odom_topic = bag_topics(config, opts.image_topic, opts.odom_topic)
    data = open_data(
        opts.data,
        odometry=opts.odometry,
        groundtruth=opts.groundtruth,
        image_topic=image_topic,
        odom_topic=odom_topic,
        max_speed=float(opts.max_speed or MAX_SPEED),
        max_turn_rate=float(opts.max_turn_rate or MAX_TURN_RATE),
    )
    odometry = _odometry_source(config, data, opts.data, opts.visual_odometry)
    kwargs: dict[str, Any] = {
        "odometry": odometry,
        "device": device,
        "pipelined": opts.pipelined,
    }
    if opts.load:
        from torchratslam.multisession.session import MultiSessionRatSLAM

        stored = run_state.loaded_maps(out, tuple(opts.load), resume=resume)
        slam: Any = MultiSessionRatSLAM(config, stored, **kwargs)
    else:
        slam = RatSLAM(config, **kwargs)
    skip = 0
    info = _own_state_info(out, run_id) if resume else None
    if info is None and resume:
        print(
            f"torchratslam run: {out} holds no checkpoint of the stopped run; mapping it "
            "again from its first frame",
            file=sys.stderr,
        )
    if info is not None:
        from torchratslam.maps.native import load_state
        from torchratslam.maps.running import apply_state

        apply_state(load_state(out / STATE_DIR), slam)
        run_state.restore_history(slam, out / STATE_DIR / HISTORY)
        run_state.restore_multisession(slam, info)
        skip = int(slam.frame_index)
        if len(slam.trajectory()) != skip:
            raise InputError(f"{out / STATE_DIR}: history and map disagree; start the run again")
    return data, odometry, slam, skip


def _run(
    opts: RunOptions,
    config: Any,
    out: Path,
    device: Any,
    resume: bool,
    status: dict[str, bool],
    settings: RunSettings,
    record: RunRecord,
) -> RunMetrics:
    """Open the data, run, write the outputs (``status["wrote"]`` once anything is)."""
    from torchratslam.pipeline import RunResult

    data, odometry, slam, skip = _open(opts, config, out, device, resume, record.run_id)
    remaining = None if opts.max_frames is None else opts.max_frames - skip
    extras = RunExtras(
        data=str(opts.data),
        config=str(opts.config),
        odometry="visual" if odometry is not None else None,
        loaded=tuple(str(p) for p in opts.load) if opts.load else None,
        resumed_at_frame=skip if resume else None,
    )
    recorder = None
    if settings.scale_report:
        from torchratslam.eval.scale import ScaleRecorder

        recorder = ScaleRecorder(links_of=lambda: slam.experience_map.num_links)
    from torchratslam.eval.tum import FramePoseRecorder

    poses = FramePoseRecorder()  # every frame's pose estimate, for the TUM files
    observer = None
    source: Any = data
    if opts.rerun or opts.rerun_save:
        from torchratslam.viz.rerun_viewer import RerunObserver

        observer = RerunObserver(slam, spawn=bool(opts.rerun), save=opts.rerun_save)
        source = observer.frames(data)
        if not hasattr(source, "frames"):
            source = _IterSource(source)
    every = _checkpoint_every(opts, settings)
    saved = {"frame": skip if skip else None}  # the last good checkpoint
    t0 = time.perf_counter()

    def on_step(r: Any) -> None:
        poses(r)
        if observer is not None:
            observer(r)
        if recorder is not None:
            recorder.on_step(r)
        if not status["wrote"]:  # OUT now holds a run that can be resumed
            status["wrote"] = True
            if opts.load:  # a resumed run reads its stored maps from OUT, not from --load
                _saving(
                    lambda: run_state.keep_loaded(slam, out, replace=not resume),
                    out,
                    out / run_state.LOADED_DIR,
                    saved["frame"],
                )
            _saving(lambda: write_record(out, record), out, out / RUN_RECORD, saved["frame"])
        if every and slam.frame_index % every == 0:
            info = {
                "partial": True,
                "stopped_at_frame": int(slam.frame_index),
                "reason": "checkpoint",
            }
            _saving(
                lambda: run_state.save_run_state(slam, out, record, info),
                out,
                out / STATE_DIR,
                saved["frame"],
            )
            saved["frame"] = int(slam.frame_index)

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
                    progress=f"run {opts.data}" if settings.progress else False,
                    callback=on_step,
                )
    except BaseException as exc:
        done = int(slam.frame_index)
        if done <= skip or isinstance(exc, SaveError):
            raise  # nothing was mapped, or nothing can be written: nothing to keep
        reason = "interrupted (Ctrl-C)" if isinstance(exc, KeyboardInterrupt) else _one_line(exc)
        n_t, n_e, n_l = slam.counts()
        result = RunResult(
            done - skip,
            time.perf_counter() - t0,
            n_t,
            n_e,
            n_l,
            slam.timings.summary(),
            bool(opts.pipelined),
        )
        info = {"partial": True, "stopped_at_frame": done, "reason": reason}
        status["wrote"] = True
        try:
            write_outputs(slam, out, result, data=data, extras=extras, record=record, info=info)
        except (RatSLAMError, OSError) as save_exc:
            print(
                f"torchratslam run: stopped at frame {done} ({reason}) and the map could not "
                f"be saved: {_one_line(save_exc)}; {_kept(out, saved['frame'])}",
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
        raise InputError(f"{opts.data}: no frames were read; check the dataset")
    status["wrote"] = True
    try:
        if opts.tum:
            Manifest(out).add(list(TUM_FILES))  # recorded before they are written
            extras = dataclasses.replace(extras, **write_tum(slam, out, poses, data))
        metrics = write_outputs(
            slam,
            out,
            result,
            data=data,
            extras=extras,
            record=record,
            info={"partial": False},
            frame_poses=_frame_poses(poses, slam) if not skip else None,
        )
        if recorder is not None and len(recorder.templates):
            Manifest(out).add(list(SCALE_FILES))
            scale = write_scale_report(recorder, slam, out, str(opts.data))
            metrics = dataclasses.replace(metrics, scale=scale)
        write_record(out, dataclasses.replace(record, finished=True))  # last of all
    except OSError as exc:
        raise _save_error(exc, out, out, saved["frame"]) from None
    run_state.drop_loaded(out)  # a finished run cannot be resumed: its copies are done with
    return metrics


def _frame_poses(recorder: Any, slam: Any) -> Any:
    """Every frame's pose estimate (None when the recorder missed frames)."""
    try:
        return recorder.poses(slam)
    except (RatSLAMError, ValueError, IndexError):
        return None


def _kept(out: Path, frame: int | None) -> str:
    """What is kept after a failed save, and how to go on."""
    if frame is None:
        kept = "no checkpoint was saved yet (a resumed run maps from the first frame)"
    else:
        kept = f"the last checkpoint (frame {frame}) is kept in {out / STATE_DIR}"
    return f"{kept}; free space, then continue with: torchratslam run --resume {out}"


def _save_error(exc: OSError, out: Path, target: Path, frame: int | None) -> SaveError:
    name = exc.filename if exc.filename else target
    why = exc.strerror or _one_line(exc)
    return SaveError(f"cannot write {name} ({why}); {_kept(out, frame)}")


def _saving(save: Any, out: Path, target: Path, frame: int | None) -> None:
    """``save()``; an OS error (a full disk) becomes a :class:`SaveError` naming the file
    and the last good checkpoint (atomic writes leave that one whole)."""
    try:
        save()
    except OSError as exc:
        raise _save_error(exc, out, target, frame) from None


def _one_line(exc: BaseException) -> str:
    return " ".join(f"{exc}".split()) or type(exc).__name__
