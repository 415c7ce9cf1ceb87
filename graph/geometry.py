"""Rigid SE(2) alignment (Umeyama without scale) and absolute trajectory error, in numpy.

Torch-free so that both ``graph`` and the torch front end can use it.
"""

from __future__ import annotations

import numpy as np

from torchratslam.graph.errors import InputError


def _xy(a: np.ndarray, what: str) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] < 2:
        raise InputError(f"{what} must be an (N, 2) or (N, 3) array of x, y(, th); got {a.shape}")
    return a[:, :2]


def umeyama_se2(
    source: np.ndarray, target: np.ndarray, weights: np.ndarray | None = None
) -> tuple[float, np.ndarray]:
    """Rotation angle and translation that best map ``source`` onto ``target``.

    Minimises ``sum_i w_i |R(angle) source_i + t - target_i|^2`` over rotations (no
    reflection, no scale) and translations, in closed form (Umeyama 1991 in 2D).

    Shape:
        source, target: (N, 2+) (only x, y are used); weights: (N,) or None.

    Returns:
        (angle, t) with t of shape (2,).
    """
    s, d = _xy(source, "source"), _xy(target, "target")
    if len(s) != len(d):
        raise InputError(f"source has {len(s)} points but target has {len(d)}")
    if len(s) == 0:
        raise InputError("cannot align empty trajectories")
    w = np.ones(len(s)) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (len(s),) or np.any(w < 0) or w.sum() <= 0:
        raise InputError("weights must be (N,) non-negative with a positive sum")
    w = w / w.sum()
    ms, md = w @ s, w @ d
    sc, dc = s - ms, d - md
    # cross-covariance terms: the optimal angle is atan2(sum w (s x d), sum w (s . d))
    dot = np.sum(w * (sc[:, 0] * dc[:, 0] + sc[:, 1] * dc[:, 1]))
    cross = np.sum(w * (sc[:, 0] * dc[:, 1] - sc[:, 1] * dc[:, 0]))
    angle = float(np.arctan2(cross, dot))
    c, sn = np.cos(angle), np.sin(angle)
    t = md - np.array([c * ms[0] - sn * ms[1], sn * ms[0] + c * ms[1]])
    return angle, t


def apply_se2(poses: np.ndarray, angle: float, t: np.ndarray) -> np.ndarray:
    """Apply a rigid motion to points or poses (headings rotate too, wrapped).

    Shape:
        poses: (N, 2) or (N, 3); t: (2,). Returns the same shape.
    """
    p = np.array(poses, dtype=np.float64, copy=True)
    c, s = np.cos(angle), np.sin(angle)
    x, y = p[:, 0].copy(), p[:, 1].copy()
    p[:, 0] = c * x - s * y + t[0]
    p[:, 1] = s * x + c * y + t[1]
    if p.shape[1] >= 3:
        p[:, 2] = np.remainder(p[:, 2] + angle + np.pi, 2 * np.pi) - np.pi
    return p


def align_se2(estimate: np.ndarray, groundtruth: np.ndarray) -> np.ndarray:
    """``estimate`` moved rigidly to best fit ``groundtruth`` (least squares on x, y).

    Shape:
        estimate: (N, 2) or (N, 3); groundtruth: (N, 2+). Returns estimate's shape.
    """
    angle, t = umeyama_se2(estimate, groundtruth)
    return apply_se2(estimate, angle, t)


def ate_rmse(estimate: np.ndarray, groundtruth: np.ndarray) -> float:
    """Absolute trajectory error: position RMSE after rigid SE(2) alignment (metres).

    Shape:
        estimate, groundtruth: (N, 2+) with matching rows.
    """
    aligned = align_se2(_xy(estimate, "estimate"), groundtruth)
    diff = aligned - _xy(groundtruth, "groundtruth")
    return float(np.sqrt(np.mean(np.sum(diff * diff, axis=1))))
