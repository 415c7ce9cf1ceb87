"""Planar geometry shared by every part of the project, in numpy (torch-free).

One home for:

* angle wrapping -- :func:`wrap_angle` and :func:`signed_delta`. The project's convention
  is ``[-pi, pi)``; ``include_pi=True`` selects ``(-pi, pi]`` (OpenRatSLAM's
  ``clip_rad_180``), used where the reference implementation's arithmetic is reproduced
  bit for bit (the experience map, the merge). Both flavours accept Python floats, numpy
  arrays and any array type with ``%`` (torch tensors stay tensors);
* SE(2) poses ``[x, y, th]`` -- :func:`compose`, :func:`inverse`, :func:`between`;
* rigid alignment -- :func:`align_se2` returns an :class:`Se2Alignment` (angle,
  translation, rotation matrix, ``apply``); :func:`apply_se2`; :func:`ate_rmse`;
* ring distances on the pose-cell torus -- :func:`ring_distance`, :func:`pc_distance`;
* dead reckoning -- :func:`dead_reckoning` integrates ``(vtrans, vrot, dt)`` as the
  experience map does (turn, then step along the new heading), :func:`odometry_step`
  is one such step (or a midpoint step) for online integrators; :func:`chain_poses`
  composes a chain of relative SE(2) steps (a graph's odometry edges).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, TypeVar, overload

import numpy as np

from ratslam_graph.errors import InputError

TWO_PI = 2.0 * np.pi
_TAU = 2.0 * math.pi  # the same value as a Python float

__all__ = [
    "TWO_PI",
    "Se2Alignment",
    "align_se2",
    "apply_se2",
    "ate_rmse",
    "between",
    "chain_poses",
    "compose",
    "dead_reckoning",
    "inverse",
    "odometry_step",
    "pc_distance",
    "pc_distance_one",
    "ring_distance",
    "signed_delta",
    "wrap_angle",
]

_T = TypeVar("_T")
_NUMPY_LIKE = (np.ndarray, np.generic, float, int, list, tuple)


# --------------------------------------------------------------------------- angles
@overload
def wrap_angle(a: float, *, include_pi: bool = ...) -> float: ...
@overload
def wrap_angle(a: np.ndarray, *, include_pi: bool = ...) -> np.ndarray: ...
@overload
def wrap_angle(a: _T, *, include_pi: bool = ...) -> _T: ...
def wrap_angle(a: Any, *, include_pi: bool = False) -> Any:
    """Wrap angles to ``[-pi, pi)`` (or ``(-pi, pi]`` with ``include_pi``).

    ``[-pi, pi)`` is computed as ``((a + pi) mod 2pi) - pi`` and ``(-pi, pi]`` as
    ``pi - ((pi - a) mod 2pi)`` (OpenRatSLAM's ``clip_rad_180``); the two differ at the
    boundary and in the last bit of some values, so each caller keeps the one its
    results were recorded with.

    Args:
        a: angles in radians: a float, anything numpy converts, or a tensor-like
            object with ``+``, ``-`` and ``%`` (returned as the same type).
        include_pi: wrap to ``(-pi, pi]`` instead of ``[-pi, pi)``.

    Returns:
        The wrapped angles; a Python float for a scalar input.

    Shape:
        a: any shape; returns the same shape.
    """
    if isinstance(a, float):  # a scalar: Python's % rounds exactly as np.remainder does
        w = math.pi - (math.pi - a) % _TAU if include_pi else (a + math.pi) % _TAU - math.pi
        return float(w)
    if not isinstance(a, _NUMPY_LIKE):  # a tensor: keep its type, device and dtype
        return math.pi - (math.pi - a) % _TAU if include_pi else (a + math.pi) % _TAU - math.pi
    x = np.asarray(a, dtype=np.float64)
    with np.errstate(invalid="ignore"):  # an infinite angle wraps to NaN, quietly
        if include_pi:
            out = np.pi - np.remainder(np.pi - x, TWO_PI)
        else:
            out = np.remainder(x + np.pi, TWO_PI) - np.pi
    return float(out) if out.ndim == 0 else out


def signed_delta(a: Any, b: Any, *, include_pi: bool = False) -> Any:
    """Signed smallest rotation from ``a`` to ``b``: ``b - a`` wrapped (see :func:`wrap_angle`).

    Shape:
        a, b: broadcastable; returns their broadcast shape (a float for scalars).
    """
    return wrap_angle(
        np.asarray(b, dtype=np.float64) - np.asarray(a, dtype=np.float64), include_pi=include_pi
    )


# --------------------------------------------------------------------------- SE(2) poses
def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """SE(2) composition ``a * b`` (pose ``b`` given in ``a``'s frame, to world).

    Shape:
        a, b: (..., 3) ``[x, y, th]``, broadcastable. Returns (..., 3).
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):  # non-finite in, NaN/inf out
        c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
        x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
        y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
        th = a[..., 2] + b[..., 2]
    return np.stack([x, y, wrap_angle(th)], axis=-1)


def inverse(p: np.ndarray, *, include_pi: bool = False) -> np.ndarray:
    """SE(2) inverse ``p^-1`` (for a transition: the source's pose in the target's frame).

    Shape:
        p: (..., 3) ``[x, y, th]``. Returns (..., 3).
    """
    p = np.asarray(p, dtype=np.float64)
    out = np.empty(p.shape, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):  # non-finite in, NaN/inf out
        c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
        out[..., 0] = -(c * p[..., 0] + s * p[..., 1])
        out[..., 1] = -(-s * p[..., 0] + c * p[..., 1])
    out[..., 2] = wrap_angle(-p[..., 2], include_pi=include_pi)
    return out


def between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """SE(2) relative pose ``a^-1 * b`` (``b`` expressed in ``a``'s frame).

    Shape:
        a, b: (..., 3) ``[x, y, th]``, broadcastable. Returns (..., 3).
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):  # non-finite in, NaN/inf out
        c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
        dx = b[..., 0] - a[..., 0]
        dy = b[..., 1] - a[..., 1]
        xy = [c * dx + s * dy, -s * dx + c * dy]
        th = b[..., 2] - a[..., 2]
    return np.stack([*xy, wrap_angle(th)], axis=-1)


# --------------------------------------------------------------------------- alignment
def _xy(a: np.ndarray, what: str) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] < 2:
        raise InputError(f"{what} must be an (N, 2) or (N, 3) array of x, y(, th); got {a.shape}")
    if not np.all(np.isfinite(a[:, :2])):
        raise InputError(f"{what}: contains NaN or infinite positions; clean the input first")
    return a[:, :2]


@dataclass(frozen=True)
class Se2Alignment:
    """A rigid motion ``p -> R(angle) p + translation`` (no scale), from :func:`align_se2`.

    Attributes:
        angle: rotation in radians.
        translation: (2,) translation applied after the rotation.
    """

    angle: float
    translation: np.ndarray

    @property
    def rotation(self) -> np.ndarray:
        """The (2, 2) rotation matrix ``R(angle)``."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        return np.array([[c, -s], [s, c]])

    def apply(self, poses: np.ndarray) -> np.ndarray:
        """``poses`` moved by this motion (see :func:`apply_se2`).

        Shape:
            poses: (N, 2) or (N, 3); returns the same shape.
        """
        return apply_se2(poses, self.angle, self.translation)


def align_se2(
    source: np.ndarray, target: np.ndarray, weights: np.ndarray | None = None
) -> Se2Alignment:
    """The rigid motion that best maps ``source`` onto ``target`` (least squares on x, y).

    Minimises ``sum_i w_i |R(angle) source_i + t - target_i|^2`` over rotations (no
    reflection, no scale) and translations, in closed form (Umeyama 1991 in 2D).
    ``align_se2(a, b).apply(a)`` is ``a`` aligned onto ``b``.

    Args:
        source: points or poses to move (a third column, the heading, is ignored).
        target: corresponding points.
        weights: non-negative weights with a positive sum; None weighs all equally.

    Shape:
        source, target: (N, 2+) with the same N; weights: (N,) or None.

    Raises:
        InputError: shapes differ, no points, non-finite values or bad weights.
    """
    s, d = _xy(source, "source"), _xy(target, "target")
    if len(s) != len(d):
        raise InputError(f"cannot align {len(s)} points with {len(d)}: counts differ")
    if len(s) == 0:
        raise InputError("cannot align empty trajectories")
    w = np.ones(len(s)) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (len(s),) or np.any(w < 0) or w.sum() <= 0:
        raise InputError("weights must be (N,) non-negative with a positive sum")
    w = w / w.sum()
    # weighted means as elementwise products and sums (no BLAS call: the same bits
    # whichever BLAS kernel the CPU picks)
    ms = np.array([np.sum(w * s[:, 0]), np.sum(w * s[:, 1])])
    md = np.array([np.sum(w * d[:, 0]), np.sum(w * d[:, 1])])
    sc, dc = s - ms, d - md
    # cross-covariance terms: the optimal angle is atan2(sum w (s x d), sum w (s . d))
    dot = np.sum(w * (sc[:, 0] * dc[:, 0] + sc[:, 1] * dc[:, 1]))
    cross = np.sum(w * (sc[:, 0] * dc[:, 1] - sc[:, 1] * dc[:, 0]))
    angle = float(np.arctan2(cross, dot))
    c, sn = np.cos(angle), np.sin(angle)
    t = md - np.array([c * ms[0] - sn * ms[1], sn * ms[0] + c * ms[1]])
    return Se2Alignment(angle, t)


def apply_se2(poses: np.ndarray, angle: float, t: np.ndarray) -> np.ndarray:
    """Apply a rigid motion to points or poses (headings rotate too, wrapped to [-pi, pi)).

    Shape:
        poses: (N, 2) or (N, 3); t: (2,). Returns the same shape.
    """
    p = np.array(poses, dtype=np.float64, copy=True)
    c, s = np.cos(angle), np.sin(angle)
    x, y = p[:, 0].copy(), p[:, 1].copy()
    p[:, 0] = c * x - s * y + t[0]
    p[:, 1] = s * x + c * y + t[1]
    if p.shape[1] >= 3:
        p[:, 2] = wrap_angle(p[:, 2] + angle)
    return p


def ate_rmse(estimate: np.ndarray, groundtruth: np.ndarray, *, align: bool = True) -> float:
    """Absolute trajectory error (metres): position RMSE after rigid SE(2) alignment.

    Args:
        estimate: estimated positions (a heading column is ignored).
        groundtruth: true positions at the same instants.
        align: align the estimate onto the ground truth first (rigid, no scale; needs
            two or more poses).

    Shape:
        estimate, groundtruth: (N, 2+) with matching rows.

    Raises:
        InputError: mismatched counts, no poses or non-finite values.
    """
    e = _xy(estimate, "estimate")
    g = _xy(groundtruth, "groundtruth")
    if e.shape[0] != g.shape[0]:
        raise InputError(
            f"ATE needs one ground-truth pose per estimate: got {e.shape[0]} and {g.shape[0]}"
        )
    if e.shape[0] == 0:
        raise InputError("ATE of an empty trajectory is undefined")
    if align and e.shape[0] >= 2:
        e = align_se2(e, g).apply(e)
    diff = e - g
    return float(np.sqrt(np.mean(np.sum(diff * diff, axis=1))))


# --------------------------------------------------------------------------- rings
def ring_distance(a: np.ndarray, b: np.ndarray, size: float | None) -> np.ndarray:
    """Absolute difference of coordinates on a ring of ``size`` cells (plain if None).

    Shape:
        a, b: broadcastable arrays. Returns their broadcast shape.
    """
    d = np.abs(np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64))
    if size is None:
        return d
    d = np.remainder(d, size)
    return np.minimum(d, size - d)


