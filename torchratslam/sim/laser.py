"""2D laser range finders (front and rear) in the simulated world."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from torchratslam.errors import InputError
from torchratslam.sim.render import cast_rays
from torchratslam.sim.world import World

__all__ = ["Laser", "scan"]


@dataclass(frozen=True)
class Laser:
    """A planar laser scanner mounted on the robot.

    Beam ``i`` of ``n_beams`` points along ``heading + mount_angle - fov/2 + i * fov /
    (n_beams - 1)`` (counter-clockwise order, as ROS ``LaserScan``).

    Attributes:
        n_beams: number of beams.
        fov_deg: angular field of view (degrees), centred on the mount direction.
        max_range: ranges beyond this (and misses) read ``max_range`` (m).
        noise: standard deviation of the additive Gaussian range noise (m).
        mount_angle_deg: direction of the scanner's centre beam relative to the
            heading (0 front, 180 rear).
        mount_offset: distance of the scanner from the robot centre along the mount
            direction (m).
    """

    n_beams: int = 682
    fov_deg: float = 240.0
    max_range: float = 30.0
    noise: float = 0.01
    mount_angle_deg: float = 0.0
    mount_offset: float = 0.0

    def __post_init__(self) -> None:
        if self.n_beams < 1:
            raise InputError(f"laser n_beams={self.n_beams} must be >= 1")
        if not 0 < self.fov_deg <= 360:
            raise InputError(f"laser fov_deg={self.fov_deg} must be in (0, 360]")
        if self.max_range <= 0 or self.noise < 0:
            raise InputError("laser max_range must be > 0 and noise >= 0")

    @property
    def beam_angles(self) -> np.ndarray:
        """``(n_beams,)`` beam directions relative to the robot heading (rad)."""
        half = math.radians(self.fov_deg) / 2
        centre = math.radians(self.mount_angle_deg)
        if self.n_beams == 1:
            return np.array([centre])
        return centre + np.linspace(-half, half, self.n_beams)


def scan(
    world: World,
    pose: tuple[float, float, float],
    laser: Laser,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """One laser scan.

    Args:
        world: the world.
        pose: robot pose ``(x, y, heading)``.
        laser: the scanner.
        rng: generator for range noise (required when ``laser.noise > 0``).

    Returns:
        ``(n_beams,)`` float32 ranges in ``[0, max_range]``.
    """
    x, y, th = (float(v) for v in pose)
    a = math.radians(laser.mount_angle_deg) + th
    ox, oy = x + laser.mount_offset * math.cos(a), y + laser.mount_offset * math.sin(a)
    dist, _, _ = cast_rays(world, (ox, oy), th + laser.beam_angles)
    r = np.minimum(dist, laser.max_range)
    if laser.noise > 0:
        if rng is None:
            raise InputError("laser noise > 0 needs an rng (np.random.Generator)")
        r = np.clip(r + rng.normal(0.0, laser.noise, r.shape), 0.0, laser.max_range)
    return r.astype(np.float32)
