"""The temporal map (Eqs. 10-11 of the experience-map paper) by Dijkstra over arrays.

The peak experience is seeded with time 0 and every other one with "a very large value";
an experience ``i`` proposes ``tau_j = t_i + t_ij`` to every linked ``j`` (Eq. 10) and
``j`` keeps the smallest proposal (Eq. 11). Processing experiences in increasing time
order (a binary heap, compiled with numba: ``_dijkstra.py``) reaches the paper's fixed
point after visiting each experience once, relaxing its links on a CSR adjacency.

Example:
    >>> import numpy as np
    >>> from ratslam_graph.navigation.temporal import temporal_map
    >>> tm = temporal_map(3, np.array([0, 1]), np.array([1, 2]), np.array([2.0, 3.0]), 0)
    >>> tm.times.tolist(), tm.parent.tolist()
    ([0.0, 2.0, 5.0], [-1, 0, 1])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ratslam_graph.errors import InputError

__all__ = ["Adjacency", "TemporalMap", "adjacency", "temporal_map"]


@dataclass(frozen=True)
class Adjacency:
    """Links as a compressed sparse row table (the neighbours of ``i`` are
    ``nbr[indptr[i]:indptr[i + 1]]`` at times ``time[...]``).

    Shape:
        indptr: (N + 1,); nbr, time, link: (L,) with L = E (directed) or 2E.
    """

    indptr: np.ndarray
    nbr: np.ndarray
    time: np.ndarray
    link: np.ndarray

    @property
    def num_nodes(self) -> int:
        """N, the number of experiences."""
        return len(self.indptr) - 1

    def neighbours(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """``(neighbour ids, link times)`` of experience ``i``."""
        a, b = self.indptr[i], self.indptr[i + 1]
        return self.nbr[a:b], self.time[a:b]


def adjacency(
    num_nodes: int,
    src: np.ndarray,
    dst: np.ndarray,
    dt: np.ndarray,
    *,
    directed: bool = False,
    keep: np.ndarray | None = None,
) -> Adjacency:
    """Build the CSR adjacency of the map's links.

    Args:
        num_nodes: N, the number of experiences.
        src, dst: link endpoints (the map's ``links()["src"]`` and ``["dst"]``).
        dt: the links' transition times ``t_ij`` (s, >= 0).
        directed: False (the paper's links are traversable both ways) lists every link
            from both ends.
        keep: optional mask of links to use (e.g. ``confidence >= threshold``).

    Shape:
        src, dst, dt, keep: (E,).
    """
    s = np.asarray(src, dtype=np.int64).reshape(-1)
    d = np.asarray(dst, dtype=np.int64).reshape(-1)
    w = np.asarray(dt, dtype=np.float64).reshape(-1)
    if not len(s) == len(d) == len(w):
        raise InputError(f"link arrays differ in length: {len(s)}, {len(d)}, {len(w)}")
    if len(s) and (min(s.min(), d.min()) < 0 or max(s.max(), d.max()) >= num_nodes):
        raise InputError(f"a link endpoint is outside [0, {num_nodes})")
    if np.any(~np.isfinite(w)) or np.any(w < 0):
        raise InputError("link times must be finite and >= 0")
    ids = np.arange(len(s), dtype=np.int64)
    if keep is not None:
        m = np.asarray(keep, dtype=bool).reshape(-1)
        s, d, w, ids = s[m], d[m], w[m], ids[m]
    if not directed:
        s, d = np.concatenate([s, d]), np.concatenate([d, s])
        w, ids = np.concatenate([w, w]), np.concatenate([ids, ids])
    order = np.lexsort((d, s))
    counts = np.bincount(s, minlength=num_nodes)
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return Adjacency(indptr=indptr, nbr=d[order], time=w[order], link=ids[order])


@dataclass(frozen=True)
class TemporalMap:
    """Time to reach every experience from the seeded one.

    Attributes:
        start: the seeded (peak) experience.
        times: seconds to reach each experience (``inf`` where unreachable).
        parent: the experience each one was reached from on a fastest route (-1 for
            the start and the unreachable ones).

    Shape:
        times, parent: (N,).
    """

    start: int
    times: np.ndarray
    parent: np.ndarray

    def reachable(self, goal: int) -> bool:
        """Whether ``goal`` has a finite time stamp."""
        return bool(np.isfinite(self.times[goal]))


def temporal_map(
    num_nodes: int,
    src: np.ndarray | None = None,
    dst: np.ndarray | None = None,
    dt: np.ndarray | None = None,
    start: int = 0,
    *,
    adj: Adjacency | None = None,
    directed: bool = False,
) -> TemporalMap:
    """The temporal map seeded at ``start`` (Eqs. 10-11).

    Give either the link arrays ``src, dst, dt`` or a prebuilt ``adj``.

    Shape:
        src, dst, dt: (E,). The result's arrays are (N,).
    """
    if adj is None:
        if src is None or dst is None or dt is None:
            raise InputError("temporal_map needs the link arrays src, dst, dt or an adjacency")
        adj = adjacency(num_nodes, src, dst, dt, directed=directed)
    if adj.num_nodes != num_nodes:
        raise InputError(f"adjacency has {adj.num_nodes} experiences, expected {num_nodes}")
    if not 0 <= start < num_nodes:
        raise InputError(f"start experience {start} is not in [0, {num_nodes})")
    from ratslam_graph.navigation._dijkstra import dijkstra  # numba: imported lazily

    t, parent = dijkstra(
        adj.indptr.astype(np.int64),
        adj.nbr.astype(np.int64),
        adj.time.astype(np.float64),
        int(start),
    )
    return TemporalMap(start=int(start), times=t, parent=parent)
