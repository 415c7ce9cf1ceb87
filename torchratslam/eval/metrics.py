"""Map evaluation: ATE after rigid SE(2) alignment, dead reckoning, and ICP RMSE.

* :func:`align_se2`, :func:`apply_se2`, :func:`ate_rmse`, :func:`dead_reckoning` --
  rigid SE(2) alignment (Umeyama's closed form in 2D), absolute trajectory error and
  odometry integration; they live in :mod:`ratslam_graph.geometry` and are
  re-exported here.
* :func:`interpolate_groundtruth` -- ground-truth poses at given times.
* :func:`ate_at_times` -- the ATE of poses at given times over those the ground truth
  covers (none clamped to its ends), undefined below :data:`MIN_ATE_POSES`, with the
  count; :data:`ATE_ALIGNMENT` names the alignment every ATE of the project uses.
* :func:`icp` / :func:`icp_rmse` -- the project's ICP figure (not the papers'):
  point-to-point ICP between two maps (nearest neighbours, closed-form rigid update,
  repeat until the motion is tiny); the RMSE (m) over the final nearest-neighbour
  distances. The papers' figure is LibICP's mean
  squared residual (m^2): :func:`torchratslam.eval.icp.libicp_point_to_point`.

All functions are numpy-only and deterministic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ratslam_graph.geometry import (
    Se2Alignment,
    align_se2,
    apply_se2,
    ate_rmse,
    dead_reckoning,
    wrap_angle,
)
from torchratslam.errors import InputError

__all__ = [
    "ATE_ALIGNMENT",
    "MIN_ATE_POSES",
    "IcpResult",
    "Se2Alignment",
    "align_se2",
    "apply_se2",
    "ate_at_times",
    "ate_rmse",
    "dead_reckoning",
    "icp",
    "icp_rmse",
    "interpolate_groundtruth",
]


def _points(a: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] < 2:
        raise InputError(
            f"{name}: expected an (N, 2) or (N, 3) array of poses, got shape {arr.shape}"
        )
    if not np.all(np.isfinite(arr[:, :2])):
        raise InputError(f"{name}: contains NaN or infinite positions; clean the input first")
    return arr[:, :2]


ATE_ALIGNMENT = "SE(2)"
"""The alignment of every ATE the project reports: a rigid SE(2) transform (rotation and
translation, no scale) fitted by least squares (Umeyama's closed form in 2D)."""
MIN_ATE_POSES = 3
"""Fewer poses with ground truth leave an ATE after an SE(2) alignment undefined."""


def ate_at_times(
    xy: np.ndarray, t: np.ndarray, groundtruth: np.ndarray
) -> tuple[float | None, int]:
    """The ATE (m) of positions ``xy`` at times ``t`` against ``groundtruth``, after an
    :data:`ATE_ALIGNMENT` alignment, over the poses whose time the ground truth covers
    (none is compared with a pose clamped to its ends) and whose position is finite.

    Returns:
        ``(ate, n)``: ``n`` poses with ground truth; ``ate`` None when ``n`` is under
        :data:`MIN_ATE_POSES`.

    Shape:
        xy: ``(N, 2+)``; t: ``(N,)``; groundtruth: ``(T, 4)`` rows ``[t, x, y, theta]``.
    """
    gt = np.asarray(groundtruth, dtype=np.float64)
    q = np.asarray(t, dtype=np.float64).reshape(-1)
    p = np.asarray(xy, dtype=np.float64).reshape(q.size, -1)[:, :2]
    if gt.ndim != 2 or gt.shape[0] == 0 or q.size == 0:
        return None, 0
    ok = (q >= gt[0, 0] - 1e-9) & (q <= gt[-1, 0] + 1e-9) & np.isfinite(p).all(axis=1)
    n = int(ok.sum())
    if n < MIN_ATE_POSES:
        return None, n
    truth = interpolate_groundtruth(gt, q[ok])
    return float(ate_rmse(p[ok], truth[:, :2])), n


def interpolate_groundtruth(groundtruth: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Ground-truth poses at the times ``t`` (linear; heading interpolated unwrapped).

    Args:
        groundtruth: rows ``[t, x, y, theta]`` with increasing t. Shape: ``(T, 4)``.
        t: query times (clamped to the ground truth's time range). Shape: ``(N,)``.

    Returns:
        ``(N, 3)`` poses ``[x, y, theta]``.
    """
    gt = np.asarray(groundtruth, dtype=np.float64)
    if gt.ndim != 2 or gt.shape[1] < 4 or gt.shape[0] == 0:
        raise InputError(f"ground truth must be a (T, 4) array [t, x, y, theta], got {gt.shape}")
    q = np.asarray(t, dtype=np.float64)
    th = np.unwrap(gt[:, 3])
    out = np.stack(
        [
            np.interp(q, gt[:, 0], gt[:, 1]),
            np.interp(q, gt[:, 0], gt[:, 2]),
            np.interp(q, gt[:, 0], th),
        ],
        axis=1,
    )
    out[:, 2] = wrap_angle(out[:, 2], include_pi=True)
    return out


@dataclass(frozen=True)
class IcpResult:
    """Result of :func:`icp`.

    Attributes:
        rotation: (2, 2) rotation applied to the source.
        translation: (2,) translation applied after the rotation.
        rmse: RMSE of the nearest-neighbour distances of the aligned source (inliers
            only when ``max_distance`` was given).
        iterations: iterations run.
        aligned: the moved source points, (N, 2).
    """

    rotation: np.ndarray
    translation: np.ndarray
    rmse: float
    iterations: int
    aligned: np.ndarray


def _nearest(src: np.ndarray, dst: np.ndarray, chunk: int = 2048) -> tuple[np.ndarray, np.ndarray]:
    """Index of and squared distance to the nearest ``dst`` point of every ``src`` point."""
    idx = np.empty(src.shape[0], dtype=np.int64)
    d2 = np.empty(src.shape[0], dtype=np.float64)
    dst_sq = np.sum(dst**2, axis=1)
    for a in range(0, src.shape[0], chunk):
        s = src[a : a + chunk]
        dist = np.sum(s**2, axis=1)[:, None] - 2.0 * s @ dst.T + dst_sq[None, :]
        j = np.argmin(dist, axis=1)
        idx[a : a + chunk] = j
        d2[a : a + chunk] = np.sum((s - dst[j]) ** 2, axis=1)
    return idx, d2


def icp(
    source: np.ndarray,
    target: np.ndarray,
    *,
    max_iterations: int = 200,
    tolerance: float = 1e-10,
    max_distance: float | None = None,
    init: tuple[np.ndarray, np.ndarray] | None = None,
) -> IcpResult:
    """Point-to-point ICP moving ``source`` onto ``target`` (rigid SE(2), no scale).

    Args:
        source: the map to move. Shape: ``(N, 2)`` or ``(N, 3)``.
        target: the fixed map. Shape: ``(M, 2)`` or ``(M, 3)``.
        max_iterations: stop after this many iterations.
        tolerance: stop when the incremental motion (rotation change in rad plus
            translation change in units) is below this.
        max_distance: correspondences farther than this are ignored (libicp's
            inlier distance); None uses all.
        init: an optional initial ``(R, t)``.

    Returns:
        :class:`IcpResult`.
    """
    src = _points(source, "source")
    dst = _points(target, "target")
    if src.shape[0] == 0 or dst.shape[0] == 0:
        raise InputError("ICP needs two non-empty maps")
    rot = np.eye(2) if init is None else np.asarray(init[0], dtype=np.float64)
    t = np.zeros(2) if init is None else np.asarray(init[1], dtype=np.float64)
    it = 0
    for it in range(1, max_iterations + 1):  # noqa: B007 - iterations are the output
        moved = src @ rot.T + t
        j, d2 = _nearest(moved, dst)
        keep = np.ones_like(d2, dtype=bool) if max_distance is None else d2 <= max_distance**2
        if keep.sum() < 2:
            break
        fit = align_se2(moved[keep], dst[j[keep]])
        r_inc, t_inc = fit.rotation, fit.translation
        rot, t = r_inc @ rot, r_inc @ t + t_inc
        if abs(math.atan2(r_inc[1, 0], r_inc[0, 0])) + float(np.linalg.norm(t_inc)) < tolerance:
            break
    moved = src @ rot.T + t
    _, d2 = _nearest(moved, dst)
    if max_distance is not None:
        inl = d2 <= max_distance**2
        d2 = d2[inl] if inl.any() else d2
    return IcpResult(rot, t, float(np.sqrt(np.mean(d2))), it, moved)


def icp_rmse(map_a: np.ndarray, map_b: np.ndarray, **options: float) -> float:
    """RMSE after ICP of ``map_a`` onto ``map_b`` (see :func:`icp`).

    Shape:
        map_a: ``(N, 2|3)``; map_b: ``(M, 2|3)``.
    """
    return icp(map_a, map_b, **options).rmse  # type: ignore[arg-type]