def pc_distance(a: Any, b: Any, dims: Sequence[int]) -> np.ndarray:
    """Pose-cell distance: per axis the shorter way round the ring, then Euclidean.

    Args:
        a, b: pose-cell coordinates ``(x, y, th)`` in cells (broadcastable).
        dims: ring sizes ``(X, Y, TH)``.

    Shape:
        a: ``(..., 3)``; b broadcastable to it; returns ``a.shape[:-1]``.
    """
    d = np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64))
    n = np.asarray(dims, np.float64)
    d = np.minimum(np.mod(d, n), n - np.mod(d, n))
    return np.sqrt((d * d).sum(-1))


def pc_distance_one(a: Sequence[float], b: Sequence[float], dims: Sequence[int]) -> float:
    """:func:`pc_distance` of two cells as Python floats: the same operations in the
    same order (Python's ``%`` rounds as ``np.mod``; three squares summed left to right
    as numpy sums them), bit for bit, without numpy's per-call cost.

    Shape:
        a, b: (3,).
    """
    total = 0.0
    for i in range(3):
        n = float(dims[i])
        d = abs(float(a[i]) - float(b[i]))
        m = d % n
        d = min(m, n - m)
        total = d * d if i == 0 else total + d * d
    return math.sqrt(total)


# --------------------------------------------------------------------------- dead reckoning
def dead_reckoning(
    vtrans: np.ndarray,
    vrot: np.ndarray,
    dt: np.ndarray,
    *,
    start: Sequence[float] = (0.0, 0.0, 0.0),
) -> np.ndarray:
    """Integrate odometry as the experience map does: turn by ``vrot*dt``, then step
    ``vtrans*dt`` along the new heading::

        th_k = th_{k-1} + vrot_k dt_k;  x_k = x_{k-1} + vtrans_k dt_k cos(th_k);  (y: sin)

    Args:
        vtrans: forward speeds (m/s).
        vrot: turn rates (rad/s).
        dt: time steps (s).
        start: the pose ``[x, y, th]`` before the first step.

    Shape:
        vtrans, vrot, dt: ``(N,)``; returns ``(N, 3)`` poses after each step (headings in
        ``[-pi, pi)``).

    Raises:
        InputError: the three inputs are not 1-D arrays of one length.
    """
    v = np.asarray(vtrans, dtype=np.float64)
    w = np.asarray(vrot, dtype=np.float64)
    h = np.asarray(dt, dtype=np.float64)
    if not (v.shape == w.shape == h.shape) or v.ndim != 1:
        raise InputError(
            "vtrans, vrot and dt must be (N,) arrays of one length: "
            f"{v.shape}, {w.shape}, {h.shape}"
        )
    th = start[2] + np.cumsum(w * h)
    step = v * h
    x = start[0] + np.cumsum(step * np.cos(th))
    y = start[1] + np.cumsum(step * np.sin(th))
    return np.column_stack([x, y, wrap_angle(th)])


