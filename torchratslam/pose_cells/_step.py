"""One network's pose-cell step on the packet's crop, compiled with numba (imported lazily).

:func:`step_crop` does in one call what :class:`~torchratslam.pose_cells.numpy_engine.NumpyEngine`
describes: gather the crop, excite and inhibit (:func:`~torchratslam.pose_cells._taps.conv3_box`,
on the box of cells that can be non-zero), global inhibition, clamp, normalise, path
integration (OpenRatSLAM's arithmetic, with its edge loss), the theta shift, scatter
back, the new non-zero arcs, the most active cell and OpenRatSLAM's ``find_best`` around
it. Every operation keeps the order and the dtype of the
numpy it stands for, so the bits are numpy's:

* a sum over an array is numpy's pairwise summation (:func:`pairwise_sum`: eight
  accumulators up to 128 elements, halves on a multiple of eight above);
* a float64 weight meant for the activity is rounded to the activity's dtype once, and a
  float32 operation never widens (numba, as numpy, keeps float32 with float32);
* no fast-math and no fused multiply-add (numba leaves floating-point contraction off).

Compiled functions are cached on disk by numba (``cache=True``); the first use in a
fresh environment compiles them (a few seconds per dtype).
"""

from __future__ import annotations

import math

import numpy as np

from ratslam_graph._jit import njit_cached
from torchratslam.pose_cells._taps import conv3_box

__all__ = ["find_best", "minimal_arc", "pairwise_sum", "step_crop", "total"]

_BLOCK = 128  # numpy's PW_BLOCKSIZE


@njit_cached(nogil=True)
def pairwise_sum(a: np.ndarray, lo: int, n: int, zero: float) -> float:  # pragma: no cover
    """numpy's pairwise sum of ``a[lo : lo + n]`` in ``a``'s dtype (``zero`` of that dtype).

    Below 8 elements a running sum from zero; up to 128 eight running sums, combined as
    ``((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))``, then the rest one by one; above,
    the two halves (the first a multiple of 8), each summed the same way.

    Shape:
        a: flat ``(N,)``.
    """
    if n < 8:
        res = zero
        for i in range(lo, lo + n):
            res += a[i]
        return res
    if n <= _BLOCK:
        r = a[lo : lo + 8].copy()
        i = 8
        end = n - n % 8
        while i < end:
            for m in range(8):
                r[m] += a[lo + i + m]
            i += 8
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        while i < n:
            res += a[lo + i]
            i += 1
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return pairwise_sum(a, lo, n2, zero) + pairwise_sum(a, lo + n2, n - n2, zero)


@njit_cached(nogil=True)
def total(a: np.ndarray, block: int, zero: float) -> float:  # pragma: no cover - compiled
    """A pairwise sum of a contiguous array: from zero, one pairwise sum per block of
    ``block`` elements (``0``: the whole array in one block, as numpy 2 sums it), added
    one after another. The order is this code's, whatever numpy is installed.

    Shape:
        a: flat ``(N,)``.
    """
    n = a.size
    step = n if block <= 0 else block
    res = zero
    for lo in range(0, n, step):
        res += pairwise_sum(a, lo, min(step, n - lo), zero)
    return res


@njit_cached(nogil=True)
def minimal_arc(mask: np.ndarray) -> tuple[int, int]:  # pragma: no cover - compiled
    """``(start, length)`` of the shortest circular arc holding every True of ``mask``
    (``(0, 0)`` when empty); on ties, the arc after the first longest empty run.

    Shape:
        mask: ``(n,)`` boolean.
    """
    n = mask.size
    prev = -1  # the last True at or before position n - 1 of mask twice over
    for j in range(n):
        if mask[j]:
            prev = j
    best, big = 0, -1
    for j in range(n):
        if mask[j]:
            gap = j + n - prev - 1  # the empty run before j
            if gap > big:
                best, big = j, gap
            prev = j + n
    if big < 0:
        return 0, 0
    return best, n - big


@njit_cached(nogil=True)
def _position(
    sums: np.ndarray, ring: np.ndarray, sin_l: np.ndarray, cos_l: np.ndarray, n: int
) -> float:  # pragma: no cover - compiled
    """find_best on one axis: ``atan2`` of the phasor sums in cell order (the window
    starts at its lowest cell), times ``n / 2 pi``, minus one cell, wrapped into ``[0, n]``."""
    w = ring.size
    start = 0
    for m in range(1, w):
        if ring[m] < ring[start]:
            start = m
    s1 = sin_l[ring[start]] * sums[start]
    s2 = cos_l[ring[start]] * sums[start]
    for m in range(1, w):
        q = (start + m) % w
        s1 = s1 + sin_l[ring[q]] * sums[q]
        s2 = s2 + cos_l[ring[q]] * sums[q]
    x = math.atan2(s1, s2) * n / (2.0 * math.pi) - 1.0
    while x < 0:
        x += n
    while x > n:
        x -= n
    return x


