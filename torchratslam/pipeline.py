"""The RatSLAM pipeline: local view, pose cells, odometry source and experience map.

Modules are chosen by name from the registries of :mod:`torchratslam.registry`
(xRatSLAM's swappable modules, without an if-chain factory), or passed as instances:

==================  ==================================================================
registry            factory signature (what a user-registered module must accept)
==================  ==================================================================
``LOCAL_VIEWS``     ``factory(params: LocalViewParams, *, dtype, device)``
``POSE_CELLS``      ``factory(params: PoseCellParams, *, dtype, device)``
``EXPERIENCE_MAPS`` ``factory(params: ExperienceMapParams)``
``ODOMETRY``        ``factory(params: VisualOdometryParams)``; the source is called
                    with each :class:`~torchratslam.messages.Frame` and returns
                    ``(vtrans, vrot, dt)``
==================  ==================================================================

Default names: local view ``"ratslam"``, pose cells ``"ratslam"``, experience map
``"ratslam"`` (:class:`ratslam_graph.experience_map.ExperienceMap`, registered here) and
odometry ``"given"`` (the reader's wheel odometry) or ``"visual"`` (intensity-profile
visual odometry), both registered here.

Per frame, in the reference's order: odometry source on the frame; local view on the
image; pose cells on the template (``on_view_template``); pose cells on the odometry
(``on_odometry``, returning the :class:`~ratslam_graph.messages.Action`); experience map on the
odometry, then ``apply(action, ...)`` and ``iterate()`` (relaxation).

The pipelined mode (``pipelined=True``) runs the reader + odometry + local view, the
pose cells and the experience map in three worker threads joined by bounded queues
(size 10, as in xRatSLAM). Each module still sees exactly the same messages in the same
order, so the map is identical to the sequential mode's.

Example:
    >>> from torchratslam import load_config  # doctest: +SKIP
    >>> from torchratslam.pipeline import RatSLAM  # doctest: +SKIP
    >>> from torchratslam.readers.datasets import open_data  # doctest: +SKIP
    >>> slam = RatSLAM(load_config("virtual_tour"))  # doctest: +SKIP
    >>> result = slam.run(open_data("sim:virtual_tour"), max_frames=500)  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import gc
import importlib
import itertools
import logging
import math
import queue
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sized
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from torchratslam.config import RatSLAMConfig, VisualOdometryParams
from ratslam_graph.errors import InputError
from ratslam_graph.messages import Action, ActionKind
from torchratslam.messages import Frame, ViewMatch
from torchratslam.protocols import FrameSource
from torchratslam.readers.visual_odometry import GivenOdometry, VisualOdometry
from torchratslam.registry import EXPERIENCE_MAPS, LOCAL_VIEWS, ODOMETRY, POSE_CELLS, Registry
from torchratslam.timing import TimeLogger

__all__ = ["QUEUE_SIZE", "RatSLAM", "RunResult", "StepResult"]

log = logging.getLogger(__name__)

QUEUE_SIZE = 10
"""Capacity of the queues between the pipelined mode's worker threads (xRatSLAM's)."""


# ----------------------------------------------------------------------------- defaults
def _experience_map_factory(params: Any) -> Any:
    from ratslam_graph.experience_map import ExperienceMap

    return ExperienceMap(params)


def _given_odometry(params: VisualOdometryParams | None = None) -> GivenOdometry:
    return GivenOdometry(params)


def _visual_odometry(params: VisualOdometryParams | None = None) -> VisualOdometry:
    return VisualOdometry(params)


if "ratslam" not in EXPERIENCE_MAPS:
    EXPERIENCE_MAPS.register("ratslam", _experience_map_factory)
if "given" not in ODOMETRY:
    ODOMETRY.register("given", _given_odometry)
if "visual" not in ODOMETRY:
    ODOMETRY.register("visual", _visual_odometry)

_DEFAULT_MODULES = ("torchratslam.local_view.view", "torchratslam.pose_cells.network")


def _load_default_modules() -> None:
    """Import the modules that register the default local view and pose cells."""
    for name in _DEFAULT_MODULES:
        try:
            importlib.import_module(name)
        except ModuleNotFoundError as exc:  # only tolerate the module itself being absent
            if exc.name != name:
                raise


def _build(registry: Registry, spec: Any, *args: Any, **kwargs: Any) -> Any:
    return registry.build(spec, *args, **kwargs)


def _centre(pose_cells: Any) -> tuple[float, float, float]:
    c = pose_cells.centre
    if callable(c):
        c = c()
    if isinstance(c, torch.Tensor):
        c = c.detach().reshape(-1).cpu().tolist()
    x, y, th = (float(v) for v in list(c)[:3])
    return x, y, th


def _n_experiences(em: Any) -> int:
    try:
        return len(em)
    except TypeError:
        return int(np.asarray(em.poses).shape[0])


# ----------------------------------------------------------------------------- results
@dataclass(frozen=True)
class StepResult:
    """What one frame did.

    Attributes:
        frame: 0-based index of the frame in this run.
        t: its timestamp (s).
        view: the local view's match (template id, relative angle, is_new, ...).
        action: the pose cells' action for the experience map.
        odometry: ``(vtrans, vrot, dt)`` used.
        pc: pose-cell packet centre ``(x, y, th)`` in cells after the step.
        experience_id: the experience current after the step.
        templates: number of templates after the step.
        experiences: number of experiences after the step.
    """

    frame: int
    t: float
    view: ViewMatch
    action: Action
    odometry: tuple[float, float, float]
    pc: tuple[float, float, float]
    experience_id: int
    templates: int
    experiences: int


@dataclass
class RunResult:
    """Summary of :meth:`RatSLAM.run`.

    Attributes:
        frames: frames processed by this call.
        wall_s: wall-clock time of the call (s).
        templates, experiences, links: map size at the end.
        timings: :meth:`TimeLogger.summary` of the whole session (ms per frame per module).
        pipelined: whether the pipelined mode ran.
    """

    frames: int
    wall_s: float
    templates: int
    experiences: int
    links: int
    timings: dict[str, dict[str, Any]] = field(default_factory=dict)
    pipelined: bool = False

    @property
    def fps(self) -> float:
        """Frames per second of wall-clock time."""
        return self.frames / self.wall_s if self.wall_s > 0 else 0.0


_STOP = object()


# ----------------------------------------------------------------------------- RatSLAM
class RatSLAM:
    """A complete RatSLAM system.

    Args:
        config: all module parameters.
        local_view, pose_cells, experience_map, odometry: a registered name, a class
            (called like the registry's factory) or a ready instance; None takes the
            name from the config's ``general`` section when it has such a key, else
            ``"ratslam"`` (``"given"`` for the odometry).
        dtype, device: for the torch modules (local view, pose cells).
        pipelined: default mode of :meth:`run` (one worker thread per module).

    Attributes:
        config, local_view, pose_cells, experience_map, odometry: the modules.
        frame_index: frames processed so far.
        timings: the :class:`~torchratslam.timing.TimeLogger` (per-frame ms per module).

    The per-frame history (frame, time, current experience, ground truth, odometry) is
    kept for :meth:`trajectory`, :meth:`ate` and :meth:`dead_reckoning_ate`.
    """

    def __init__(
        self,
        config: RatSLAMConfig | None = None,
        *,
        local_view: Any = None,
        pose_cells: Any = None,
        experience_map: Any = None,
        odometry: Any = None,
        dtype: torch.dtype = torch.float32,
        device: torch.device | str | None = None,
        pipelined: bool = False,
    ) -> None:
        _load_default_modules()
        self.config = config if config is not None else RatSLAMConfig()
        general = self.config.general
        if local_view is None:
            local_view = getattr(general, "local_view", "ratslam")
        if pose_cells is None:
            pose_cells = getattr(general, "pose_cells", "ratslam")
        if experience_map is None:
            experience_map = getattr(general, "experience_map", "ratslam")
        if odometry is None:
            odometry = getattr(general, "odometry", "given")
        self.dtype, self.device = dtype, device
        self.pipelined = pipelined
        self.local_view = _build(
            LOCAL_VIEWS, local_view, self.config.local_view, dtype=dtype, device=device
        )
        self.pose_cells = _build(
            POSE_CELLS, pose_cells, self.config.pose_cells, dtype=dtype, device=device
        )
        self.experience_map = _build(EXPERIENCE_MAPS, experience_map, self.config.experience_map)
        self.odometry = _build(ODOMETRY, odometry, self.config.visual_odometry)
        self.odometry_name = odometry if isinstance(odometry, str) else type(self.odometry).__name__
        self.frame_index = 0
        self.timings = TimeLogger()
        self._frames: list[int] = []
        self._t: list[float] = []
        self._exp: list[int] = []
        self._gt: list[tuple[float, float, float] | None] = []
        self._odo: list[tuple[float, float, float]] = []
        self._pc: list[tuple[float, float, float]] = []
        self._last_t = 0.0

    # ------------------------------------------------------------------ module swapping
    def set_local_view(self, module: Any) -> None:
        """Replace the local view (a registered name, a class or an instance)."""
        self.local_view = _build(
            LOCAL_VIEWS, module, self.config.local_view, dtype=self.dtype, device=self.device
        )

    def set_pose_cells(self, module: Any) -> None:
        """Replace the pose-cell module (a registered name, a class or an instance)."""
        self.pose_cells = _build(
            POSE_CELLS, module, self.config.pose_cells, dtype=self.dtype, device=self.device
        )

    def set_experience_map(self, module: Any) -> None:
        """Replace the experience map (a registered name, a class or an instance)."""
        self.experience_map = _build(EXPERIENCE_MAPS, module, self.config.experience_map)

    def set_odometry(self, module: Any) -> None:
        """Replace the odometry source (``"given"``, ``"visual"``, a class or an instance)."""
        self.odometry = _build(ODOMETRY, module, self.config.visual_odometry)
        self.odometry_name = module if isinstance(module, str) else type(self.odometry).__name__

    # ------------------------------------------------------------------ internal state
    @property
    def templates(self) -> torch.Tensor:
        """The local view's templates. Shape: ``(N, Y, X)``."""
        return self.local_view.templates

    @property
    def activity(self) -> torch.Tensor:
        """The pose-cell activity. Shape: ``(TH, Y, X)``."""
        return self.pose_cells.activity

    @property
    def graph(self) -> Any:
        """The experience graph (``networkx.DiGraph``)."""
        return self.experience_map.graph

    def counts(self) -> tuple[int, int, int]:
        """``(templates, experiences, links)`` now."""
        em = self.experience_map
        n_links = getattr(em, "num_links", None)
        if n_links is None:
            n_links = em.graph.number_of_edges()
        return len(self.local_view), _n_experiences(em), int(n_links)

    # ------------------------------------------------------------------ one frame
    def _stage_view(self, frame: Frame, index: int) -> tuple[tuple[float, float, float], ViewMatch]:
        with self.timings.section("odometry"):
            odo = tuple(float(v) for v in self.odometry(frame))
        if frame.image is None:
            raise InputError(
                f"frame {frame.index}: no image; the local view needs one in every frame"
            )
        with self.timings.section("local_view"):
            view = self.local_view.process(frame.image, frame_index=index)
        return odo, view  # type: ignore[return-value]

    def _skips_odometry(self, index: int) -> bool:
        """OpenRatSLAM's nodes skip their first odometry message (``skip_first_odometry``)."""
        return index == 0 and bool(getattr(self.config.general, "skip_first_odometry", False))

    def _stage_pose_cells(
        self, view: ViewMatch, odo: tuple[float, float, float], index: int = -1
    ) -> tuple[Action, tuple[float, float, float]]:
        pcs = self.pose_cells
        with self.timings.section("pose_cells"):
            pcs.on_view_template(view)
            if self._skips_odometry(index):
                action = Action.none()
            else:
                action = pcs.on_odometry(*odo)
                if (
                    action.kind != ActionKind.NONE
                    and getattr(self.config.general, "action_angle", "view") == "injection"
                    and hasattr(pcs, "vt_delta_pc_th")
                ):
                    # OpenRatSLAM's get_relative_rad(): the angle of the last injection
                    rad = pcs.vt_delta_pc_th * 2.0 * math.pi / pcs.dims[2]
                    action = dataclasses.replace(action, relative_rad=rad)
            pc = _centre(pcs)
        return action, pc

    def _stage_experience_map(
        self,
        frame: Frame,
        index: int,
        view: ViewMatch,
        odo: tuple[float, float, float],
        action: Action,
        pc: tuple[float, float, float],
    ) -> int:
        em = self.experience_map
        relax = getattr(getattr(em, "params", None), "exp_relax", "every_frame")
        with self.timings.section("experience_map"):
            if not self._skips_odometry(index):
                em.on_odometry(*odo)
            em.apply(
                action, frame=index, t=float(frame.t), pc=pc, template_id=int(view.template_id)
            )
            if relax == "every_frame" or action.kind != ActionKind.NONE:
                em.iterate()
        return int(em.current_id)

    def _finish(
        self,
        frame: Frame,
        index: int,
        view: ViewMatch,
        odo: tuple[float, float, float],
        action: Action,
        pc: tuple[float, float, float],
        exp_id: int,
        counts: tuple[int, int] | None = None,
    ) -> StepResult:
        self._frames.append(index)
        self._t.append(float(frame.t))
        self._exp.append(exp_id)
        self._gt.append(None if frame.pose is None else tuple(float(v) for v in frame.pose))  # type: ignore[arg-type]
        self._odo.append(odo)
        self._pc.append(pc)
        self._last_t = float(frame.t)
        n_t, n_e = counts if counts is not None else self.counts()[:2]
        return StepResult(index, float(frame.t), view, action, odo, pc, exp_id, n_t, n_e)

    def step_frame(self, frame: Frame) -> StepResult:
        """Process one frame (sequentially) and return what it did."""
        index = self.frame_index
        odo, view = self._stage_view(frame, index)
        action, pc = self._stage_pose_cells(view, odo, index)
        exp_id = self._stage_experience_map(frame, index, view, odo, action, pc)
        self.frame_index += 1
        return self._finish(frame, index, view, odo, action, pc, exp_id)

    def step(
        self, image: np.ndarray | torch.Tensor, odometry: tuple[float, float, float] | None = None
    ) -> StepResult:
        """Process one image with its odometry.

        Args:
            image: the camera image. Shape: ``(H, W)`` grey or ``(H, W, 3)``.
            odometry: ``(vtrans m/s, vrot rad/s, dt s)`` over the interval ending at
                this image; None when the odometry source is visual.

        Raises:
            InputError: no odometry given while the odometry source needs it.
        """
        if odometry is None:
            if isinstance(self.odometry, GivenOdometry):
                raise InputError(
                    "step() got no odometry but the odometry source is 'given'; pass "
                    "(vtrans, vrot, dt) or build RatSLAM(..., odometry='visual')"
                )
        if isinstance(image, torch.Tensor):
            image = image.detach().cpu().numpy()
        if odometry is None:  # the source estimates it; timestamps at the camera rate
            vtrans, vrot, dt = 0.0, 0.0, 0.0
            t = self._last_t + 1.0 / self.config.visual_odometry.camera_hz
        else:
            vtrans, vrot, dt = (float(v) for v in odometry)
            t = self._last_t + dt
        t = t if self.frame_index else 0.0
        frame = Frame(self.frame_index, t, np.asarray(image), vtrans=vtrans, vrot=vrot, dt=dt)
        return self.step_frame(frame)

    # ------------------------------------------------------------------ whole runs
    def run(
        self,
        frames: Iterable[Frame] | Any,
        *,
        max_frames: int | None = None,
        progress: bool = True,
        pipelined: bool | None = None,
        callback: Callable[[StepResult], None] | None = None,
    ) -> RunResult:
        """Process a sequence of frames.

        Args:
            frames: an iterable of :class:`Frame`, or a reader / simulator session
                (anything with ``frames()``).
            max_frames: stop after this many frames.
            progress: show a tqdm progress bar (frames/s, templates, experiences).
            pipelined: one worker thread per module (default: the constructor's).
            callback: called with every :class:`StepResult`, in order.

        Returns:
            :class:`RunResult`.
        """
        total = len(frames) if isinstance(frames, Sized) else None
        it: Iterator[Frame] = iter(frames.frames() if isinstance(frames, FrameSource) else frames)
        if (
            isinstance(frames, FrameSource)
            and not getattr(frames, "has_odometry", True)
            and isinstance(self.odometry, GivenOdometry)
        ):
            log.warning(
                "%s carries no odometry but the odometry source is 'given' (zero "
                "motion); build RatSLAM(..., odometry='visual') to estimate it",
                getattr(frames, "name", "the data"),
            )
        if max_frames is not None:
            if max_frames < 0:
                raise InputError(f"max_frames must be >= 0, got {max_frames}")
            it = itertools.islice(it, max_frames)
            total = max_frames if total is None else min(total, max_frames)
        pipelined = self.pipelined if pipelined is None else pipelined
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=total, unit="frame", dynamic_ncols=True, mininterval=0.5)
        n = 0

        def on_result(r: StepResult) -> None:
            nonlocal n
            n += 1
            if callback is not None:
                callback(r)
            if bar is not None:
                bar.update(1)
                if n % 25 == 0 or n == total:
                    bar.set_postfix(templates=r.templates, experiences=r.experiences, refresh=False)

        # Python's cyclic garbage collector: a full collection scans every object alive
        # (torch, the frames, the map: 10^5-10^6 objects, tens of ms) and fires on
        # allocation counts, i.e. at random frames. Objects that exist before the run
        # are parked in the permanent generation for its duration, so collections only
        # scan what the run itself allocates (only when nobody else froze objects).
        freeze = gc.isenabled() and gc.get_freeze_count() == 0
        if freeze:
            gc.freeze()
        t0 = time.perf_counter()
        try:
            if pipelined:
                self._run_pipelined(it, on_result)
            else:
                for frame in it:
                    on_result(self.step_frame(frame))
        finally:
            if freeze:
                gc.unfreeze()
            if bar is not None:
                bar.close()
        wall = time.perf_counter() - t0
        n_t, n_e, n_l = self.counts()
        return RunResult(n, wall, n_t, n_e, n_l, self.timings.summary(), pipelined)

    def _run_pipelined(
        self, frames: Iterator[Frame], on_result: Callable[[StepResult], None]
    ) -> None:
        q_view: queue.Queue = queue.Queue(QUEUE_SIZE)
        q_pc: queue.Queue = queue.Queue(QUEUE_SIZE)
        q_out: queue.Queue = queue.Queue(QUEUE_SIZE)
        stop = threading.Event()
        errors: list[BaseException] = []

        def put(q: queue.Queue, item: Any) -> None:
            while True:
                try:
                    q.put(item, timeout=0.05)
                    return
                except queue.Full:
                    if stop.is_set():
                        return

        def get(q: queue.Queue) -> Any:
            while True:
                try:
                    return q.get(timeout=0.05)
                except queue.Empty:
                    if stop.is_set():
                        return _STOP

        start = self.frame_index
        # OpenMP's thread count is per thread: give the workers the caller's setting
        # (else each worker's torch ops would use every core and oversubscribe)
        n_threads = torch.get_num_threads()

        def drain(q: queue.Queue) -> Any:
            while (item := get(q)) is not _STOP:
                yield item

        def stage(source: Any, out: queue.Queue, work: Any) -> Any:
            """A worker: ``work`` on every item of ``source`` into ``out``, then _STOP;
            an error stops every stage and is re-raised by the caller."""

            def run() -> None:
                torch.set_num_threads(n_threads)
                try:
                    for item in source:
                        if stop.is_set():
                            break
                        put(out, work(item))
                except BaseException as exc:
                    errors.append(exc)
                    stop.set()
                finally:
                    put(out, _STOP)

            return run

        def view_work(item: tuple[int, Frame]) -> tuple:
            i, frame = item
            return (frame, start + i, *self._stage_view(frame, start + i))

        def pc_work(item: tuple) -> tuple:
            _, index, odo, view = item
            return (*item, *self._stage_pose_cells(view, odo, index))

        def em_work(item: tuple) -> tuple:
            frame, index, odo, view, action, pc = item
            exp_id = self._stage_experience_map(frame, index, view, odo, action, pc)
            return (
                frame,
                index,
                view,
                odo,
                action,
                pc,
                exp_id,
                _n_experiences(self.experience_map),
            )

        stages = {
            "view": stage(enumerate(frames), q_view, view_work),
            "pose_cells": stage(drain(q_view), q_pc, pc_work),
            "experience_map": stage(drain(q_pc), q_out, em_work),
        }
        workers = [
            threading.Thread(target=run, name=f"ratslam-{name}", daemon=True)
            for name, run in stages.items()
        ]
        for w in workers:
            w.start()
        n_templates = len(self.local_view)
        try:
            while (item := get(q_out)) is not _STOP:
                frame, index, view, odo, action, pc, exp_id, n_e = item
                self.frame_index = index + 1
                n_templates = max(n_templates, int(view.template_id) + 1)
                on_result(
                    self._finish(frame, index, view, odo, action, pc, exp_id, (n_templates, n_e))
                )
        except BaseException:
            stop.set()
            raise
        finally:
            for w in workers:
                w.join()
        if errors:
            raise errors[0]

    # ------------------------------------------------------------------ outputs
    def trajectory(self) -> np.ndarray:
        """Per processed frame: ``[frame, t, experience_id, x, y, th]`` with the
        experience's current (final, after relaxation) pose.

        Shape:
            returns ``(F, 6)`` float64.
        """
        poses = np.asarray(self.experience_map.poses, dtype=np.float64).reshape(-1, 3)
        exp = np.asarray(self._exp, dtype=np.int64)
        out = np.full((exp.shape[0], 6), np.nan)
        out[:, 0] = self._frames
        out[:, 1] = self._t
        out[:, 2] = exp
        ok = (exp >= 0) & (exp < poses.shape[0])
        out[ok, 3:] = poses[exp[ok]]
        return out

    def groundtruth_poses(self) -> np.ndarray | None:
        """The frames' ground-truth poses ``(F, 3)``, or None if any frame had none."""
        if not self._gt or any(p is None for p in self._gt):
            return None
        return np.asarray(self._gt, dtype=np.float64)

    def odometry_log(self) -> np.ndarray:
        """The ``(vtrans, vrot, dt)`` used for each frame. Shape: ``(F, 3)``."""
        return np.asarray(self._odo, dtype=np.float64).reshape(-1, 3)

    def ate(self, groundtruth: np.ndarray | None = None) -> float | None:
        """ATE (m) of the per-frame experience trajectory after SE(2) alignment.

        Args:
            groundtruth: ``(T, 4)`` rows ``[t, x, y, theta]`` interpolated at the frame
                times; default: the frames' own ground-truth poses.

        Returns:
            The ATE, or None when there is no ground truth.
        """
        from torchratslam.eval.metrics import ate_rmse, interpolate_groundtruth

        traj = self.trajectory()
        if traj.shape[0] < 2:
            return None
        gt = self.groundtruth_poses()
        if groundtruth is not None:
            gt = interpolate_groundtruth(groundtruth, traj[:, 1])
        if gt is None:
            return None
        ok = np.isfinite(traj[:, 3])
        return ate_rmse(traj[ok, 3:5], gt[ok, :2])

    def dead_reckoning_ate(self, groundtruth: np.ndarray | None = None) -> float | None:
        """ATE (m) of the integrated odometry alone (the baseline a map must beat)."""
        from torchratslam.eval.metrics import ate_rmse, dead_reckoning, interpolate_groundtruth

        odo = self.odometry_log()
        if odo.shape[0] < 2:
            return None
        gt = self.groundtruth_poses()
        if groundtruth is not None:
            gt = interpolate_groundtruth(groundtruth, np.asarray(self._t))
        if gt is None:
            return None
        dr = dead_reckoning(odo[:, 0], odo[:, 1], odo[:, 2])
        return ate_rmse(dr[:, :2], gt[:, :2])

    def pc_log(self) -> np.ndarray:
        """The pose-cell packet centre ``(x, y, th)`` in cells after each frame.

        Shape:
            returns ``(F, 3)``.
        """
        return np.asarray(self._pc, dtype=np.float64).reshape(-1, 3)

    def remap_experiences(self, old_to_new: np.ndarray) -> None:
        """Re-point the per-frame history at new experience ids (after a map merge).

        Args:
            old_to_new: ``old_to_new[i]`` is the new id of experience ``i`` (-1: dropped;
                ids beyond its length are kept). Shape: ``(M,)``.
        """
        ids = np.asarray(old_to_new, dtype=np.int64).reshape(-1)
        old = np.asarray(self._exp, dtype=np.int64)
        ok = (old >= 0) & (old < ids.size)
        if not ok.any():  # nothing to re-point (e.g. no experience yet: frame 0 only)
            return
        new = np.where(ok, ids[np.where(ok, old, 0)], old)
        self._exp[:] = [int(v) for v in new]

    def reset_history(self) -> None:
        """Forget the per-frame history and timings (the map is kept)."""
        self._frames.clear()
        self._t.clear()
        self._exp.clear()
        self._gt.clear()
        self._odo.clear()
        self._pc.clear()
        self.timings.reset()
