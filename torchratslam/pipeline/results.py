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
