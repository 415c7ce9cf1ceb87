"""MBARAM as a pipeline module: frames in, node out (registered as ``"mbaram"`` in
:data:`torchratslam.registry.RANGE_MAPPERS`)."""

from __future__ import annotations

from typing import cast

import numpy as np
import torch

from torchratslam.errors import ConfigError, InputError
from torchratslam.mbaram.inputs import OdometryIntegrator, frame_inputs
from torchratslam.mbaram.model import MBARAM
from torchratslam.mbaram.params import LASER_CHANNELS, MBARAMParams
from torchratslam.messages import Frame
from torchratslam.registry import RANGE_MAPPERS

__all__ = ["MBARAMMapper"]


@RANGE_MAPPERS.register("mbaram")
class MBARAMMapper:
    """MBARAM as a module of the pipeline: :class:`~torchratslam.messages.Frame` in, node out.

    Builds the channel inputs from each frame's laser scans (``frame.scans``) and its
    odometric pose (the ground-truth pose, the paper's accurate odometry, or dead
    reckoning of ``vtrans``/``vrot``, continuous over the whole run), then learns
    (Algorithm 1) or localises (Section 2.1.3) with :class:`MBARAM`.

    Args:
        params: MBARAM parameters.
        odometry: ``"groundtruth"`` or ``"integrated"``.
        dtype: float dtype of the node statistics.
        device: torch device.
    """

    def __init__(
        self,
        params: MBARAMParams | None = None,
        *,
        odometry: str = "groundtruth",
        dtype: torch.dtype = torch.float64,
        device: torch.device | str | None = None,
    ) -> None:
        if odometry not in ("groundtruth", "integrated"):
            raise ConfigError(f"odometry must be 'groundtruth' or 'integrated', got {odometry!r}")
        self.params = params if params is not None else MBARAMParams()
        self.mode = odometry
        self.model = MBARAM(self.params, dtype=dtype, device=device)
        self.integ: OdometryIntegrator | None = None
        self.keep_inputs = False  # remember every frame's inputs (to replay the mapping frames)
        self._memo: dict[int, tuple[Frame, dict[str, np.ndarray], tuple[float, float, float]]] = {}

    def __len__(self) -> int:
        return len(self.model)

    def inputs(self, frame: Frame) -> tuple[dict[str, np.ndarray], tuple[float, float, float]]:
        """The channel vectors of ``frame`` and its odometric pose (one integration step)."""
        hit = self._memo.get(id(frame))
        if hit is not None and hit[0] is frame:
            return hit[1], hit[2]
        if frame.pose is None and self.mode == "groundtruth":
            raise InputError("odometry='groundtruth' needs frames with a ground-truth pose")
        if self.integ is None:
            self.integ = OdometryIntegrator(*(frame.pose if frame.pose is not None else (0, 0, 0)))
        if self.mode == "integrated":
            pose = self.integ.step(frame.vtrans, frame.vrot, frame.dt)
        else:
            pose = cast(tuple[float, float, float], tuple(float(v) for v in frame.pose or ()))
        x = frame_inputs(frame.scans, pose, self.params)
        if not self.keep_inputs:
            self._memo.clear()
        self._memo[id(frame)] = (frame, x, pose)
        return x, pose

    def learn(self, frame: Frame) -> int:
        """One mapping step on ``frame``; returns the winning (or new) node."""
        return self.model.learn(self.inputs(frame)[0]).node

    def localise(self, frame: Frame, *, odometry: bool = True) -> int:
        """The node ``frame`` is localised at (-1 = none passes vigilance), no learning.

        Args:
            frame: the frame (its scans, and its pose when ``odometry``).
            odometry: use the odometry channel, or the lasers alone.
        """
        x = self.inputs(frame)[0]
        return self.model.localise(x, None if odometry else LASER_CHANNELS).node
