"""The template search compiled with numba (imported lazily): one call per view.

:func:`search_normal` (normal mode) and :func:`search_panoramic` (panoramic mode) run
the whole bound cascade of one view on the CPU: cheap lower bounds of each (template,
offset) pair's sum of absolute differences (SAD), then the float64 SAD itself, summed
row by row and abandoned as soon as the partial sum exceeds the current cut
(successive elimination, :func:`early_sad`). They decide nothing: the pairs they keep
are evaluated again by the exact kernel (:meth:`TemplateMatcher.sparse_sad
<torchratslam.local_view.matcher.TemplateMatcher.sparse_sad>`, in the bank's dtype),
which picks the answer, so the result is the brute-force one. They only skip pairs
whose bound or float64 sum already exceeds the best float64 sum found plus ``margin``,
the rounding allowance the search uses between its bounds and the exact errors.

Compiled functions are cached on disk by numba (``cache=True``); the first use in a
fresh environment compiles them (a few seconds).
"""

from __future__ import annotations

import numpy as np

from ratslam_graph._jit import njit_cached


@njit_cached(nogil=True, inline="always")
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
        if panoramic:  # template columns o .., then .. o - 1 (two contiguous runs)
            trow = data[t, y]
            vrow = view[y]
            for c in range(nx - o):
                s += abs(np.float64(trow[o + c]) - np.float64(vrow[c]))
            for c in range(o):
                s += abs(np.float64(trow[c]) - np.float64(vrow[nx - o + c]))
        else:
            trow = data[t, y, o : o + width]  # indices from range(): no wraparound checks
            vrow = view[y, shift : shift + width]
            for c in range(width):
                s += abs(np.float64(trow[c]) - np.float64(vrow[c]))
        if s > cut:
            break
    return s


