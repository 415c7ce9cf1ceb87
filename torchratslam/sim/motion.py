"""Routes, ground-truth poses and noisy odometry.

Ground truth and odometry are consistent by construction: the heading at frame ``k``
is the direction of travel from frame ``k-1`` to ``k`` (frame 0 takes frame 1's), and
the odometry of the interval ending at frame ``k`` integrates back exactly with the
rotate-then-translate rule used by OpenRatSLAM's experience map
(:func:`ratslam_graph.geometry.dead_reckoning`)::

    th_k = th_{k-1} + vrot_k * dt_k
    x_k  = x_{k-1}  + vtrans_k * dt_k * cos(th_k)
    y_k  = y_{k-1}  + vtrans_k * dt_k * sin(th_k)

Noise (all seeded) is applied to the odometry only::

    vtrans' = vtrans * (1 + scale_error) + N(0, trans_noise)
    vrot'   = vrot * (1 + rot_scale_error) + heading_bias + N(0, rot_noise)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ratslam_graph.geometry import wrap_angle
from torchratslam.errors import InputError

__all__ = ["OdometryNoise", "Route", "odometry_from_poses"]


class Route:
    """A path on the floor, parameterised by arc length (linear between dense points).

    Args:
        points: ``(P, 2)`` points along the path (dense enough to follow curves).
        closed: whether the path returns to its first point (arc length wraps).
    """

    def __init__(self, points: np.ndarray, *, closed: bool = True) -> None:
        pts = np.asarray(points, np.float64).reshape(-1, 2)
        if len(pts) < 2:
            raise InputError("a route needs at least two points")
        if closed and np.hypot(*(pts[0] - pts[-1])) > 1e-9:
            pts = np.vstack([pts, pts[:1]])
        self.points = pts
        self.closed = closed
        seg = np.hypot(*np.diff(pts, axis=0).T)
        self.s = np.concatenate([[0.0], np.cumsum(seg)])
        self.length = float(self.s[-1])

    def at(self, s: np.ndarray) -> np.ndarray:
        """``(N, 2)`` positions at arc lengths ``s`` (wrapped on a closed route)."""
        s = np.asarray(s, np.float64)
        s = s % self.length if self.closed else np.clip(s, 0.0, self.length)
        return np.stack(
            [np.interp(s, self.s, self.points[:, 0]), np.interp(s, self.s, self.points[:, 1])], -1
        )

    @classmethod
    def ellipse(
        cls,
        a: float,
        b: float,
        *,
        centre: tuple[float, float] = (0.0, 0.0),
        start_deg: float = 0.0,
        n: int = 4000,
    ) -> Route:
        """A counter-clockwise ellipse with semi-axes ``a`` (x) and ``b`` (y)."""
        t = np.radians(start_deg) + np.linspace(0, 2 * np.pi, n, endpoint=False)
        return cls(np.stack([centre[0] + a * np.cos(t), centre[1] + b * np.sin(t)], -1))

    @classmethod
    def polygon(
        cls,
        corners: list[tuple[float, float]],
        *,
        radius: float = 0.0,
        n_arc: int = 24,
        closed: bool = True,
    ) -> Route:
        """A polyline through ``corners`` with corners rounded by circular arcs of ``radius``.

        A closed polygon rounds every corner; an open polyline keeps its two ends.
        """
        c = np.asarray(corners, np.float64)
        if radius <= 0 or len(c) < 3:
            return cls(c, closed=closed)
        n = len(c)
        out = [] if closed else [c[0]]
        for i in range(n) if closed else range(1, n - 1):
            p, q, r = c[i - 1], c[i], c[(i + 1) % n]
            d1, d2 = (q - p) / np.linalg.norm(q - p), (r - q) / np.linalg.norm(r - q)
            turn = np.arctan2(d1[0] * d2[1] - d1[1] * d2[0], d1 @ d2)
            if abs(turn) < 1e-9:
                out.append(q)
                continue
            cut = min(
                radius * np.tan(abs(turn) / 2),
                0.49 * np.linalg.norm(q - p),
                0.49 * np.linalg.norm(r - q),
            )
            rad = cut / np.tan(abs(turn) / 2)
            a = q - d1 * cut
            normal = np.array([-d1[1], d1[0]]) * np.sign(turn)
            centre = a + normal * rad
            a0 = np.arctan2(*(a - centre)[::-1])
            ang = a0 + np.linspace(0, turn, n_arc)
            out.extend(centre + rad * np.stack([np.cos(ang), np.sin(ang)], -1))
        if not closed:
            out.append(c[-1])
        return cls(np.array(out), closed=closed)


@dataclass(frozen=True)
class OdometryNoise:
    """Odometry error model (see the module docstring); all zero = exact odometry.

    Attributes:
        scale_error: relative error of the translational speed (0.02 = +2 %).
        rot_scale_error: relative error of the turn rate.
        heading_bias: constant added to the turn rate (rad/s).
        trans_noise: std of Gaussian noise on vtrans (m/s).
        rot_noise: std of Gaussian noise on vrot (rad/s).
    """

    scale_error: float = 0.0
    rot_scale_error: float = 0.0
    heading_bias: float = 0.0
    trans_noise: float = 0.0
    rot_noise: float = 0.0

    def __post_init__(self) -> None:
        if self.trans_noise < 0 or self.rot_noise < 0:
            raise InputError("odometry trans_noise and rot_noise must be >= 0")
        if self.scale_error <= -1:
            raise InputError("odometry scale_error must be > -1")


def poses_along(route: Route, s: np.ndarray) -> np.ndarray:
    """``(N, 3)`` poses ``[x, y, th]`` at arc lengths ``s`` (heading = direction of travel)."""
    xy = route.at(s)
    th = np.empty(len(xy))
    if len(xy) >= 2:
        d = np.diff(xy, axis=0)
        th[1:] = np.arctan2(d[:, 1], d[:, 0])
        th[0] = th[1]
    else:
        fwd = route.at(np.asarray(s) + 1e-3)[0] - xy[0]
        th[0] = np.arctan2(fwd[1], fwd[0])
    return np.column_stack([xy, th])


def odometry_from_poses(
    poses: np.ndarray,
    dt: np.ndarray | float,
    noise: OdometryNoise | None = None,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Odometry for each frame: the interval ending at it.

    Args:
        poses: ground-truth poses ``[x, y, th]``.
        dt: frame intervals (s); ``dt[0]`` is ignored (the first frame has dt = 0).
        noise: the error model (None = exact).
        rng: generator for the Gaussian terms.

    Shape:
        poses ``(T, 3)``, dt scalar or ``(T,)`` -> ``(T, 3)`` ``[vtrans, vrot, dt]``.
    """
    poses = np.asarray(poses, np.float64)
    t = len(poses)
    dts = np.broadcast_to(np.asarray(dt, np.float64), (t,)).copy()
    dts[0] = 0.0
    out = np.zeros((t, 3))
    out[:, 2] = dts
    if t < 2:
        return out
    if np.any(dts[1:] <= 0):
        raise InputError("frame intervals must be positive")
    d = np.diff(poses, axis=0)
    out[1:, 0] = np.hypot(d[:, 0], d[:, 1]) / dts[1:]
    out[1:, 1] = wrap_angle(d[:, 2]) / dts[1:]
    if noise is not None:
        rng = rng or np.random.default_rng(0)
        n = t - 1
        gv = rng.normal(0.0, 1.0, n)
        gw = rng.normal(0.0, 1.0, n)
        out[1:, 0] = out[1:, 0] * (1 + noise.scale_error) + noise.trans_noise * gv
        out[1:, 1] = (
            out[1:, 1] * (1 + noise.rot_scale_error) + noise.heading_bias + noise.rot_noise * gw
        )
    return out
