"""MBARAM's front end: dead reckoning and the channel vectors of one frame."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from ratslam_graph.geometry import odometry_step
from torchratslam.errors import InputError
from torchratslam.mbaram.params import MBARAMParams

__all__ = ["OdometryIntegrator", "frame_inputs"]


class OdometryIntegrator:
    """Dead reckoning from (vtrans, vrot, dt): the odometry channel's pose (x, y, th)."""

    def __init__(self, x: float = 0.0, y: float = 0.0, th: float = 0.0) -> None:
        self.pose = (float(x), float(y), float(th))

    def step(self, vtrans: float, vrot: float, dt: float) -> tuple[float, float, float]:
        """Advance by one interval (turn half, move, turn half) and return the pose."""
        self.pose = odometry_step(self.pose, vtrans, vrot, dt, midpoint=True)
        return self.pose


def frame_inputs(
    scans: Mapping[str, np.ndarray],
    pose: Sequence[float] | None,
    params: MBARAMParams,
    channels: Iterable[str] = ("laser_front", "laser_rear", "odometry"),
) -> dict[str, np.ndarray]:
    """Channel vectors from one frame's laser scans and odometric pose.

    Laser ranges are clipped to ``[0, laser_max_range]`` (+inf = no return = max range)
    and multiplied by ``laser_scale``; the pose becomes ``(x, y) * odo_scale, th``.

    Args:
        scans: ``{"laser_front": (N,), "laser_rear": (N,)}`` ranges in metres.
        pose: ``(x, y, th)`` for the odometry channel (None when it is not used).
        params: the MBARAM parameters.
        channels: the channels to build.

    Returns:
        channel -> float64 vector.
    """
    out: dict[str, np.ndarray] = {}
    for k in channels:
        if k == "odometry":
            if pose is None:
                raise InputError("the odometry channel needs a pose (x, y, th)")
            x, y, th = (float(v) for v in pose)
            out[k] = np.array([x * params.odo_scale, y * params.odo_scale, th])
            continue
        if k not in scans:
            raise InputError(
                f"frame has no scan {k!r} (has {sorted(scans)}); turn the lasers on in the "
                "simulator or use a dataset with laser scans"
            )
        r = np.asarray(scans[k], dtype=np.float64).reshape(-1)
        if np.isnan(r).any():
            raise InputError(f"scan {k!r} has {int(np.isnan(r).sum())} NaN range(s)")
        r = np.clip(np.nan_to_num(r, posinf=params.laser_max_range), 0.0, params.laser_max_range)
        out[k] = r * params.laser_scale
    return out
