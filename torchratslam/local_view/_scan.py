"""OpenRatSLAM's template search, compiled with numba (imported lazily): a linear scan.

:func:`linear_scan` is ``LocalViewMatch::compare`` of OpenRatSLAM's C++ as written
there: every template in id order, skipped when its mean differs from the view's by
more than ``vt_match_threshold + 0.005``, then every offset, its sum of absolute
differences (SAD) accumulated row by row and abandoned after the first row that takes
it above the least SAD found so far; a strictly smaller SAD replaces the best (ties:
the lowest template id, then the lowest offset). No lower bounds, no ordering: its cost
grows with every template learnt, which is what xRatSLAM's Experiment II measured
against its newest-first search.
"""

from __future__ import annotations

import numpy as np

from ratslam_graph._jit import njit_cached

# OpenRatSLAM's compare(): templates whose mean differs by more than the threshold plus
# this are not compared
MEAN_EPSILON = 0.005


@njit_cached(nogil=True)
def linear_scan(  # pragma: no cover - compiled
    data: np.ndarray,
    means: np.ndarray,
    n: int,
    view: np.ndarray,
    offsets: np.ndarray,
    panoramic: bool,
    width: int,
    shift: int,
    skip: float,
) -> tuple[int, int, float]:
    """OpenRatSLAM's linear scan over the first ``n`` templates.

    Args:
        data: the templates, ``(>= n, Y, X)``.
        means: their means, ``(>= n,)``.
        n: how many templates.
        view: the view template, ``(Y, X)``.
        offsets: the column offsets, in increasing order.
        panoramic: template column ``c`` faces view column ``(c - o) mod X``; otherwise
            template columns ``o .. o + width - 1`` face view columns ``shift ..``.
        width: the compared columns (normal mode).
        shift: ``vt_shift_match`` (normal mode).
        skip: templates with ``|mean - view mean| > skip`` are not compared (inf: none).

    Returns:
        ``(template id, offset index, SAD)``; ``(-1, 0, inf)`` when every template was
        skipped.
    """
    ny, nx = view.shape[0], view.shape[1]
    vmean = 0.0
    for y in range(ny):
        for x in range(nx):
            vmean += np.float64(view[y, x])
    vmean /= ny * nx
    best, best_t, best_k = np.inf, -1, 0
    for t in range(n):
        if abs(vmean - np.float64(means[t])) > skip:
            continue
        for k in range(offsets.shape[0]):
            o = offsets[k]
            s = 0.0
            for y in range(ny):
                if panoramic:
                    for c in range(nx - o):
                        s += abs(np.float64(data[t, y, o + c]) - np.float64(view[y, c]))
                    for c in range(o):
                        s += abs(np.float64(data[t, y, c]) - np.float64(view[y, nx - o + c]))
                else:
                    for c in range(width):
                        s += abs(np.float64(data[t, y, o + c]) - np.float64(view[y, shift + c]))
                if s > best:
                    break
            if s < best:
                best, best_t, best_k = s, t, k
    return best_t, best_k, best
