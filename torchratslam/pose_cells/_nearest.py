"""The nearest experience cell to the packet, compiled with numba (imported lazily).

:func:`nearest_cell` is what :class:`~torchratslam.pose_cells.stage.PoseCells` asks
after a familiar view: of the experiences learnt with the current template, the one
whose cell lies nearest the (corrected) packet centre. The distance is
:func:`ratslam_graph.geometry.pc_distance`'s arithmetic, operation for operation (per
axis ``|a - b|``, its remainder by the ring, the shorter way round, the three squares
summed left to right, the root), and the first minimum wins as ``np.argmin``'s does, a
NaN included; so the choice is the numpy path's bit for bit, without a dozen small
arrays per frame. Compiled functions are cached on disk by numba (``cache=True``).
"""

from __future__ import annotations

import math

import numpy as np

from ratslam_graph._jit import njit_cached

__all__ = ["nearest_cell"]


@njit_cached(nogil=True, inline="always")
def _ring(a: float, b: float, n: float) -> float:  # pragma: no cover - compiled
    """The shorter way round a ring of ``n`` cells from ``b`` to ``a``."""
    d = abs(a - b)
    m = d % n
    r = n - m
    return r if r < m else m


@njit_cached(nogil=True)
def nearest_cell(  # pragma: no cover - compiled
    cells: np.ndarray,
    ids: np.ndarray,
    skip: int,
    centre: tuple[float, float, float],
    dims: tuple[float, float, float],
) -> tuple[int, float]:
    """Of the rows ``ids`` of ``cells`` other than ``skip``, the first nearest to
    ``centre`` on the wrapping network, and its distance; ``(-1, inf)`` when no row is
    left. A row at a NaN distance (the first such) is returned as numpy's ``argmin``
    returns it.

    Shape:
        cells: ``(M, 3)`` float64; ids: ``(K,)`` int64.
    """
    best = -1
    best_d = math.inf
    for k in range(ids.size):
        i = ids[k]
        if i == skip:
            continue
        dx = _ring(cells[i, 0], centre[0], dims[0])
        dy = _ring(cells[i, 1], centre[1], dims[1])
        dt = _ring(cells[i, 2], centre[2], dims[2])
        total = dx * dx
        total = total + dy * dy
        total = total + dt * dt
        d = math.sqrt(total)
        if math.isnan(d):
            return i, d
        if best < 0 or d < best_d:
            best, best_d = i, d
    return best, best_d
