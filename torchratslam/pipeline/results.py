"""What the pipeline returns: one frame's :class:`StepResult`, one run's :class:`RunResult`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ratslam_graph.messages import Action
from torchratslam.messages import ViewMatch

__all__ = ["RunResult", "StepResult"]


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


@dataclass(frozen=True)
class RunResult:
    """Summary of :meth:`RatSLAM.run <torchratslam.pipeline.ratslam.RatSLAM.run>`.

    Attributes:
        frames: frames processed by this call.
        wall_s: wall-clock time of the call (s).
        templates, experiences, links: map size at the end.
        timings: :meth:`TimeLogger.summary` of the whole session (ms per frame per module).
        pipelined: whether the pipelined mode ran.
        startup_s: the wall-clock time to the first frame's result (s): the first frame
            with every one-off cost of the start (numba compiling its kernels on the
            first use after installing, caches warming).
    """

    frames: int
    wall_s: float
    templates: int
    experiences: int
    links: int
    timings: dict[str, dict[str, Any]] = field(default_factory=dict)
    pipelined: bool = False
    startup_s: float = 0.0

    @property
    def fps(self) -> float:
        """Frames per second of wall-clock time, the start-up left out: the frames after
        the first over the time after it (with one frame, or no start-up measured, the
        whole call)."""
        rest = self.wall_s - self.startup_s
        if self.frames > 1 and self.startup_s > 0 and rest > 0:
            return (self.frames - 1) / rest
        return self.frames / self.wall_s if self.wall_s > 0 else 0.0
