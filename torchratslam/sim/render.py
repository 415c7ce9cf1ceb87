"""Vectorised ray casting: panoramic and forward cameras.

Conventions (all angles in radians, counter-clockwise from the world x axis):

* Panoramic camera (``kind="panoramic"``, 360 degrees): column ``c`` looks along
  ``heading + c * 2*pi / W``, so column 0 looks straight ahead and the columns turn
  counter-clockwise (to the robot's left). Rotating the robot by ``+2*pi / W`` shifts
  the image by one column: ``new[:, c] == old[:, (c + 1) % W]`` (``np.roll(old, -1,
  axis=1)``). Note this is the mirror of a forward camera, whose columns turn
  clockwise from left to right.
* Forward camera (``kind="forward"``): a pinhole with horizontal field of view
  ``fov_deg``; column ``c`` looks along ``heading + atan(((W - 1) / 2 - c) / f)`` with
  ``f = (W / 2) / tan(fov / 2)`` (the image's left edge is to the robot's left).
* Rows: row ``r`` sees height ``z = cam_height + d * ((H - 1) / 2 - r) / f`` at
  horizontal distance ``d`` (perpendicular distance for the forward camera); the
  panoramic camera uses ``f = W / (2*pi)`` (a cylinder). A wall pixel shows the wall's
  texture at that height; rows above the wall show the ceiling, rows below the floor,
  both shaded by distance.

Every column is cast at once (rays x segments arrays): no Python loop over pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from torchratslam.errors import InputError
from torchratslam.sim.world import TEX_ROWS, World

__all__ = ["Camera", "cast_rays", "render"]

_FAR = 1e6

COMPILED = True
"""Cast rays with :func:`torchratslam.sim._rays.nearest_hits` (one compiled pass, the same
numbers bit for bit); False: the array path below, the reference it is tested against."""


def cast_rays(
    world: World, origin: tuple[float, float], angles: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Intersect rays from one origin with every wall segment.

    Args:
        world: the world.
        origin: ``(x, y)`` of the rays' common origin (m).
        angles: ray directions (rad, counter-clockwise from +x).

    Shape:
        angles ``(R,)`` -> distance ``(R,)`` float64 (inf where nothing is hit),
        segment ``(R,)`` int64 (-1 where nothing is hit), u ``(R,)`` float64 (position
        along the hit segment from its first end, metres).
    """
    angles = np.asarray(angles, np.float64)
    seg = world.segments
    if COMPILED and angles.ndim == 1 and len(seg):
        from torchratslam.sim._rays import nearest_hits

        return nearest_hits(
            np.cos(angles),
            np.sin(angles),
            seg[:, 0] - origin[0],
            seg[:, 1] - origin[1],
            seg[:, 2] - seg[:, 0],
            seg[:, 3] - seg[:, 1],
            world.lengths,
        )
    rx, ry = np.cos(angles)[:, None], np.sin(angles)[:, None]
    px, py = seg[None, :, 0] - origin[0], seg[None, :, 1] - origin[1]
    ex, ey = seg[None, :, 2] - seg[None, :, 0], seg[None, :, 3] - seg[None, :, 1]
    denom = rx * ey - ry * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / denom
        t = (px * ey - py * ex) * inv
        s = (px * ry - py * rx) * inv
    ok = (t > 1e-9) & (s >= 0.0) & (s <= 1.0)
    t = np.where(ok, t, np.inf)
    idx = np.argmin(t, axis=1)
    rows = np.arange(len(angles))
    dist = t[rows, idx]
    hit = np.isfinite(dist)
    u = np.where(hit, s[rows, idx], 0.0) * world.lengths[idx]
    return dist, np.where(hit, idx, -1), u


@dataclass(frozen=True)
class Camera:
    """A camera on the robot.

    Attributes:
        kind: "panoramic" (360 degrees) or "forward" (pinhole).
        width: image columns.
        height: image rows.
        fov_deg: horizontal field of view of the forward camera (ignored when panoramic).
        cam_height: height of the optical centre above the floor (m).
        fog: distance (m) at which walls fade to 1/e of their contrast towards the fog
            level; 0 disables fog.
        fog_level: grey level of the fog, in [0, 1].
    """

    kind: str = "panoramic"
    width: int = 256
    height: int = 64
    fov_deg: float = 60.0
    cam_height: float = 0.8
    fog: float = 0.0
    fog_level: float = 0.6

    def __post_init__(self) -> None:
        if self.kind not in ("panoramic", "forward"):
            raise InputError(f"camera kind {self.kind!r} is unknown; use 'panoramic' or 'forward'")
        if self.width < 2 or self.height < 2:
            raise InputError(f"camera size {self.width}x{self.height} is too small (>= 2x2)")
        if self.kind == "forward" and not 0 < self.fov_deg < 180:
            raise InputError(f"forward camera fov_deg={self.fov_deg} must be in (0, 180)")

    @property
    def focal(self) -> float:
        """Focal length in pixels."""
        if self.kind == "panoramic":
            return self.width / (2 * math.pi)
        return (self.width / 2) / math.tan(math.radians(self.fov_deg) / 2)

    @property
    def column_angles(self) -> np.ndarray:
        """``(W,)`` direction of each column relative to the heading (rad)."""
        c = np.arange(self.width, dtype=np.float64)
        if self.kind == "panoramic":
            return c * (2 * math.pi / self.width)
        return np.arctan(((self.width - 1) / 2 - c) / self.focal)

    @property
    def row_slopes(self) -> np.ndarray:
        """``(H,)`` height gained per metre of distance for each row."""
        r = np.arange(self.height, dtype=np.float64)
        return ((self.height - 1) / 2 - r) / self.focal