@njit_cached(nogil=True, inline="always")
def _sort_into(a: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """``out[:] = np.sort(a)`` for a short, NaN-free ``a`` (a template's columns): an
    insertion sort, several times faster than ``np.sort`` at 64 values."""
    for i in range(a.shape[0]):
        x = a[i]
        j = i
        while j > 0 and out[j - 1] > x:
            out[j] = out[j - 1]
            j -= 1
        out[j] = x


# bound sums may be reassociated (vectorised): the search's margin covers their rounding
_BOUND_MATH = {"reassoc", "nsz", "contract"}


# templates whose pair bounds are computed together (8 kB per offset, in L1 or L2)
PAIR_BLOCK = 1024


@njit_cached(nogil=True)
def pair_bounds(  # pragma: no cover - compiled
    pairs_t: np.ndarray,
    t0: int,
    t1: int,
    vpairs: np.ndarray,
    bases: np.ndarray,
    out: np.ndarray,
    least: np.ndarray,
) -> None:
    """The pair bound of templates ``t0 .. t1 - 1`` at every offset, in the arrays'
    dtype: ``out[k, i]`` is the L1 distance between the view's pair sums ``vpairs`` and
    template ``t0 + i``'s pair sums from entry ``bases[k]`` on, summed in entry order
    (no reassociation, so the same bits on every machine), and ``least[i]`` its least
    over the offsets, NaN when any of them is NaN or infinite; one pass over a
    column-major copy of the templates' pair sums, vectorised across templates.

    Shape:
        pairs_t: ``(2 * (X // 2), capacity)``; vpairs: ``(W // 2,)``; bases: ``(K,)``;
        out: ``(K, >= t1 - t0)``; least: ``(>= t1 - t0,)``.
    """
    m = t1 - t0
    for k in range(bases.shape[0]):
        o = out[k]
        for i in range(m):
            o[i] = 0.0
        for j in range(vpairs.shape[0]):
            row = pairs_t[bases[k] + j, t0:t1]  # indices from range(): no wraparound checks
            v = vpairs[j]
            for i in range(m):
                o[i] += abs(row[i] - v)
        for i in range(m):
            x = o[i]
            low = x if k == 0 or x < least[i] else least[i]
            least[i] = low if x < np.inf else np.nan  # NaN and infinities: NaN


@njit_cached(nogil=True, fastmath=_BOUND_MATH)
def search_normal(  # pragma: no cover - compiled
    data: np.ndarray,
    cols: np.ndarray,
    pairs_t: np.ndarray,
    n: int,
    view: np.ndarray,
    offsets: np.ndarray,
    width: int,
    shift: int,
    hint: int,
    best0: float,
    cap: float,
    margin: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float, float]:
    """Normal mode: every (template, offset) pair through three stages of elimination.

    Per pair, the L1 distance between the sums of pairs of compared columns (the
    view's, summed in float64, against the template's: 47 numbers per template of 48
    columns serve every offset, read from their column-major float32 copy ``pairs_t``
    for :data:`PAIR_BLOCK` templates at a time by :func:`pair_bounds`, less what
    float32's rounding allows), then between the
    compared columns' sums (the view's against ``cols[t, o:o + width]``):
    lower bounds of the pair's SAD by the triangle inequality, each tighter than the
    last; then, if both are within the cut, the float64 SAD itself, row by row with
    early exit. The hint template goes first (its error
    sets a tight cut early), then every template in id order. Within a block, the
    column bounds of the pairs the first bound keeps are computed in one pass before
    the pairs are visited (the loads overlap instead of waiting on each decision); each
    pair is still decided at its turn with the cut of that moment, so what is kept and
    ``pruned`` are what visiting pair by pair gives. It only screens: the pairs it
    returns are evaluated again exactly by the caller.

    Args:
        data: the bank's rows, ``(capacity, Y, X)``.
        cols: each template's column sums, ``(capacity, X)``.
        pairs_t: each template's sums of adjacent column pairs, from even columns then
            from odd columns, column-major, float32 (``(2 * (X // 2), capacity)``;
            NaN where a sum is past float32's range): block ``j``
            of offset ``o``'s window is entry ``(o % 2) * (X // 2) + o // 2 + j``.
        n: templates in the bank.
        view: the view template, ``(Y, X)``.
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
    nb = width // 2
    half = pairs_t.shape[0] // 2
    # the column sums of the view's compared columns, and their sums in pairs
    vcols = np.zeros(width)
    for y in range(view.shape[0]):
        for c in range(width):
            vcols[c] += view[y, shift + c]
    vpairs = np.empty(nb)
    for j in range(nb):
        vpairs[j] = vcols[2 * j] + vcols[2 * j + 1]
    bases = np.empty(kk, np.int64)
    for ki in range(kk):
        bases[ki] = (offsets[ki] % 2) * half + offsets[ki] // 2
    # the pair bounds in float32 (twice as many lanes): ``s32`` is at most
    # ``(1 + eps) * true + eps * vsum`` (the rounding of the inputs to float32 and of
    # the nb-term sum), so ``s32 * (1 - eps) - eps * vsum`` is a lower bound; a bound
    # that is not finite (a value past float32's range) prunes nothing
    v32 = np.empty(nb, np.float32)
    vsum = 0.0
    for j in range(nb):
        v32[j] = np.float32(vpairs[j])
        vsum += abs(vpairs[j])
    eps = 2.0 * (nb + 4) * 2.0**-24
    keep = 1.0 - eps
    slack = eps * vsum
    bound = np.empty((kk, PAIR_BLOCK), np.float32)
    least = np.empty(PAIR_BLOCK, np.float32)
    cand_i = np.empty(PAIR_BLOCK * kk, np.int64)
    cand_k = np.empty(PAIR_BLOCK * kk, np.int64)
    cand_b = np.empty(PAIR_BLOCK * kk, np.float64)
    cand_c = np.empty(PAIR_BLOCK * kk, np.float64)
    out_t = np.empty(n * kk, np.int64)
    out_k = np.empty(n * kk, np.int64)
    out_s = np.empty(n * kk, np.float64)
    m = 0
    best = best0
    pruned = np.inf
    first = 0 <= hint < n
    # the hint alone first, then the templates in id order, a block at a time
    blk0 = -1 if first else 0
    while blk0 < n:
        if blk0 < 0:
            t0, t1 = hint, hint + 1
        else:
            t0, t1 = blk0, min(blk0 + PAIR_BLOCK, n)
        pair_bounds(pairs_t, t0, t1, v32, bases, bound, least)
        # a template whose every pair bound is above the cut is skipped whole (the cut
        # only falls, so it would be skipped later in the block too); the other
        # templates' pairs within the cut are listed in visiting order (the rest lower
        # ``pruned`` as they would at their turn), their column bounds computed in one
        # pass without branches (the loads overlap), then visited
        cut0 = min(best, cap) + margin
        nc = 0
        for i in range(t1 - t0):
            if blk0 >= 0 and first and t0 + i == hint:
                continue
            b = np.float64(least[i]) * keep - slack
            if b > cut0 and b < np.inf:
                if b < pruned:
                    pruned = b
                continue
            for ki in range(kk):
                b = np.float64(bound[ki, i]) * keep - slack
                out = b > cut0 and b < np.inf
                if out and b < pruned:
                    pruned = b
                cand_i[nc] = i
                cand_k[nc] = ki
                cand_b[nc] = b
                nc += not out
        for c in range(nc):
            t = t0 + cand_i[c]
            o = offsets[cand_k[c]]
            cb = 0.0
            win = cols[t, o : o + width]
            for cc in range(width):
                cb += abs(win[cc] - vcols[cc])
            cand_c[c] = cb
        for c in range(nc):
            t = t0 + cand_i[c]
            ki = cand_k[c]
            cut = min(best, cap) + margin
            b = cand_b[c]
            if b > cut and b < np.inf:
                if b < pruned:
                    pruned = b
                continue
            b = cand_c[c]
            if b > cut:
                if b < pruned:
                    pruned = b
                continue
            o = offsets[ki]
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
        blk0 = 0 if blk0 < 0 else t1
    return out_t, out_k, out_s, m, best, pruned


@njit_cached(nogil=True, fastmath=_BOUND_MATH)
def search_panoramic(  # pragma: no cover - compiled
    data: np.ndarray,
    gsort: np.ndarray,
    pool: np.ndarray,
    n: int,
    view: np.ndarray,
    group_of_row: np.ndarray,
    block_of_col: np.ndarray,
    offsets: np.ndarray,
    hint: int,
    cap: float,
    margin: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float, float]:
    """Panoramic mode: the whole bound cascade of one view in one call.

    The view's group column sums (float64) give its sorted profile and its block sums
    at every offset (:func:`~torchratslam.local_view.bounds.view_summaries`' ``gsort``
    and ``pool``); every template's bound at any offset (the L1 distance of the sorted
    profiles) orders the templates. The template of the least bound goes first, then
    the hint, then the others in increasing order of their bound, until that bound
    exceeds the cut; per (template, offset) pair the block-pooled bound, then the
    float64 SAD row by row with early exit. As :func:`search_normal`, it only screens:
    the pairs it returns are evaluated again exactly by the caller.

    Args:
        data: the bank's rows, ``(capacity, Y, X)``.
        gsort: each template's sorted group column sums, ``(capacity, G * X)``.
        pool: each template's group-block sums, ``(capacity, G * B)``.
        n: templates in the bank.
        view: the view template, ``(Y, X)``.
        group_of_row: the row group of each row, ``(Y,)``.
        block_of_col: the column block of each template column, ``(X,)``.
        offsets: the column offset of each offset index, ``(K,)``.
        hint: a template id to try after the first (-1: none).
        cap: the threshold in SAD units (``inf``: none).
        margin: rounding allowance added to every cut.

    Returns:
        ``(t, k, sad, m, best, pruned)`` as :func:`search_normal`.
    """
    ny, nx = view.shape[0], view.shape[1]
    g = gsort.shape[1] // nx
    gb = pool.shape[1]
    nb = gb // g
    kk = offsets.shape[0]
    # the view's group column sums, sorted profile and block sums at every offset
    vg = np.zeros((g, nx))
    for y in range(ny):
        gi = group_of_row[y]
        for c in range(nx):
            vg[gi, c] += view[y, c]
    vsort = np.empty(g * nx)
    for gi in range(g):
        _sort_into(vg[gi], vsort[gi * nx : (gi + 1) * nx])
    # block j (template columns a[j] .. a[j + 1] - 1) faces view columns a[j] - o ..
    # (mod X): differences of the circular prefix sums of the view's group columns
    a = np.zeros(nb + 1, np.int64)
    for c in range(nx - 1, -1, -1):
        a[block_of_col[c]] = c
    a[nb] = nx
    cum = np.zeros((g, 2 * nx + 1))
    for gi in range(g):
        for c in range(2 * nx):
            cum[gi, c + 1] = cum[gi, c] + vg[gi, c % nx]
    vpool = np.empty((kk, gb))
    for ki in range(kk):
        o = offsets[ki]
        for j in range(nb):
            s0 = a[j] - o + nx  # the doubled prefix sums cover the wrap
            s1 = s0 + a[j + 1] - a[j]
            for gi in range(g):
                vpool[ki, gi * nb + j] = cum[gi, s1] - cum[gi, s0]
    # every template's bound at any offset
    tb = np.empty(n)
    for t in range(n):
        b = 0.0
        row = gsort[t]
        for i in range(g * nx):
            b += abs(row[i] - vsort[i])
        tb[t] = b
    order = np.argsort(tb, kind="mergesort")
    out_t = np.empty(n * kk, np.int64)
    out_k = np.empty(n * kk, np.int64)
    out_s = np.empty(n * kk, np.float64)
    m = 0
    best = np.inf
    pruned = np.inf
    seed = order[0] if n > 0 else -1
    if hint == seed or hint >= n:
        hint = -1
    for j in range(n + 2):
        if j == 0:
            t = seed
        elif j == 1:
            t = hint
        else:
            t = order[j - 2]
            if t == seed or t == hint:
                continue
        if t < 0:
            continue
        if j >= 2 and tb[t] > min(best, cap) + margin:
            if tb[t] < pruned:
                pruned = tb[t]
            break  # every later template's bound is at least as large
        for ki in range(kk):
            cut = min(best, cap) + margin
            if tb[t] > cut:
                if tb[t] < pruned:
                    pruned = tb[t]
                break
            b = 0.0
            prow = pool[t]
            for i in range(gb):
                b += abs(prow[i] - vpool[ki, i])
            if b > cut:
                if b < pruned:
                    pruned = b
                continue
            s = early_sad(data, t, view, offsets[ki], True, nx, 0, cut)
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


@njit_cached(nogil=True)
def _group_sums(
    t: np.ndarray, m: int, group_of_row: np.ndarray, g: int
) -> np.ndarray:  # pragma: no cover - compiled
    """Template ``m``'s group column sums in float64, ``(G, X)``."""
    ny, nx = t.shape[1], t.shape[2]
    gs = np.zeros((g, nx))
    for y in range(ny):
        gi = group_of_row[y]
        for c in range(nx):
            gs[gi, c] += t[m, y, c]
    return gs