@njit_cached(nogil=True)
def find_best(
    act: np.ndarray,
    peak: int,
    c: int,
    lookups: np.ndarray,
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """OpenRatSLAM's ``find_best``: the centre ``(x, y, th)`` of the cube of ``+-c`` cells
    (wrapping) around the flat ``peak`` index, summed in float64 as numpy sums the cube:
    over theta one layer after another, then over y the same way (per x), over x pairwise
    (per y), and over each layer's ``(y, x)`` pairwise (per theta).

    Args:
        act: the activity.
        peak: flat index of the most active cell.
        c: ``pc_cells_to_avg``.
        lookups: find_best's ``sin``, ``cos`` of ``(i + 1) 2 pi / n`` per axis, rows
            ``sin x, cos x, sin y, cos y, sin th, cos th`` (padded to the longest axis).

    Shape:
        act: ``(TH, Y, X)``; lookups: ``(6, max(TH, Y, X))``.
    """
    n_t, n_y, n_x = act.shape
    pt, py, px = peak // (n_y * n_x), (peak // n_x) % n_y, peak % n_x
    w = 2 * c + 1
    it = np.empty(w, np.int64)
    iy = np.empty(w, np.int64)
    ix = np.empty(w, np.int64)
    for m in range(w):
        it[m] = (pt + m - c) % n_t
        iy[m] = (py + m - c) % n_y
        ix[m] = (px + m - c) % n_x
    cube = np.empty((w, w, w), np.float64)
    for i in range(w):
        for j in range(w):
            for k in range(w):
                cube[i, j, k] = act[it[i], iy[j], ix[k]]
    c2 = np.zeros((w, w), np.float64)
    for i in range(w):
        for j in range(w):
            for k in range(w):
                c2[j, k] = c2[j, k] + cube[i, j, k]
    sx = np.zeros(w, np.float64)
    for j in range(w):
        for k in range(w):
            sx[k] = sx[k] + c2[j, k]
    sy = np.empty(w, np.float64)
    st = np.empty(w, np.float64)
    flat2 = c2.reshape(w * w)
    flat3 = cube.reshape(w * w * w)
    for m in range(w):
        sy[m] = 0.0 + pairwise_sum(flat2, m * w, w, 0.0)
        st[m] = 0.0 + pairwise_sum(flat3, m * w * w, w * w, 0.0)
    return (
        _position(sx, ix, lookups[0], lookups[1], n_x),
        _position(sy, iy, lookups[2], lookups[3], n_y),
        _position(st, it, lookups[4], lookups[5], n_t),
    )


@njit_cached(nogil=True)
def _move(
    a: np.ndarray, axis: int, base: np.ndarray, step: np.ndarray, w: np.ndarray
) -> np.ndarray:  # pragma: no cover - compiled
    """``s0 + w[k] (s1 - s0)`` per layer ``k``, ``s0`` / ``s1`` the crop moved by
    ``base[k]`` / ``step[k]`` cells along ``axis`` (1: y, 2: x), wrapping on the crop."""
    t, y, x = a.shape
    out = np.empty_like(a)
    twice = np.empty(2 * x, a.dtype)
    for k in range(t):
        wk = w[k]
        if axis == 2:
            o0, o1 = (-base[k]) % x, (-step[k]) % x  # (i - shift) % x = (i + o) % x
            for j in range(y):
                row, dst = a[k, j], out[k, j]
                for i in range(x):  # the row twice over: no wrap inside the next loop
                    twice[i] = row[i]
                    twice[i + x] = row[i]
                for i in range(x):
                    s0 = twice[i + o0]
                    dst[i] = s0 + wk * (twice[i + o1] - s0)
        else:
            for j in range(y):
                r0, r1, dst = a[k, (j - base[k]) % y], a[k, (j - step[k]) % y], out[k, j]
                for i in range(x):
                    s0 = r0[i]
                    dst[i] = s0 + wk * (r1[i] - s0)
    return out


@njit_cached(nogil=True)
def _edge_loss(
    out: np.ndarray,
    src: np.ndarray,
    v: float,
    layer: np.ndarray,
    box_y: tuple[int, int],
    box_x: tuple[int, int],
    n_y: int,
    n_x: int,
    sin: np.ndarray,
    cos: np.ndarray,
    cells: np.ndarray,
    corner: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """Take from ``out`` what OpenRatSLAM drops at the wrap: per layer, the moves of two
    corner cells (of ``src``, before the move) across the edge, summed in float64 and
    rounded to the activity's dtype after each move, subtracted from the corner both
    would have reached."""
    pos_y = np.empty(2, np.int64)
    pos_x = np.empty(2, np.int64)
    for e in range(2):  # local position of each ring's first and last cell
        g = 0 if e == 0 else n_y - 1
        p = (g - box_y[0]) % n_y
        pos_y[e] = p if p < box_y[1] else -1
        g = 0 if e == 0 else n_x - 1
        p = (g - box_x[0]) % n_x
        pos_x[e] = p if p < box_x[1] else -1
    take = np.zeros(1, out.dtype)
    for k in range(out.shape[0]):
        lk = layer[k]
        lost = (v * sin[lk] * (1.0 - v * cos[lk]), v * cos[lk] * (1.0 - v * sin[lk]))
        take[0] = 0
        for m in range(2):
            sy, sx = pos_y[cells[lk, m, 0]], pos_x[cells[lk, m, 1]]
            if sy >= 0 and sx >= 0:
                take[0] = take[0] + lost[m] * src[k, sy, sx]
        cy, cx = pos_y[corner[lk, 0]], pos_x[corner[lk, 1]]
        if cy >= 0 and cx >= 0 and take[0] != 0:
            out[k, cy, cx] = out[k, cy, cx] - take[0]


@njit_cached(nogil=True)
def step_crop(
    act: np.ndarray,
    box: np.ndarray,
    w_e: np.ndarray,
    w_i: np.ndarray,
    inhib: float,
    trans: float,
    rot: float,
    coef: np.ndarray,
    steps: np.ndarray,
    one_cell: bool,
    edge: np.ndarray,
    cells: np.ndarray,
    lookups: np.ndarray,
    c: int,
    block: int,
) -> tuple[int, int, np.ndarray, tuple[float, float, float]]:  # pragma: no cover - compiled
    """One step of the network ``act`` in place, on the crop ``box``.

    Args:
        act: the activity (written unless it died out).
        box: per axis (th, y, x) the crop's ``start``, ``length``, whether it is the
            whole ring (1) or not (0), and ``[lo, hi)`` in the crop holding every
            non-zero cell of ``act`` (the packet's arcs: outside them the convolutions
            skip zeros).
        w_e, w_i: the excitatory and inhibitory 1D kernels in ``act``'s dtype.
        inhib: ``pc_global_inhib`` in ``act``'s dtype.
        trans: translation in cells along each layer's heading.
        rot: rotation in theta cells.
        coef: per global layer, the move along y and x per cell of travel (float64) for
            this direction of travel.
        steps: per global layer, the one-cell neighbour's shift along y and x.
        one_cell: OpenRatSLAM's one-cell path integration (else any distance).
        edge: per global layer ``sin``, ``cos`` of the edge loss (empty: no edge loss).
        cells: per global layer the edge loss's two source cells and their corner, as
            (y_is_last, x_is_last).
        lookups: find_best's tables (see :func:`find_best`; empty: no decoding).
        c: ``pc_cells_to_avg``.
        block: the summation's blocks (:func:`total`; the engine passes ``0``).

    Returns:
        ``(status, peak, arcs, centre)``: status 1 when the activity died out (nothing
        written); the flat index of the most active cell (ties: the lowest); the new
        non-zero arcs ``(start, length)`` per axis (th, y, x); the decoded centre
        ``(x, y, th)`` (zeros without lookups).

    Shape:
        act: ``(TH, Y, X)``; box: ``(3, 5)``; coef, steps: ``(2, TH)``; edge: ``(2, TH)``
        or ``(0, 0)``; cells: ``(TH, 3, 2)``; lookups: ``(6, n)`` or ``(0, 0)``.
    """
    dims = act.shape
    idx = []
    for ax in range(3):
        n = dims[ax]
        ix = np.empty(box[ax, 1], np.int64)
        for m in range(box[ax, 1]):
            ix[m] = (box[ax, 0] + m) % n
        idx.append(ix)
    it, iy, ix = idx[0], idx[1], idx[2]
    t, y, x = it.size, iy.size, ix.size
    crop = np.empty((t, y, x), act.dtype)
    for k in range(t):
        for j in range(y):
            row, dst = act[it[k], iy[j]], crop[k, j]
            for i in range(x):
                dst[i] = row[ix[i]]
    circ_t, circ_y, circ_x = box[0, 2] != 0, box[1, 2] != 0, box[2, 2] != 0
    # the excitation and the inhibition on the cells that can be non-zero (the same bits
    # as on the whole crop: conv3_box)
    e, e_nz = conv3_box(crop, w_e, circ_t, circ_y, circ_x, box[:, 3:5].copy())
    a, _ = conv3_box(e, w_i, circ_t, circ_y, circ_x, e_nz)
    fa = a.reshape(t * y * x)
    fe = e.reshape(t * y * x)
    for p in range(fa.size):
        q = fe[p] - fa[p]
        q = q - inhib
        fa[p] = q if not q < 0 else 0
    zero = np.zeros(1, act.dtype)
    mass = total(fa, block, zero[0])
    centre = (0.0, 0.0, 0.0)
    arcs = np.zeros(6, np.int64)
    if not mass > 0:
        return 1, -1, arcs, centre
    for p in range(fa.size):
        fa[p] = fa[p] / mass
    if trans != 0:
        v = abs(trans)
        base = np.zeros((2, t), np.int64)
        step = np.empty((2, t), np.int64)
        wts = np.empty((2, t), act.dtype)
        for k in range(t):
            for ax in range(2):  # y, x
                cv = v * coef[ax, it[k]]
                if one_cell:
                    step[ax, k] = steps[ax, it[k]]
                    wts[ax, k] = cv
                else:
                    fl = math.floor(cv)
                    base[ax, k] = int(fl)
                    step[ax, k] = int(fl) + 1
                    wts[ax, k] = cv - fl
        src = a
        a = _move(a, 2, base[1], step[1], wts[1])
        a = _move(a, 1, base[0], step[0], wts[0])
        if edge.shape[1] > 0:
            _edge_loss(
                a,
                src,
                v,
                it,
                (box[1, 0], box[1, 1]),
                (box[2, 0], box[2, 1]),
                dims[1],
                dims[2],
                edge[0],
                edge[1],
                cells[:, :2, :],
                cells[:, 2, :],
            )
    if rot != 0:
        r = abs(rot)
        fl = math.floor(r)
        wr = r - fl
        if wr == 0.0:
            wr = 1.0  # its "while (weight > 1) weight -= 1" stops at 1
        sign = -1 if rot < 0 else 1
        s1, s2 = sign * fl, sign * math.ceil(r)
        wts2 = np.empty(2, act.dtype)
        wts2[0] = 1.0 - wr
        wts2[1] = wr
        out = np.empty_like(a)
        w0, w1 = wts2[0], wts2[1]
        for k in range(t):  # layer k takes layers k - s1 and k - s2 (wrapping)
            l1, l2, dst = a[(k - s1) % t].reshape(y * x), a[(k - s2) % t].reshape(y * x), out[k]
            flat = dst.reshape(y * x)
            for q in range(y * x):
                flat[q] = l1[q] * w0
                flat[q] = flat[q] + l2[q] * w1
        a = out
    # scatter back, the non-zero projections and the most active cell
    mt = np.zeros(t, np.bool_)
    my = np.zeros(y, np.bool_)
    mx = np.zeros(x, np.bool_)
    n_y, n_x = dims[1], dims[2]
    top = a[0, 0, 0]
    peak = (it[0] * n_y + iy[0]) * n_x + ix[0]
    for k in range(t):
        for j in range(y):
            src, dst = a[k, j], act[it[k], iy[j]]
            row_g = (it[k] * n_y + iy[j]) * n_x
            on = False
            for i in range(x):
                q = src[i]
                dst[ix[i]] = q
                if q != 0:
                    on = True
                    mx[i] = True
                if q >= top:
                    g = row_g + ix[i]
                    if q > top or g < peak:
                        top, peak = q, g
            if on:
                mt[k] = True
                my[j] = True
    for ax, mask in enumerate((mt, my, mx)):
        if box[ax, 2] != 0:
            s, ln = minimal_arc(mask)
        else:
            s, ln = 0, 0
            first, last = -1, -1
            for m in range(mask.size):
                if mask[m]:
                    if first < 0:
                        first = m
                    last = m
            if first >= 0:
                s, ln = (box[ax, 0] + first) % dims[ax], last - first + 1
        arcs[2 * ax] = s
        arcs[2 * ax + 1] = ln
    if lookups.shape[0] > 0:
        centre = find_best(act, peak, c, lookups)
    return 0, peak, arcs, centre