class _Projector:
    """Cached per-camera arrays (row slopes, background) for :func:`render`."""

    _cache: dict[tuple, _Projector] = {}  # noqa: RUF012

    def __init__(self, camera: Camera, world: World) -> None:
        self.col_angles = camera.column_angles
        self.cos_cols = np.cos(self.col_angles) if camera.kind == "forward" else None
        k = camera.row_slopes
        self.k = k[:, None].astype(np.float32)
        # background: ceiling above the horizon, floor below, both shaded by distance
        bg = np.empty(camera.height, np.float64)
        up = k > 0
        with np.errstate(divide="ignore"):
            d_floor = np.where(~up, camera.cam_height / np.maximum(-k, 1e-9), np.inf)
        bg[~up] = world.floor * (0.55 + 0.45 * np.exp(-d_floor[~up] / 4.0))
        bg[up] = world.ceiling * (0.85 + 0.15 * np.minimum(k[up] * 2.0, 1.0))
        self.bg = np.broadcast_to(bg[:, None], (camera.height, camera.width)).astype(np.float32)

    @classmethod
    def get(cls, camera: Camera, world: World) -> _Projector:
        key = (camera, world.floor, world.ceiling)
        p = cls._cache.get(key)
        if p is None:
            if len(cls._cache) > 32:
                cls._cache.clear()
            p = cls._cache[key] = cls(camera, world)
        return p


def render(
    world: World,
    pose: tuple[float, float, float],
    camera: Camera | None = None,
    *,
    gain: float = 1.0,
    offset: float = 0.0,
    pixel_noise: float = 0.0,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Render one grey image.

    Args:
        world: the world to look at.
        pose: robot pose ``(x, y, heading)`` (m, m, rad).
        camera: the camera (default: 256x64 panoramic).
        gain: illumination gain applied to the whole image.
        offset: illumination offset in grey levels (0-255 scale).
        pixel_noise: standard deviation of additive Gaussian pixel noise (grey levels).
        rng: generator for the pixel noise (required when ``pixel_noise > 0``).

    Returns:
        ``(H, W)`` uint8 image.
    """
    camera = camera or Camera()
    proj = _Projector.get(camera, world)
    x, y, th = (float(v) for v in pose)
    dist, seg, u = cast_rays(world, (x, y), th + proj.col_angles)
    hit = seg >= 0
    d = np.where(hit, dist, _FAR)
    if proj.cos_cols is not None:
        d = d * proj.cos_cols
    segc = np.where(hit, seg, 0)
    hw = np.where(hit, world.heights[segc], 1.0)
    z = (camera.cam_height + d.astype(np.float32)[None, :] * proj.k) / hw.astype(np.float32)
    wall = (z >= 0.0) & (z < 1.0) & hit[None, :]
    row_t = np.clip((z * TEX_ROWS).astype(np.int32, copy=False), 0, TEX_ROWS - 1)
    col_t = world.tex_start[segc] + np.minimum(
        (u * world.tex_res).astype(np.int64), world.tex_cols[segc] - 1
    )
    tex = world.atlas[row_t, col_t[None, :]]
    if camera.fog > 0:
        a = np.exp(-d / camera.fog).astype(np.float32)[None, :]
        tex = tex * a + np.float32(camera.fog_level) * (1 - a)
    img = np.where(wall, tex, proj.bg)
    scale = 255.0 * gain
    img = img * np.float32(scale) + np.float32(offset)
    if pixel_noise > 0:
        if rng is None:
            raise InputError("pixel_noise > 0 needs an rng (np.random.Generator)")
        img = img + rng.normal(0.0, pixel_noise, img.shape).astype(np.float32)
    return np.clip(img + 0.5, 0, 255).astype(np.uint8)
