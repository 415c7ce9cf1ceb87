"""Typed messages between front-end modules.

* :class:`Frame` -- what every reader and the simulator yield: one timestamped image
  with the odometry over the interval that ends at it.
* :class:`ViewMatch` -- the local view's verdict on one frame.
* :class:`~ratslam_graph.messages.Action` -- the pose cells' decision for the experience map
  (defined in the torch-free ``graph`` package, re-exported here).
* :class:`SessionState` -- where a pipeline's session stands (frames processed, the last
  frame's time stamp), saved with its map.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ratslam_graph.messages import Action, ActionKind

__all__ = ["Action", "ActionKind", "Frame", "SessionState", "ViewMatch"]


@dataclass(frozen=True)
class Frame:
    """One time step of a dataset.

    Attributes:
        index: 0-based frame number within the sequence.
        t: timestamp in seconds.
        image: the camera image, ``(H, W)`` grey or ``(H, W, 3)`` BGR, uint8 or float
            in [0, 1]; None for sensor-only data.
        vtrans: forward speed over the interval ending at ``t`` (m/s).
        vrot: turn rate over the interval ending at ``t`` (rad/s, counter-clockwise).
        dt: length of that interval (s); 0 for the first frame.
        pose: ground-truth ``(x, y, theta)`` if known, else None.
        scans: optional extra sensor channels, e.g. ``{"laser_front": (N,) ranges}``.
    """

    index: int
    t: float
    image: np.ndarray | None
    vtrans: float = 0.0
    vrot: float = 0.0
    dt: float = 0.0
    pose: tuple[float, float, float] | None = None
    scans: dict[str, np.ndarray] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ViewMatch:
    """The local view's result for one frame.

    Attributes:
        template_id: the matched template, or the new one when ``is_new``.
        relative_rad: relative view angle of the match (radians, in (-pi, pi]); 0 for
            new templates and in normal (non-panoramic) mode.
        error: the best mean absolute difference found (inf when the bank was empty).
        offset: the column offset of the best match.
        is_new: True when no template matched under ``vt_match_threshold`` and a new
            one was learnt.
    """

    template_id: int
    relative_rad: float = 0.0
    error: float = float("inf")
    offset: int = 0
    is_new: bool = False


@dataclass(frozen=True)
class SessionState:
    """Where a pipeline's session stands.

    Attributes:
        frame_index: frames processed so far.
        last_t: time stamp of the last frame processed (s; 0 before the first).
    """

    VERSION: ClassVar[int] = 1

    frame_index: int = 0
    last_t: float = 0.0
