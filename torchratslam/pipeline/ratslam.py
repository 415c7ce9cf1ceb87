"""The :class:`RatSLAM` pipeline: local view, pose cells, odometry source and experience map.

See :mod:`torchratslam.pipeline` for the registries, the per-frame order and the
pipelined mode.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch

import torchratslam.pipeline.defaults  # noqa: F401  (registers the default stages)
from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.frame_step import odometry_frame, stage_frame
from ratslam_graph.messages import Action, ActionKind
from torchratslam.config import RatSLAMConfig
from torchratslam.errors import InputError
from torchratslam.messages import Frame, SessionState, ViewMatch
from torchratslam.pipeline.checks import as_config, check_device, check_odometry_step
from torchratslam.pipeline.em_stage import general_step
from torchratslam.pipeline.history import History
from torchratslam.pipeline.results import RunResult, StepResult
from torchratslam.pipeline.runner import RunProgress, open_frames, parked_gc
from torchratslam.pipeline.threads import run_pipelined
from torchratslam.pose_cells.stage import PoseCells
from torchratslam.protocols import (
    ExperienceMapModule,
    FrameSource,
    InjectionAngle,
    LocalViewModule,
    OdometrySource,
    PoseCellModule,
)
from torchratslam.readers.visual_odometry import GivenOdometry
from torchratslam.registry import EXPERIENCE_MAPS, LOCAL_VIEWS, ODOMETRY, POSE_CELLS
from torchratslam.timing import TimeLogger, watch_compiles

__all__ = ["RatSLAM"]

log = logging.getLogger(__name__)


def _has_injection_angle(pose_cells: object) -> bool:
    """``isinstance(pose_cells, InjectionAngle)`` without the protocol check's cost per
    frame (the members are looked up directly)."""
    return hasattr(pose_cells, "vt_delta_pc_th") and hasattr(pose_cells, "dims")


def _centre(pose_cells: PoseCellModule) -> tuple[float, float, float]:
    c = pose_cells.centre
    if type(c) is tuple and len(c) == 3 and all(type(v) is float for v in c):
        return c  # PoseCells' own centre: nothing to convert
    if callable(c):
        c = c()
    if isinstance(c, torch.Tensor):
        c = c.detach().reshape(-1).cpu().tolist()
    x, y, th = (float(v) for v in list(c)[:3])
    return x, y, th


class RatSLAM:
    """A complete RatSLAM system.

    Args:
        config: all module parameters.
        local_view, pose_cells, experience_map, odometry: a registered name, a class
            (called like the registry's factory) or a ready instance; None takes the
            name from the config's ``general`` section.
        dtype: for the torch modules (local view, pose cells); None takes the config's
            ``dtype`` key (float64 unless set: OpenRatSLAM's ``double``).
        device: for the torch modules.
        pipelined: default mode of :meth:`run` (one worker thread per module).

    Attributes:
        config, local_view, pose_cells, experience_map, odometry: the modules.
        frame_index: frames processed so far.
        session: the :class:`~torchratslam.messages.SessionState` record (frames
            processed, last time stamp); assigning one restores it.
        timings: the :class:`~torchratslam.timing.TimeLogger` (per-frame ms per module).
        history: the :class:`~torchratslam.pipeline.history.History` of the frames
            (frame, time, current experience, ground truth, odometry, pose-cell centre)
            behind :meth:`trajectory`, :meth:`ate` and :meth:`dead_reckoning_ate`.
    """

    def __init__(
        self,
        config: RatSLAMConfig | str | Path | dict[str, Any] | None = None,
        *,
        local_view: LocalViewModule | str | type | None = None,
        pose_cells: PoseCellModule | str | type | None = None,
        experience_map: ExperienceMapModule | str | type | None = None,
        odometry: OdometrySource | str | type | None = None,
        dtype: torch.dtype | None = None,
        device: torch.device | str | None = None,
        pipelined: bool = False,
    ) -> None:
        self.config = as_config(config)
        check_device(device)
        general = self.config.general
        if dtype is None:
            dtype = torch.float64 if general.dtype == "float64" else torch.float32
        self.dtype, self.device = dtype, device
        self.pipelined = pipelined
        self.local_view: LocalViewModule = LOCAL_VIEWS.build(
            general.local_view if local_view is None else local_view,
            self.config.local_view,
            dtype=dtype,
            device=device,
        )
        self.pose_cells: PoseCellModule = POSE_CELLS.build(
            general.pose_cells if pose_cells is None else pose_cells,
            self.config.pose_cells,
            dtype=dtype,
            device=device,
        )
        self.experience_map: ExperienceMapModule = EXPERIENCE_MAPS.build(
            general.experience_map if experience_map is None else experience_map,
            self.config.experience_map,
        )
        odometry = general.odometry if odometry is None else odometry
        self.odometry: OdometrySource = ODOMETRY.build(odometry, self.config.visual_odometry)
        self.odometry_name = odometry if isinstance(odometry, str) else type(self.odometry).__name__
        self.frame_index = 0
        self.timings = TimeLogger()
        self.history = History()
        self._last_t = 0.0

    # ------------------------------------------------------------------ module swapping
    def set_local_view(self, module: LocalViewModule | str | type) -> None:
        """Replace the local view (a registered name, a class or an instance)."""
        self.local_view = LOCAL_VIEWS.build(
            module, self.config.local_view, dtype=self.dtype, device=self.device
        )

    def set_pose_cells(self, module: PoseCellModule | str | type) -> None:
        """Replace the pose-cell module (a registered name, a class or an instance)."""
        self.pose_cells = POSE_CELLS.build(
            module, self.config.pose_cells, dtype=self.dtype, device=self.device
        )

    def set_experience_map(self, module: ExperienceMapModule | str | type) -> None:
        """Replace the experience map (a registered name, a class or an instance)."""
        self.experience_map = EXPERIENCE_MAPS.build(module, self.config.experience_map)

    def set_odometry(self, module: OdometrySource | str | type) -> None:
        """Replace the odometry source (``"given"``, ``"visual"``, a class or an instance)."""
        self.odometry = ODOMETRY.build(module, self.config.visual_odometry)
        self.odometry_name = module if isinstance(module, str) else type(self.odometry).__name__

    # ------------------------------------------------------------------ internal state
    @property
    def session(self) -> SessionState:
        """Frames processed so far and the last frame's time stamp."""
        return SessionState(frame_index=self.frame_index, last_t=self._last_t)

    @session.setter
    def session(self, value: SessionState) -> None:
        self.frame_index = int(value.frame_index)
        self._last_t = float(value.last_t)

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
        return len(self.local_view), len(em), int(em.num_links)

    # ------------------------------------------------------------------ one frame
    def _stage_view(self, frame: Frame, index: int) -> tuple[tuple[float, float, float], ViewMatch]:
        with self.timings.section("odometry"):
            vtrans, vrot, dt = self.odometry(frame)
            odo = (float(vtrans), float(vrot), float(dt))
        if frame.image is None:
            raise InputError(
                f"frame {frame.index}: no image; the local view needs one in every frame"
            )
        with self.timings.section("local_view"):
            view = self.local_view.process(frame.image, frame_index=index)
        return odo, view

    def _skips_odometry(self, index: int) -> bool:
        """OpenRatSLAM's nodes skip their first odometry message (``skip_first_odometry``)."""
        return index == 0 and bool(self.config.general.skip_first_odometry)

    def _stage_pose_cells(
        self, view: ViewMatch, odo: tuple[float, float, float], index: int = -1
    ) -> tuple[Action, tuple[float, float, float]]:
        pcs = self.pose_cells
        with self.timings.section("pose_cells"):
            if type(pcs) is PoseCells and not self._skips_odometry(index):
                # the stage's own frame: view, step and action in one compiled call
                return pcs.on_frame(
                    view, *odo, injection_angle=self.config.general.action_angle == "injection"
                )
            pcs.on_view_template(view)
            if self._skips_odometry(index):
                action = Action.none()
            else:
                action = pcs.on_odometry(*odo)
                if (
                    action.kind != ActionKind.NONE
                    and self.config.general.action_angle == "injection"
                    and _has_injection_angle(pcs)
                ):
                    # OpenRatSLAM's get_relative_rad(): the angle of the last injection
                    inj = cast(InjectionAngle, pcs)
                    rad = inj.vt_delta_pc_th * 2.0 * math.pi / inj.dims[2]
                    if type(action) is Action:  # (replace() costs as much as the rest)
                        action = Action(action.kind, action.dest_id, action.src_id, rad)
                    else:
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
        behaviour: int | None = None,
    ) -> int:
        with self.timings.section("experience_map"):
            # experience_map_step: its compiled_step without a layer, the rest worked out
            # only where it is needed
            em = self.experience_map
            if index and isinstance(em, ExperienceMap):
                current = (
                    stage_frame(em, odo, action, index, frame.t, pc, view.template_id, behaviour)
                    if action.kind
                    else odometry_frame(em, odo, action)
                )
                if current is not None:
                    return current
            return general_step(
                em,
                odo if index or not self._skips_odometry(index) else None,
                action,
                frame=index,
                t=float(frame.t),
                pc=pc,
                template_id=int(view.template_id),
                pc_dims=self._pc_dims(),
                behaviour=behaviour,
            )

    def _pc_dims(self) -> tuple[float, ...]:
        """The pose cells' ``(X, Y, TH)`` as floats, kept while the config is the same."""
        pcp = self.config.pose_cells
        cached = self.__dict__.get("_pc_dims_of")
        if cached is None or cached[0] is not pcp:
            cached = self.__dict__["_pc_dims_of"] = (pcp, tuple(float(d) for d in pcp.dims))
        return cached[1]

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
        self.history.append(index, frame.t, exp_id, frame.pose, odo, pc)
        self._last_t = float(frame.t)
        if counts is None:  # (the links' count is not wanted)
            counts = (len(self.local_view), len(self.experience_map))
        n_t, n_e = counts
        return StepResult(index, float(frame.t), view, action, odo, pc, exp_id, n_t, n_e)

    def step_frame(self, frame: Frame, *, behaviour: int | None = None) -> StepResult:
        """Process one frame (sequentially) and return what it did.

        Args:
            frame: the frame.
            behaviour: the movement behaviour executed over the frame's interval; the
                experience map labels the frame's transition with it and monitors link
                confidence (Eq. 9 of the experience-map paper). None: unlabelled.
        """
        watch_compiles()  # numba's first compilation is said, not a silent pause
        index = self.frame_index
        odo, view = self._stage_view(frame, index)
        action, pc = self._stage_pose_cells(view, odo, index)
        exp_id = self._stage_experience_map(frame, index, view, odo, action, pc, behaviour)
        self.frame_index += 1
        return self._finish(frame, index, view, odo, action, pc, exp_id)

    def step(
        self,
        image: np.ndarray | torch.Tensor,
        odometry: tuple[float, float, float] | None = None,
        *,
        behaviour: int | None = None,
    ) -> StepResult:
        """Process one image with its odometry.

        Args:
            image: the camera image. Shape: ``(H, W)`` grey or ``(H, W, 3)``.
            odometry: ``(vtrans m/s, vrot rad/s, dt s)`` over the interval ending at
                this image; None when the odometry source is visual.
            behaviour: the movement behaviour executed (see :meth:`step_frame`).

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
            vtrans, vrot, dt = check_odometry_step(odometry)
            t = self._last_t + dt
        t = t if self.frame_index else 0.0
        frame = Frame(self.frame_index, t, np.asarray(image), vtrans=vtrans, vrot=vrot, dt=dt)
        return self.step_frame(frame, behaviour=behaviour)

    # ------------------------------------------------------------------ whole runs
    def run(
        self,
        frames: Iterable[Frame] | FrameSource | str | Path,
        *,
        max_frames: int | None = None,
        progress: bool | str | None = None,
        pipelined: bool | None = None,
        callback: Callable[[StepResult], None] | None = None,
    ) -> RunResult:
        """Process a sequence of frames.

        Args:
            frames: an iterable of :class:`Frame`, a reader / simulator session
                (anything with ``frames()``), or a data spec (``str`` or ``Path``, e.g.
                ``"sim:loop"``) that :func:`~torchratslam.readers.datasets.open_data` opens.
            max_frames: stop after this many frames.
            progress: True or a label: show a tqdm progress bar (frames/s, templates,
                experiences); None (default): only in a notebook; False: none.
            pipelined: one worker thread per module (default: the constructor's).
            callback: called with every :class:`StepResult`, in order.

        Returns:
            :class:`RunResult`.

        Raises:
            InputError: ``frames`` is none of these, or names no readable data.
        """
        data, it, total = open_frames(frames, max_frames)
        if (
            isinstance(data, FrameSource)
            and not getattr(data, "has_odometry", True)
            and isinstance(self.odometry, GivenOdometry)
        ):
            log.warning(
                "%s carries no odometry but the odometry source is 'given' (zero "
                "motion); build RatSLAM(..., odometry='visual') to estimate it",
                getattr(data, "name", "the data"),
            )
        pipelined = self.pipelined if pipelined is None else pipelined
        report = RunProgress(total, show=progress, callback=callback)
        first: list[float] = []  # when the first frame's result came (the start-up's end)

        def on_result(r: StepResult) -> None:
            if not first:
                first.append(time.perf_counter())
            report(r)

        try:
            with parked_gc():  # see parked_gc: no full collections at random frames
                t0 = time.perf_counter()
                if pipelined:
                    self._run_pipelined(it, on_result)
                else:
                    for frame in it:
                        on_result(self.step_frame(frame))
        finally:
            report.close()
        wall = time.perf_counter() - t0
        n_t, n_e, n_l = self.counts()
        startup = first[0] - t0 if first else 0.0
        summary = self.timings.summary()
        return RunResult(report.n, wall, n_t, n_e, n_l, summary, pipelined, startup)

    def _run_pipelined(
        self, frames: Iterator[Frame], on_result: Callable[[StepResult], None]
    ) -> None:
        """The three stages in worker threads (see :mod:`torchratslam.pipeline.threads`)."""

        def view_work(item: tuple[int, Frame]) -> tuple:
            index, frame = item
            return (frame, index, *self._stage_view(frame, index))

        def pc_work(item: tuple) -> tuple:
            _, index, odo, view = item
            return (*item, *self._stage_pose_cells(view, odo, index))

        def em_work(item: tuple) -> tuple:
            frame, index, odo, view, action, pc = item
            exp_id = self._stage_experience_map(frame, index, view, odo, action, pc)
            return (*item, exp_id, len(self.experience_map))

        n_templates = len(self.local_view)

        def finish(item: tuple) -> None:
            nonlocal n_templates
            frame, index, odo, view, action, pc, exp_id, n_e = item
            self.frame_index = index + 1
            n_templates = max(n_templates, int(view.template_id) + 1)
            on_result(self._finish(frame, index, view, odo, action, pc, exp_id, (n_templates, n_e)))

        run_pipelined(frames, self.frame_index, view_work, pc_work, em_work, finish)

    # ------------------------------------------------------------------ outputs
    def trajectory(self) -> np.ndarray:
        """Per processed frame: ``[frame, t, experience_id, x, y, th]`` with the
        experience's current (final, after relaxation) pose.

        Shape:
            returns ``(F, 6)`` float64.
        """
        return self.history.trajectory(self.experience_map.poses)

    def groundtruth_poses(self) -> np.ndarray | None:
        """The frames' ground-truth poses ``(F, 3)``, or None if any frame had none."""
        return self.history.groundtruth_poses()

    def odometry_log(self) -> np.ndarray:
        """The ``(vtrans, vrot, dt)`` used for each frame. Shape: ``(F, 3)``."""
        return self.history.odometry_log()

    def ate(self, groundtruth: np.ndarray | None = None) -> float | None:
        """ATE (m) of the per-frame experience trajectory after SE(2) alignment.

        Args:
            groundtruth: ``(T, 4)`` rows ``[t, x, y, theta]`` interpolated at the frame
                times; default: the frames' own ground-truth poses.

        Returns:
            The ATE, or None when there is no ground truth.
        """
        return self.history.ate(self.experience_map.poses, groundtruth)

    def dead_reckoning_ate(self, groundtruth: np.ndarray | None = None) -> float | None:
        """ATE (m) of the integrated odometry alone (the baseline a map must beat)."""
        return self.history.dead_reckoning_ate(groundtruth)

    def pc_log(self) -> np.ndarray:
        """The pose-cell packet centre ``(x, y, th)`` in cells after each frame.

        Shape:
            returns ``(F, 3)``.
        """
        return self.history.pc_log()

    def remap_experiences(self, old_to_new: np.ndarray) -> None:
        """Re-point the per-frame history at new experience ids (after a map merge).

        Args:
            old_to_new: ``old_to_new[i]`` is the new id of experience ``i`` (-1: dropped;
                ids beyond its length are kept). Shape: ``(M,)``.
        """
        self.history.remap_experiences(old_to_new)

    def reset_history(self) -> None:
        """Forget the per-frame history and timings (the map is kept)."""
        self.history.clear()
        self.timings.reset()
