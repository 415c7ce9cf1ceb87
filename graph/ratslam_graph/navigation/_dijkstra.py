"""The temporal map's Dijkstra compiled with numba (imported lazily).

One visit per experience in increasing time order (a binary heap); each visit relaxes
the experience's links in CSR order with a strict ``<`` (Eq. 11), so a neighbour
listed twice keeps its smallest proposal and ties keep the first. Compiled functions
are cached on disk by numba (``cache=True``); the first use in a fresh environment
compiles them (about a second). Call it through
:func:`ratslam_graph.navigation.temporal.temporal_map`.
"""

from __future__ import annotations

import heapq

import numpy as np

from ratslam_graph._jit import njit_cached


@njit_cached(nogil=True)
def dijkstra(
    indptr: np.ndarray, nbr: np.ndarray, time: np.ndarray, start: int
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Times from ``start`` and the parent of every experience on a fastest route.

    Shape:
        indptr: (N + 1,); nbr, time: (L,). Returns (N,) float64 and (N,) int64.
    """
    n = len(indptr) - 1
    t = np.full(n, np.inf)
    parent = np.full(n, -1, dtype=np.int64)
    done = np.zeros(n, dtype=np.bool_)
    t[start] = 0.0
    heap = [(0.0, np.int64(start))]
    while len(heap) > 0:
        ti, i = heapq.heappop(heap)
        if done[i]:
            continue
        done[i] = True
        for k in range(indptr[i], indptr[i + 1]):
            j = nbr[k]
            tau = ti + time[k]  # Eq. 10
            if tau < t[j]:  # Eq. 11
                t[j] = tau
                parent[j] = i
                heapq.heappush(heap, (tau, j))
    return t, parent
