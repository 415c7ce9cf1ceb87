"""Exploration of the office floor and how much of it a run has covered.

:func:`explore_behaviour` picks, for the node ahead, the way out whose passage has been
driven least often (ties broken by the generator), turning around only at dead ends:
an edge-counting walk that drives every passage of the connected floor.
:func:`coverage` measures the floor within a radius of a trajectory.
"""

from __future__ import annotations

import numpy as np

from torchratslam.sim.office.builder import Office
from torchratslam.sim.office.motion import Behaviour, MotionState, options

__all__ = ["coverage", "edge_index", "explore_behaviour"]


def edge_index(office: Office, a: int, b: int) -> int:
    """Row of the passage between nodes ``a`` and ``b`` (either direction), -1 if none."""
    e = office.edges
    hit = np.nonzero(((e[:, 0] == a) & (e[:, 1] == b)) | ((e[:, 0] == b) & (e[:, 1] == a)))[0]
    return int(hit[0]) if len(hit) else -1


def explore_behaviour(
    office: Office, m: MotionState, edge_visits: np.ndarray, rng: np.random.Generator
) -> Behaviour:
    """The behaviour to hold for the node ahead: its least-driven way out.

    Shape:
        edge_visits: (K,) traversal count of each passage.
    """
    opts = options(office, m.u, m.v)
    ways = {b: w for b, w in opts.items() if b is not Behaviour.TURN_AROUND}
    if not ways:
        return Behaviour.TURN_AROUND
    bs = list(ways)
    visits = np.array([edge_visits[edge_index(office, m.v, ways[b])] for b in bs])
    least = np.nonzero(visits == visits.min())[0]
    return bs[int(least[rng.integers(len(least))])]


def coverage(office: Office, xy: np.ndarray, radius: float) -> float:
    """Fraction of the floor's free cells within ``radius`` of some trajectory point.

    Shape:
        xy: (T, 2) positions (m).
    """
    res = office.resolution
    k = int(np.ceil(radius / res))
    oy, ox = np.mgrid[-k : k + 1, -k : k + 1]
    disk = (ox * ox + oy * oy) * res * res <= radius * radius
    dr, dc = oy[disk], ox[disk]
    p = np.asarray(xy, np.float64).reshape(-1, 2)
    c = np.floor((p[:, 0] - office.origin[0]) / res).astype(np.int64)
    r = np.floor((p[:, 1] - office.origin[1]) / res).astype(np.int64)
    cells = np.unique(np.stack([r, c], 1), axis=0)
    rr = (cells[:, :1] + dr[None, :]).ravel()
    cc = (cells[:, 1:] + dc[None, :]).ravel()
    h, w = office.free.shape
    ok = (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w)
    seen = np.zeros_like(office.free)
    seen[rr[ok], cc[ok]] = True
    return float((seen & office.free).sum() / office.free.sum())
