"""The template search's last stage compiled with numba (imported lazily).

:func:`screen_pairs` walks the (template, offset) pairs that survived the lower bounds,
in increasing order of their bound, and sums each pair's absolute differences in
float64 row by row, abandoning the pair as soon as the partial sum exceeds the current
cut (successive elimination). It decides nothing: the pairs it keeps are evaluated again
by :meth:`TemplateMatcher.pair_sad` (the exact kernel, in the bank's dtype), which picks
the answer, so the result is the brute-force one. It only skips pairs whose float64 sum
already exceeds the best float64 sum found plus ``margin``, the rounding allowance the
search uses between its bounds and the exact errors.

Compiled functions are cached on disk by numba (``cache=True``); the first use in a
fresh environment compiles them (about a second).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def screen_pairs(  # pragma: no cover - compiled
    data: np.ndarray,
    view: np.ndarray,
    t: np.ndarray,
    k: np.ndarray,
    lb: np.ndarray,
    offsets: np.ndarray,
    panoramic: bool,
    width: int,
    shift: int,
    best0: float,
    cap: float,
    margin: float,
) -> tuple[np.ndarray, float, float]:
    """Screen candidate pairs by their float64 SAD with early exit.

    Args:
        data: the bank's rows, ``(N, Y, X)``.
        view: the view template, ``(Y, X)``.
        t, k: template id and offset index of each pair, ``(P,)``, sorted by ``lb``.
        lb: each pair's lower bound of its SAD, ``(P,)``, increasing.
        offsets: the column offset of each offset index, ``(K,)``.
        panoramic: template column ``c`` faces view column ``(c - o) mod X``; else
            template columns ``o .. o + width - 1`` face view columns ``shift ..``.
        width: compared columns (normal mode).
        shift: first compared view column (normal mode).
        best0: the best SAD already known (e.g. of the seeds; ``inf`` if none).
        cap: the threshold in SAD units (``inf``: none).
        margin: rounding allowance added to every cut.

    Returns:
        ``(sad, best, pruned)``: ``sad`` ``(P,)`` the float64 SAD of each pair screened
        to the end (``inf`` for pairs abandoned or never reached), the least such SAD,
        and the least lower bound of the pairs abandoned or never reached (each partial
        sum less ``margin``, or the bound ``lb``).
    """
    n = t.shape[0]
    ny, nx = view.shape[0], view.shape[1]
    sad = np.full(n, np.inf)
    best = best0
    pruned = np.inf
    for i in range(n):
        cut = min(best, cap) + margin
        if lb[i] > cut:
            if lb[i] < pruned:
                pruned = lb[i]
            break
        ti = t[i]
        o = offsets[k[i]]
        s = 0.0
        out = False
        for y in range(ny):
            if panoramic:
                for c in range(nx):
                    v = c - o
                    if v < 0:
                        v += nx
                    s += abs(np.float64(data[ti, y, c]) - np.float64(view[y, v]))
            else:
                for c in range(width):
                    s += abs(np.float64(data[ti, y, o + c]) - np.float64(view[y, shift + c]))
            if s > cut:
                out = True
                break
        if out:
            if s - margin < pruned:
                pruned = s - margin
            continue
        sad[i] = s
        if s < best:
            best = s
    return sad, best, pruned
