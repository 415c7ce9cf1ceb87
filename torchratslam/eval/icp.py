"""ICP between two experience maps, as the multisession paper computed its figures.

The paper compares its single-session and multisession maps with LibICP (Geiger) and
prints the residual LibICP returns: the **mean squared** nearest-neighbour distance
(m^2, not an RMSE) after point-to-point ICP. LibICP's roles: the *model* ``M`` is the
fixed set (the nearest-neighbour search runs on it), the *template* ``T`` is the set
that moves, ``M ~ R T + t``. The paper's template is the single-session map and its
model the multisession map: the **single-session map moves** onto the multisession
map. 2-D experience positions, every point (no inlier distance), started from the
identity. On the authors' own Lab Tour saves this gives the paper's 0.00883269 exactly;
moving the multisession map instead gives 0.0134467.

:func:`libicp_point_to_point` does what LibICP's ``IcpPointToPoint`` does: per iteration
each moved template point is paired with its nearest model point, the rigid motion of
the pairs is fitted in closed form (SVD of the cross-covariance, reflection fixed, no
scale) and composed with the current one; it goes on while the step's change
``max(|dR - I|_F, |dt|)`` is above ``min_delta`` (1e-4), for at most ``max_iter`` (200)
steps; the residual is the mean squared distance of every moved template point to its
nearest model point. (LibICP stores the points in float32; this runs in float64, which
moves the Lab Tour figure by about 1e-12 m^2.)

ICP from the identity can stop in a wrong local minimum (a map turned by a large angle
against the other). :func:`libicp_starts` runs the same ICP from several rotations of
the template about its centroid and reports the best residual and the spread; it warns
when the identity start (the paper's figure) is not the best minimum.

:func:`compare_icp` gives those figures next to the project's own RMSE
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

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from torchratslam.errors import InputError

__all__ = [
    "DEFAULT_START_ANGLES_DEG",
    "PAPER_ICP_MSE_M2",
    "LibIcpResult",
    "LibIcpStarts",
    "compare_icp",
    "libicp_point_to_point",
    "libicp_starts",
    "nearest_neighbours",
]

log = logging.getLogger(__name__)

PAPER_ICP_MSE_M2 = {
    "virtual_tour": 0.00773327,
    "lab_tour": 0.00883269,
    "irat": 0.0126932,
    "irat_like": 0.0126932,
    "new_college": 85.4687,
}
"""The paper's ICP figures (Figs. 10, 14, 16, 18; printed as "RMSE"): LibICP residuals,
mean squared nearest-neighbour distances in m^2, the single-session map moved onto the
multisession map."""

DEFAULT_START_ANGLES_DEG = (0.0, 90.0, 180.0, 270.0)
"""The start rotations :func:`libicp_starts` tries (degrees; 0 is LibICP's identity)."""


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
    point, by a full scan (ties go to the lowest index). The scan ranks
    ``|p|^2 - 2 q.p`` with both sets centred on ``points``' centroid (rounding can only
    swap neighbours closer than about 1e-12 of the map's extent squared); the returned
    distances are computed directly. Memory is bounded by chunking.

    Shape:
        query: ``(N, 2)``; points: ``(M, 2)``; returns ``(N,)`` int64 and ``(N,)`` float64.
    """
    n, m = query.shape[0], points.shape[0]
    idx = np.empty(n, np.int64)
    centre = points.mean(0)
    pc = points - centre
    p_sq = pc[:, 0] * pc[:, 0] + pc[:, 1] * pc[:, 1]
    step = max(1, (1 << 21) // max(m, 1))
    for a in range(0, n, step):
        rank = (query[a : a + step] - centre) @ pc.T
        rank *= -2.0
        rank += p_sq
        idx[a : a + step] = np.argmin(rank, axis=1)
    diff = query - points[idx]
    return idx, diff[:, 0] * diff[:, 0] + diff[:, 1] * diff[:, 1]


def _fit(moved: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """LibICP's closed-form step: ``R, t`` minimising ``sum |R p_i + t - q_i|^2`` for the
    moved template points ``p`` and their model neighbours ``q``."""
    mu_p, mu_q = moved.mean(0), target.mean(0)
    h = (moved - mu_p).T @ (target - mu_q)
    u, _, vt = np.linalg.svd(h)
    r = vt.T @ u.T
    if np.linalg.det(r) < 0:  # an improper rotation (reflection): flip the last axis
        b = np.diag([1.0, float(np.linalg.det(r))])
        r = vt.T @ b @ u.T
    return r, mu_q - r @ mu_p


def _rotation(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


@dataclass(frozen=True)
class LibIcpResult:
    """Result of :func:`libicp_point_to_point`.

    Attributes:
        rotation: ``(2, 2)`` rotation applied to the template.
        translation: ``(2,)`` translation applied after the rotation (``R T + t``).
        residual_m2: mean squared nearest-neighbour distance of the moved template to the
            model (m^2): LibICP's residual, the paper's figure.
        iterations: ICP steps run.
        converged: the last step changed the transform by at most ``min_delta``.
        start_angle_rad: the start rotation of the template about its centroid (0: the
            identity, LibICP's start).
        aligned: the moved template, ``(N, 2)``.
    """

    rotation: np.ndarray
    translation: np.ndarray
    residual_m2: float
    iterations: int
    converged: bool
    start_angle_rad: float
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
    start_angle_rad: float = 0.0,
) -> LibIcpResult:
    """Point-to-point ICP as LibICP computes it: ``template`` moved onto the fixed
    ``model``; returns the mean squared residual (m^2).

    Args:
        template: the moved map (the paper: the single-session map). Shape: ``(N, 2|3)``.
        model: the fixed map, searched for nearest neighbours (the paper: the
            multisession map). Shape: ``(M, 2|3)``.
        max_iter: at most this many steps (LibICP: 200).
        min_delta: go on while ``max(|dR - I|_F, |dt|)`` of a step is above this
            (LibICP: 1e-4).
        start_angle_rad: start with the template turned by this angle about its
            centroid; 0 (LibICP, the paper) starts from the identity.

    Returns:
        :class:`LibIcpResult`.

    Raises:
        InputError: an empty map, a wrong shape or non-finite positions.
    """
    tpl, mdl = _xy(template, "template"), _xy(model, "model")
    if start_angle_rad == 0.0:
        rot, t = np.eye(2), np.zeros(2)
    else:
        rot = _rotation(start_angle_rad)
        centre = tpl.mean(0)
        t = centre - rot @ centre
    it, delta = 0, math.inf
    while it < max_iter and delta > min_delta:
        moved = tpl @ rot.T + t
        j, _ = nearest_neighbours(moved, mdl)
        r_inc, t_inc = _fit(moved, mdl[j])
        rot, t = r_inc @ rot, r_inc @ t + t_inc
        delta = max(float(np.linalg.norm(r_inc - np.eye(2))), float(np.linalg.norm(t_inc)))
        it += 1
    moved = tpl @ rot.T + t
    _, d2 = nearest_neighbours(moved, mdl)
    return LibIcpResult(
        rot, t, float(np.mean(d2)), it, bool(delta <= min_delta), float(start_angle_rad), moved
    )


@dataclass(frozen=True)
class LibIcpStarts:
    """Result of :func:`libicp_starts`: the same ICP from several start rotations.

    Attributes:
        results: one :class:`LibIcpResult` per start, in the order of the angles.
        rtol: relative tolerance under which two residuals are the same minimum.
    """

    results: tuple[LibIcpResult, ...]
    rtol: float

    @property
    def identity(self) -> LibIcpResult:
        """The identity start: LibICP's (the paper's) figure."""
        return next(r for r in self.results if r.start_angle_rad == 0.0)

    @property
    def best(self) -> LibIcpResult:
        """The best minimum, by a stated rule: of the starts whose residuals lie within
        ``rtol`` of the smallest (the same minimum), the first in the order tried (the
        identity first, then the angles as given). Starts that reach one minimum differ
        only by rounding, which differs between CPU kernels; the rule never lets it pick."""
        return self._lowest

    @property
    def _lowest(self) -> LibIcpResult:
        low = min(r.residual_m2 for r in self.results)
        return next(r for r in self.results if self._same_minimum(r.residual_m2, low))

    def _same_minimum(self, residual: float, low: float) -> bool:
        return residual <= low * (1.0 + self.rtol) + 1e-15

    @property
    def spread_m2(self) -> float:
        """Largest minus smallest residual over the starts (m^2)."""
        res = [r.residual_m2 for r in self.results]
        return max(res) - min(res)

    @property
    def starts_agree(self) -> bool:
        """Every start ended in the same minimum (residuals within ``rtol``)."""
        res = [r.residual_m2 for r in self.results]
        return self._same_minimum(max(res), min(res))

    @property
    def identity_is_best(self) -> bool:
        """The identity start's minimum is the best one (within ``rtol``)."""
        return self._lowest is self.identity

    def warning(self) -> str | None:
        """One line when the identity start stopped in a worse minimum than another
        start, else None."""
        if self.identity_is_best:
            return None
        ident, best = self.identity, self.best
        return (
            f"ICP from the identity stopped in a local minimum: residual "
            f"{ident.residual_m2:.6g} m^2, against {best.residual_m2:.6g} m^2 from a start "
            f"turned by {math.degrees(best.start_angle_rad):.0f} deg; the maps are probably "
            f"turned against each other, so the identity figure (LibICP's, the paper's) "
            f"understates their similarity"
        )


def libicp_starts(
    template: Any,
    model: Any,
    *,
    start_angles_deg: tuple[float, ...] = DEFAULT_START_ANGLES_DEG,
    rtol: float = 0.01,
    max_iter: int = 200,
    min_delta: float = 1e-4,
) -> LibIcpStarts:
    """:func:`libicp_point_to_point` from several rotations of the template about its
    centroid; logs a warning when the identity start is not the best minimum.

    Args:
        template: the moved map (the single-session map). Shape: ``(N, 2|3)``.
        model: the fixed map (the multisession map). Shape: ``(M, 2|3)``.
        start_angles_deg: the start rotations (degrees); 0 is added when missing.
        rtol: residuals within this relative tolerance are the same minimum.
        max_iter: as :func:`libicp_point_to_point`.
        min_delta: as :func:`libicp_point_to_point`.

    Returns:
        :class:`LibIcpStarts`.

    Raises:
        InputError: as :func:`libicp_point_to_point`, or a negative ``rtol``.
    """
    if rtol < 0:
        raise InputError(f"rtol must be >= 0, got {rtol}")
    angles = tuple(dict.fromkeys((0.0, *(float(a) % 360.0 for a in start_angles_deg))))
    results = tuple(
        libicp_point_to_point(
            template,
            model,
            max_iter=max_iter,
            min_delta=min_delta,
            start_angle_rad=math.radians(a),
        )
        for a in angles
    )
    out = LibIcpStarts(results, rtol)
    warning = out.warning()
    if warning is not None:
        log.warning("%s", warning)
    return out


def compare_icp(template: Any, model: Any, *, starts: LibIcpStarts | None = None) -> dict[str, Any]:
    """Every ICP figure of two maps, each named for what it is (JSON-able).

    Args:
        template: the moved map (the paper: single-session). Shape: ``(N, 2|3)``.
        model: the fixed map (the paper: multisession). Shape: ``(M, 2|3)``.
        starts: :func:`libicp_starts` of the same two maps when already computed;
            None computes it.

    Returns:
        ``libicp_mse_m2`` (the paper's figure: mean squared nearest-neighbour distance
        in m^2 after LibICP-style ICP from the identity moving ``template`` onto
        ``model``), ``libicp_iterations``, ``libicp_converged``, ``transform``
        (``dth_rad, tx_m, ty_m`` of that ICP: ``x' = R(dth) x + t`` applied to
        ``template``), the other starts (``libicp_best_mse_m2``,
        ``libicp_best_start_deg``, ``libicp_spread_m2``, ``libicp_starts_agree``,
        ``libicp_starts``: per start ``start_deg, mse_m2, iterations``, and
        ``libicp_warning``: a line when the identity is not the best minimum, else
        None), ``icp_rmse_m`` (the project's RMSE in m,
        :func:`torchratslam.eval.metrics.icp` moving ``template`` onto ``model``) and
        ``icp_rmse_swapped_m`` (the same with the roles swapped: ``model`` moved onto
        ``template``; ICP is not symmetric).
    """
    from torchratslam.eval.metrics import icp

    if starts is None:
        starts = libicp_starts(template, model)
    lib, best = starts.identity, starts.best
    return {
        "libicp_mse_m2": lib.residual_m2,
        "libicp_iterations": lib.iterations,
        "libicp_converged": lib.converged,
        "transform": {
            "dth_rad": lib.angle_rad,
            "tx_m": float(lib.translation[0]),
            "ty_m": float(lib.translation[1]),
        },
        "libicp_best_mse_m2": best.residual_m2,
        "libicp_best_start_deg": math.degrees(best.start_angle_rad),
        "libicp_spread_m2": starts.spread_m2,
        "libicp_starts_agree": starts.starts_agree,
        "libicp_starts": [
            {
                "start_deg": math.degrees(r.start_angle_rad),
                "mse_m2": r.residual_m2,
                "iterations": r.iterations,
            }
            for r in starts.results
        ],
        "libicp_warning": starts.warning(),
        "icp_rmse_m": float(icp(template, model).rmse),
        "icp_rmse_swapped_m": float(icp(model, template).rmse),
    }
