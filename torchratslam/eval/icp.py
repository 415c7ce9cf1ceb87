"""ICP between two experience maps, as the multisession paper computed its figures.

The paper compares its single-session and multisession maps with LibICP (Geiger) and
prints the residual LibICP returns: the **mean squared** nearest-neighbour distance
(m^2, not an RMSE) after point-to-point ICP, with the single-session map as the
*template* (the fixed point set, the one the k-d tree is built on) and the multisession
map as the *model* (the set that is moved), 2-D experience positions, every point
(no inlier distance), started from the identity. :func:`libicp_point_to_point` does
exactly that: per iteration each moved model point is paired with its nearest template
point, the rigid motion of the pairs is fitted in closed form (SVD of the
cross-covariance, reflection fixed, no scale), composed with the current one, until the
change is below ``min_delta`` (LibICP's 1e-4) or ``max_iter`` (200) iterations.

:func:`compare_icp` gives that figure next to the project's own RMSE
(:func:`torchratslam.eval.metrics.icp`: the same pairing, converged to 1e-10, the root
of the mean squared distance, in m), each under a name that says what it is:

* ``libicp_mse_m2``: compares with the paper's 0.00773327 (Virtual Tour), 0.00883269
  (Lab Tour), 0.0126932 (iRat) and 85.4687 (Oxford New College), all in m^2;
* ``icp_rmse_m``: metres, easier to read against the size of the map; not comparable
  with the paper's numbers (their square root would be).

Example:
    >>> res = libicp_point_to_point(single_xy, multi_xy)  # doctest: +SKIP
    >>> res.residual_m2  # the paper's figure  # doctest: +SKIP
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from torchratslam.errors import InputError

__all__ = [
    "PAPER_ICP_MSE_M2",
    "LibIcpResult",
    "compare_icp",
    "libicp_point_to_point",
    "nearest_neighbours",
]

PAPER_ICP_MSE_M2 = {
    "virtual_tour": 0.00773327,
    "lab_tour": 0.00883269,
    "irat": 0.0126932,
    "irat_like": 0.0126932,
    "new_college": 85.4687,
}
"""The paper's ICP figures (Figs. 10, 14, 16, 18; printed as "RMSE"): LibICP residuals,
mean squared nearest-neighbour distances in m^2, single-session map fixed."""


def _xy(a: Any, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] < 2:
        raise InputError(f"{name}: expected an (N, 2) or (N, 3) array of poses, got {arr.shape}")
    if arr.shape[0] == 0:
        raise InputError(f"{name}: ICP needs a non-empty map")
    if not np.isfinite(arr[:, :2]).all():
        raise InputError(f"{name}: contains NaN or infinite positions")
    return np.ascontiguousarray(arr[:, :2])


def nearest_neighbours(query: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of and squared distance to the nearest of ``points`` for every ``query``
    point (exact; ties go to the lowest index). Memory is bounded by chunking.

    Shape:
        query: ``(N, 2)``; points: ``(M, 2)``; returns ``(N,)`` int64 and ``(N,)`` float64.
    """
    n, m = query.shape[0], points.shape[0]
    idx = np.empty(n, np.int64)
    d2 = np.empty(n, np.float64)
    step = max(1, (1 << 21) // max(m, 1))
    for a in range(0, n, step):
        diff = query[a : a + step, None, :] - points[None, :, :]
        dist = diff[..., 0] * diff[..., 0] + diff[..., 1] * diff[..., 1]
        j = np.argmin(dist, axis=1)
        idx[a : a + step] = j
        d2[a : a + step] = dist[np.arange(j.size), j]
    return idx, d2


def _fit(model: np.ndarray, template: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """LibICP's closed-form step: ``R, t`` minimising ``sum |R m_i + t - t_i|^2``."""
    mu_m, mu_t = model.mean(0), template.mean(0)
    h = (model - mu_m).T @ (template - mu_t)
    u, _, vt = np.linalg.svd(h)
    r = vt.T @ u.T
    if np.linalg.det(r) < 0:  # an improper rotation (reflection): flip the last axis
        b = np.diag([1.0, float(np.linalg.det(r))])
        r = vt.T @ b @ u.T
    return r, mu_t - r @ mu_m


@dataclass(frozen=True)
class LibIcpResult:
    """Result of :func:`libicp_point_to_point`.

    Attributes:
        rotation: ``(2, 2)`` rotation applied to the model.
        translation: ``(2,)`` translation applied after the rotation.
        residual_m2: mean squared nearest-neighbour distance of the moved model to the
            template (m^2): LibICP's residual, the paper's figure.
        iterations: ICP iterations run.
        aligned: the moved model, ``(N, 2)``.
    """

    rotation: np.ndarray
    translation: np.ndarray
    residual_m2: float
    iterations: int
    aligned: np.ndarray

    @property
    def angle_rad(self) -> float:
        """The rotation as an angle (rad)."""
        return math.atan2(float(self.rotation[1, 0]), float(self.rotation[0, 0]))

    @property
    def rmse_m(self) -> float:
        """``sqrt(residual_m2)`` (m)."""
        return math.sqrt(self.residual_m2)


def libicp_point_to_point(
    template: Any,
    model: Any,
    *,
    max_iter: int = 200,
    min_delta: float = 1e-4,
    inlier_dist: float | None = None,
) -> LibIcpResult:
    """Point-to-point ICP as LibICP computes it: ``model`` moved onto the fixed
    ``template`` from the identity; returns the mean squared residual (m^2).

    Args:
        template: the fixed map (the paper: the single-session map). Shape: ``(M, 2|3)``.
        model: the moved map (the paper: the multisession map). Shape: ``(N, 2|3)``.
        max_iter: at most this many iterations (LibICP: 200).
        min_delta: stop when ``max(|dR|_F, |dt|)`` of a step is below this (LibICP: 1e-4).
        inlier_dist: pair only points closer than this (LibICP's ``indist``); None
            (the paper) pairs every point.

    Returns:
        :class:`LibIcpResult`.

    Raises:
        InputError: an empty map, a wrong shape or non-finite positions.
    """
    tpl, mdl = _xy(template, "template"), _xy(model, "model")
    rot, t = np.eye(2), np.zeros(2)
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 - the count is an output
        moved = mdl @ rot.T + t
        j, d2 = nearest_neighbours(moved, tpl)
        act = np.ones(d2.size, bool) if inlier_dist is None else d2 <= inlier_dist**2
        if act.sum() < 2:
            break
        r_inc, t_inc = _fit(moved[act], tpl[j[act]])
        rot, t = r_inc @ rot, r_inc @ t + t_inc
        delta = max(float(np.linalg.norm(r_inc - np.eye(2))), float(np.linalg.norm(t_inc)))
        if delta < min_delta:
            break
    moved = mdl @ rot.T + t
    _, d2 = nearest_neighbours(moved, tpl)
    if inlier_dist is not None and (d2 <= inlier_dist**2).any():
        d2 = d2[d2 <= inlier_dist**2]
    return LibIcpResult(rot, t, float(np.mean(d2)), it, moved)


def compare_icp(fixed: Any, moved: Any) -> dict[str, Any]:
    """Both ICP figures of two maps, each named for what it is (JSON-able).

    Args:
        fixed: the reference map (the paper: single-session). Shape: ``(M, 2|3)``.
        moved: the compared map (the paper: multisession). Shape: ``(N, 2|3)``.

    Returns:
        ``libicp_mse_m2`` (the paper's figure: mean squared nearest-neighbour distance
        in m^2 after LibICP-style ICP moving ``moved`` onto ``fixed``),
        ``libicp_iterations``, ``transform`` (``dth_rad, tx_m, ty_m`` of that ICP:
        ``x' = R(dth) x + t`` applied to ``moved``), ``icp_rmse_m`` (the project's RMSE
        in m, :func:`torchratslam.eval.metrics.icp` moving ``moved`` onto ``fixed``) and
        ``icp_rmse_swapped_m`` (the same with the roles swapped: ``fixed`` moved onto
        ``moved``; ICP is not symmetric).
    """
    from torchratslam.eval.metrics import icp

    lib = libicp_point_to_point(fixed, moved)
    return {
        "libicp_mse_m2": lib.residual_m2,
        "libicp_iterations": lib.iterations,
        "transform": {
            "dth_rad": lib.angle_rad,
            "tx_m": float(lib.translation[0]),
            "ty_m": float(lib.translation[1]),
        },
        "icp_rmse_m": float(icp(moved, fixed).rmse),
        "icp_rmse_swapped_m": float(icp(fixed, moved).rmse),
    }
