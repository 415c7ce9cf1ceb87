"""Behaviour arbitration (experience-map paper, Fig. 7).

The local movement module offers a few paths from the robot's position (follow the
corridor, take a branch, turn around); the robot chooses the one spatially closest to
the recalled route. A path's distance to the route is the mean, over the path's sample
points, of each point's distance to the route polyline; every path, point and route
segment is measured in one array operation.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ratslam_graph.errors import InputError

__all__ = ["Arbitration", "choose_path", "distance_to_polyline", "path_distances", "route_ahead"]


@dataclass(frozen=True)
class Arbitration:
    """The arbitration's result.

    Attributes:
        index: the chosen path (-1 when no path was offered).
        distances: each path's mean distance to the route (m).

    Shape:
        distances: (B,).
    """

    index: int
    distances: np.ndarray


def distance_to_polyline(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Distance of every point to a polyline (to its nearest segment).

    Shape:
        points: (..., 2); polyline: (R, 2) with R >= 1. Returns (...).
    """
    p = np.asarray(points, dtype=np.float64)
    q = np.asarray(polyline, dtype=np.float64).reshape(-1, 2)
    if len(q) == 0:
        raise InputError("the route polyline is empty")
    if len(q) == 1:
        return np.hypot(p[..., 0] - q[0, 0], p[..., 1] - q[0, 1])
    a, ab = q[:-1], q[1:] - q[:-1]  # (S, 2)
    ap = p[..., None, :] - a  # (..., S, 2)
    den = np.sum(ab * ab, axis=-1)
    u = np.clip(np.sum(ap * ab, axis=-1) / np.where(den > 0, den, 1.0), 0.0, 1.0)
    diff = ap - u[..., None] * ab
    return np.sqrt(np.sum(diff * diff, axis=-1)).min(axis=-1)


def path_distances(paths: Sequence[np.ndarray] | np.ndarray, route_xy: np.ndarray) -> np.ndarray:
    """Mean distance of each path's points to the route polyline.

    Paths of different lengths are padded (the padding is left out of the mean).

    Shape:
        paths: B arrays (P_b, 2) or one (B, P, 2); route_xy: (R, 2). Returns (B,).
    """
    if len(paths) == 0:
        return np.zeros(0)
    arrs = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in paths]
    lens = np.array([len(a) for a in arrs])
    if np.any(lens == 0):
        raise InputError("every local movement path needs at least one point")
    padded = np.zeros((len(arrs), int(lens.max()), 2))
    mask = np.arange(lens.max())[None, :] < lens[:, None]
    padded[mask] = np.concatenate(arrs)
    d = distance_to_polyline(padded, route_xy)
    return np.where(mask, d, 0.0).sum(axis=1) / lens


def route_ahead(route_xy: np.ndarray, lookahead_m: float | None) -> np.ndarray:
    """The route's first ``lookahead_m`` metres (arc length), ending at an interpolated
    point; None keeps the whole route.

    Shape:
        route_xy: (R, 2). Returns (R', 2), R' <= R + 1.
    """
    r = np.asarray(route_xy, dtype=np.float64).reshape(-1, 2)
    if lookahead_m is None or len(r) < 2:
        return r
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(r, axis=0).T))])
    if lookahead_m >= s[-1]:
        return r
    k = int(np.searchsorted(s, lookahead_m, side="right"))  # s[k-1] <= L < s[k]
    f = (lookahead_m - s[k - 1]) / (s[k] - s[k - 1])
    return np.vstack([r[:k], r[k - 1] + f * (r[k] - r[k - 1])])


def choose_path(
    paths: Sequence[np.ndarray] | np.ndarray,
    route_xy: np.ndarray,
    *,
    lookahead_m: float | None = None,
) -> Arbitration:
    """Choose the local movement path closest to the recalled route (Fig. 7).

    Args:
        paths: the local movement paths available at the robot's position, each a
            sequence of points in the same frame as the route.
        route_xy: the route's experience positions (:func:`route_positions`).
        lookahead_m: compare against the route's first metres only (None: all of it).

    Shape:
        paths: B arrays (P_b, 2); route_xy: (R, 2). ``distances``: (B,).

    Returns:
        The closest path's index (the first on ties) and every path's distance.
    """
    d = path_distances(paths, route_ahead(route_xy, lookahead_m))
    return Arbitration(index=int(np.argmin(d)) if len(d) else -1, distances=d)