@njit_cached(nogil=True)
def summaries_panoramic(  # pragma: no cover - compiled
    t: np.ndarray,
    group_of_row: np.ndarray,
    block_of_col: np.ndarray,
    g: int,
    nb: int,
    gsort: np.ndarray,
    pool: np.ndarray,
) -> None:
    """Panoramic bound summaries of templates ``t`` (sums in float64, stored in the
    outputs' dtype): each group's column sums sorted (``gsort``) and summed over each
    block of columns (``pool``), as :func:`~torchratslam.local_view.bounds.template_summaries`.

    Shape:
        t: (M, Y, X); group_of_row: (Y,); block_of_col: (X,); gsort: (M, G * X);
        pool: (M, G * B).
    """
    nx = t.shape[2]
    for m in range(t.shape[0]):
        gs = _group_sums(t, m, group_of_row, g)
        pl = np.zeros(g * nb)
        for gi in range(g):
            gsort[m, gi * nx : (gi + 1) * nx] = np.sort(gs[gi])
            for c in range(nx):
                pl[gi * nb + block_of_col[c]] += gs[gi, c]
        pool[m] = pl


@njit_cached(nogil=True)
def summaries_normal(  # pragma: no cover - compiled
    t: np.ndarray,
    group_of_row: np.ndarray,
    block_of_col: np.ndarray,
    offsets: np.ndarray,
    g: int,
    nb: int,
    pool: np.ndarray,
    cols: np.ndarray,
    pairs: np.ndarray,
) -> None:
    """Normal-mode bound summaries of templates ``t`` (sums in float64, stored in the
    outputs' dtype), as :func:`~torchratslam.local_view.bounds.template_summaries`: the
    group-block sums of every offset's compared window (``pool``, offset-major), the
    column sums (``cols``) and the sums of adjacent column pairs from even, then from
    odd columns (``pairs``, zero-padded).

    Shape:
        t: (M, Y, X); group_of_row: (Y,); block_of_col: (W,) the block of each window
        column; offsets: (K,); pool: (M, K * G * B); cols: (M, X); pairs: (M, 2 * (X // 2)).
    """
    ny, nx = t.shape[1], t.shape[2]
    width = block_of_col.shape[0]
    h = nx // 2
    odd = (nx - 1) // 2
    for m in range(t.shape[0]):
        gs = _group_sums(t, m, group_of_row, g)
        pl = np.zeros(offsets.shape[0] * g * nb)
        for k in range(offsets.shape[0]):
            o = offsets[k]
            for gi in range(g):
                base = (k * g + gi) * nb
                for j in range(width):
                    pl[base + block_of_col[j]] += gs[gi, o + j]
        pool[m] = pl
        cs = np.zeros(nx)
        for y in range(ny):
            for c in range(nx):
                cs[c] += t[m, y, c]
        cols[m] = cs
        pr = np.zeros(2 * h)
        for j in range(h):
            pr[j] = cs[2 * j] + cs[2 * j + 1]
        for j in range(odd):
            pr[h + j] = cs[2 * j + 1] + cs[2 * j + 2]
        pairs[m] = pr
