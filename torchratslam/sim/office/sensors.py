"""The office robot's sensors: a forward camera reduced to a small grey image, a
scanning range sensor and wheel odometry with noise.

The camera is the simulator's forward pinhole (:class:`~torchratslam.sim.render.Camera`,
50 degree field of view) rendered at a multiple of the output size and averaged down in
blocks (12 x 8 grey, as in the experience-map paper); the range sensor is a 180 degree
:class:`~torchratslam.sim.laser.Laser`; odometry comes from consecutive ground-truth
poses through :func:`~torchratslam.sim.motion.odometry_from_poses` and its error model.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from torchratslam.errors import InputError
from torchratslam.sim.laser import Laser, scan
from torchratslam.sim.motion import OdometryNoise, odometry_from_poses
from torchratslam.sim.render import Camera, render
from torchratslam.sim.world import World

__all__ = ["SensorParams", "odometry", "range_scan", "small_image"]


@dataclass(frozen=True)
class SensorParams:
    """Sensor models.

    Attributes:
        image_size: ``(rows, cols)`` of the reduced grey image.
        oversample: the camera renders ``oversample`` times the image size.
        fov_deg: the camera's horizontal field of view.
        pixel_noise: grey-level noise of the rendered image (0-255 scale).
        laser: the range sensor.
        odometry: the wheel odometry's error model.
    """

    image_size: tuple[int, int] = (8, 12)
    oversample: int = 4
    fov_deg: float = 50.0
    pixel_noise: float = 2.0
    laser: Laser = field(
        default_factory=lambda: Laser(n_beams=91, fov_deg=180.0, max_range=8.0, noise=0.01)
    )
    odometry: OdometryNoise = field(
        default_factory=lambda: OdometryNoise(
            scale_error=0.02, rot_scale_error=0.02, trans_noise=0.01, rot_noise=0.02
        )
    )

    def __post_init__(self) -> None:
        if min(self.image_size) < 1 or self.oversample < 1:
            raise InputError(
                f"image_size={self.image_size}, oversample={self.oversample} must be >= 1"
            )

    @property
    def camera(self) -> Camera:
        """The forward camera rendering at ``oversample`` times the image size."""
        h, w = self.image_size
        k = self.oversample
        return Camera(kind="forward", width=w * k, height=h * k, fov_deg=self.fov_deg)


def _pose3(pose: np.ndarray) -> tuple[float, float, float]:
    return float(pose[0]), float(pose[1]), float(pose[2])


def small_image(
    world: World, pose: np.ndarray, params: SensorParams, rng: np.random.Generator
) -> np.ndarray:
    """The forward camera's view averaged down to ``image_size``.

    Shape:
        pose: (3,). Returns ``image_size`` uint8.
    """
    big = render(world, _pose3(pose), params.camera, pixel_noise=params.pixel_noise, rng=rng)
    h, w = params.image_size
    k = params.oversample
    blocks = big.reshape(h, k, w, k).astype(np.float32).mean(axis=(1, 3))
    return np.clip(np.rint(blocks), 0, 255).astype(np.uint8)


def range_scan(
    world: World, pose: np.ndarray, params: SensorParams, rng: np.random.Generator
) -> np.ndarray:
    """One scan of the range sensor against walls and obstacles, (n_beams,) float32 m."""
    return scan(world, _pose3(pose), params.laser, rng)


def odometry(
    prev: np.ndarray, pose: np.ndarray, dt: float, params: SensorParams, rng: np.random.Generator
) -> np.ndarray:
    """Noisy wheel odometry ``[vtrans, vrot, dt]`` of the tick from ``prev`` to ``pose``.

    Shape:
        prev, pose: (3,). Returns (3,).
    """
    return odometry_from_poses(np.stack([prev, pose]), dt, params.odometry, rng)[1]
