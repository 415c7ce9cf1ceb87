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


@njit(cache=True, nogil=True, inline="always")
def early_sad(  # pragma: no cover - compiled
    data: np.ndarray,
    t: int,
    view: np.ndarray,
    o: int,
    panoramic: bool,
    width: int,
    shift: int,
    cut: float,
) -> float:
    """The float64 SAD of template ``t`` at column offset ``o`` against ``view``, summed
    row by row; stops after the first row that takes it above ``cut`` (the partial sum,
    a lower bound, is returned then).

    Panoramic: template column ``c`` faces view column ``(c - o) mod X``; normal:
    template columns ``o .. o + width - 1`` face view columns ``shift ..``.
    """
    ny, nx = view.shape[0], view.shape[1]
    s = 0.0
    for y in range(ny):
        if panoramic:
            for c in range(nx):
                v = c - o
                if v < 0:
                    v += nx
                s += abs(np.float64(data[t, y, c]) - np.float64(view[y, v]))
        else:
            trow = data[t, y, o : o + width]  # indices from range(): no wraparound checks
            vrow = view[y, shift : shift + width]
            for c in range(width):
                s += abs(np.float64(trow[c]) - np.float64(vrow[c]))
        if s > cut:
            break
    return s


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
        s = early_sad(data, ti, view, o, panoramic, width, shift, cut)
        if s > cut:
            if s - margin < pruned:
                pruned = s - margin
            continue
        sad[i] = s
        if s < best:
            best = s
    return sad, best, pruned


# bound sums may be reassociated (vectorised): the search's margin covers their rounding
_BOUND_MATH = {"reassoc", "nsz", "contract"}


@njit(cache=True, nogil=True, fastmath=_BOUND_MATH)
def search_normal(  # pragma: no cover - compiled
    data: np.ndarray,
    cols: np.ndarray,
    pairs: np.ndarray,
    n: int,
    view: np.ndarray,
    vcols: np.ndarray,
    vpairs: np.ndarray,
    offsets: np.ndarray,
    width: int,
    shift: int,
    hint: int,
    best0: float,
    cap: float,
    margin: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float, float]:
    """Normal mode: every (template, offset) pair through three stages of elimination.

    Per pair, the L1 distance between the sums of pairs of compared columns (the view's
    ``vpairs`` against the template's, read from ``pairs``: 47 numbers per template of 48
    columns serve every offset), then
    between the compared columns' sums (``vcols`` against ``cols[t, o:o + width]``):
    lower bounds of the pair's SAD by the triangle inequality, each tighter than the
    last; then, if both are within the cut, the float64 SAD itself, row by row with
    early exit. The hint template goes first (its error
    sets a tight cut early), then every template in id order. As
    :func:`screen_pairs`, it only screens: the pairs it returns are evaluated again
    exactly by the caller.

    Args:
        data: the bank's rows, ``(capacity, Y, X)``.
        cols: each template's column sums, ``(capacity, X)``.
        pairs: each template's sums of adjacent column pairs, from even columns then
            from odd columns (``(capacity, 2 * (X // 2))``): block ``j`` of offset
            ``o``'s window is entry ``(o % 2) * (X // 2) + o // 2 + j``.
        n: templates in the bank.
        view: the view template, ``(Y, X)``.
        vcols: the column sums of the view's compared columns ``shift .. shift +
            width - 1``, ``(width,)``.
        vpairs: ``vcols`` summed in pairs ``[v0 + v1, v2 + v3, ...]``, ``(width // 2,)``.
        offsets: the column offset of each offset index, ``(K,)``.
        width: compared columns.
        shift: first compared view column.
        hint: a template id to try first (-1: none).
        best0: the best SAD already known (``inf`` if none).
        cap: the threshold in SAD units (``inf``: none).
        margin: rounding allowance added to every cut.

    Returns:
        ``(t, k, sad, m, best, pruned)``: the first ``m`` entries of ``t``, ``k`` and
        ``sad`` are the pairs screened to the end and their float64 SADs (in the order
        visited), ``best`` the least of those SADs (or ``best0``), ``pruned`` the least
        lower bound of every pair abandoned (bound, or partial sum less ``margin``).
    """
    kk = offsets.shape[0]
    nb = vpairs.shape[0]
    half = pairs.shape[1] // 2
    out_t = np.empty(n * kk, np.int64)
    out_k = np.empty(n * kk, np.int64)
    out_s = np.empty(n * kk, np.float64)
    m = 0
    best = best0
    pruned = np.inf
    for j in range(n + 1):
        if j == 0:
            if hint < 0 or hint >= n:
                continue
            t = hint
        else:
            t = j - 1
            if t == hint:
                continue
        for ki in range(kk):
            cut = min(best, cap) + margin
            o = offsets[ki]
            b = vcols[0] * 0
            base = (o % 2) * half + o // 2
            row = pairs[t, base : base + nb]  # indices from range(): no wraparound checks
            for j in range(nb):
                b += abs(row[j] - vpairs[j])
            if b > cut:
                if b < pruned:
                    pruned = b
                continue
            b = cols[t, 0] * 0
            win = cols[t, o : o + width]
            for c in range(width):
                b += abs(win[c] - vcols[c])
            if b > cut:
                if b < pruned:
                    pruned = b
                continue
            s = early_sad(data, t, view, o, False, width, shift, cut)
            if s > cut:
                if s - margin < pruned:
                    pruned = s - margin
                continue
            out_t[m] = t
            out_k[m] = ki
            out_s[m] = s
            m += 1
            if s < best:
                best = s
    return out_t, out_k, out_s, m, best, pruned