def odometry_step(
    pose: Sequence[float], vtrans: float, vrot: float, dt: float, *, midpoint: bool = False
) -> tuple[float, float, float]:
    """One step of dead reckoning for an online integrator (heading wrapped to [-pi, pi)).

    The default turns first and then steps along the new heading, as
    :func:`dead_reckoning` (the experience map's rule); ``midpoint=True`` steps along
    the mean heading of the interval (MBARAM's odometry channel).

    Args:
        pose: ``(x, y, th)`` before the step.
        vtrans, vrot, dt: speed (m/s), turn rate (rad/s) and interval (s).
    """
    x, y, th = (float(v) for v in pose)
    heading = th + 0.5 * vrot * dt if midpoint else th + vrot * dt
    x, y = x + vtrans * dt * math.cos(heading), y + vtrans * dt * math.sin(heading)
    return x, y, wrap_angle(th + vrot * dt)


def chain_poses(steps: np.ndarray, start: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Compose a chain of relative SE(2) steps: ``p_0 = start``, ``p_k = p_{k-1} * steps_k``.

    Headings accumulate by a cumulative sum and positions by a rotated cumulative sum
    (no Python loop); the result equals composing one step at a time with
    :func:`compose` up to rounding.

    Shape:
        steps: (N, 3) ``[dx, dy, dth]`` (step k moves pose k-1 to pose k; row 0 is
        ignored). Returns (N, 3).

    Raises:
        InputError: a step or the start that is not finite, or positions that overflow.
    """
    step = np.asarray(steps, dtype=np.float64).reshape(-1, 3)
    n = len(step)
    poses = np.empty((n, 3))
    if n == 0:
        return poses
    poses[0] = start
    bad = ~np.isfinite(step[1:]).all(axis=1)
    if bad.any() or not np.isfinite(poses[0]).all():
        which = f"step {int(np.flatnonzero(bad)[0]) + 1}" if bad.any() else "the start"
        raise InputError(f"cannot chain poses: {which} is not finite (NaN or inf)")
    with np.errstate(invalid="ignore", over="ignore"):  # overflow is refused below
        th = wrap_angle(np.cumsum(np.concatenate([[start[2]], step[1:, 2]])))
        c, s = np.cos(th[:-1]), np.sin(th[:-1])
        dx = c * step[1:, 0] - s * step[1:, 1]
        dy = s * step[1:, 0] + c * step[1:, 1]
        poses[:, 0] = start[0] + np.concatenate([[0.0], np.cumsum(dx)])
        poses[:, 1] = start[1] + np.concatenate([[0.0], np.cumsum(dy)])
    poses[:, 2] = th
    if not np.isfinite(poses).all():
        raise InputError("cannot chain poses: the positions overflow (steps too large)")
    return poses
