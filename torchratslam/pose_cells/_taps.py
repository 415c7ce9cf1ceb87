"""The pose cells' separable convolution compiled with numba (imported lazily).

One pass per axis (x, then y, then theta), each output cell the sum of the kernel's
taps in a fixed order: ``out = 0; out += w[0] * a[p + h]; out += w[1] * a[p + h - 1];
...`` in the array's own dtype, every product and sum rounded on its own. No BLAS call
and no fused multiply-add (numba leaves floating-point contraction off), so the result
is the same on every x86-64 CPU, whatever vector width or BLAS kernel it has: a
decision that rests on the last bit of a float32 cell rests on the same bit everywhere.

Compiled functions are cached on disk by numba (``cache=True``); the first use in a
fresh environment compiles them (a few seconds).
"""

from __future__ import annotations

import numpy as np

from ratslam_graph._jit import njit_cached


@njit_cached(nogil=True, inline="always")
def _add(  # pragma: no cover - compiled
    out: np.ndarray, a: np.ndarray, wj: float, dst: int, src: int, m: int
) -> None:
    """``out[dst + i] += wj * a[src + i]`` for ``i < m`` (one product, one sum each)."""
    o = out[dst : dst + m]
    v = a[src : src + m]
    for i in range(m):
        o[i] = o[i] + wj * v[i]


@njit_cached(nogil=True, inline="always")
def _grown(lo: int, hi: int, n: int, k: int, circular: bool) -> tuple[int, int]:  # pragma: no cover
    """Where a convolution by ``k`` taps along an axis of ``n`` cells can be non-zero when
    its input is zero outside ``[lo, hi)``: ``h = k // 2`` below, ``k - 1 - h`` above
    (the whole ring when circular; nothing when the input is nothing)."""
    if hi <= lo:
        return 0, 0
    if circular:
        return 0, n
    h = k // 2
    return max(0, lo - h), min(n, hi + k - 1 - h)


@njit_cached(nogil=True)
def conv3_box(  # pragma: no cover - compiled
    a: np.ndarray, w: np.ndarray, circ_t: bool, circ_y: bool, circ_x: bool, box: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`conv3` of an array that is zero outside ``box``, the same bits: the passes
    skip only the products of those zeros (a sum started at ``+0`` is unchanged by a
    zero, and is never ``-0``), so rows, slabs and runs outside the box cost nothing.

    Args:
        a: the input, zero outside ``box``.
        w: the 1D kernel, in ``a``'s dtype.
        circ_t, circ_y, circ_x: whether each axis is a whole ring (indices wrap).
        box: per axis (t, y, x) ``[lo, hi)`` holding every non-zero cell of ``a``.

    Returns:
        The convolution and a box holding every non-zero cell of it.

    Shape:
        a: ``(T, Y, X)`` C-contiguous; w: ``(K,)``; box: ``(3, 2)`` int64.
    """
    t, y, x = a.shape
    k = w.size
    h = k // 2
    t0, t1 = box[0, 0], box[0, 1]
    y0, y1 = box[1, 0], box[1, 1]
    x0, x1 = box[2, 0], box[2, 1]
    flat = a.reshape(t * y * x)
    # x: along each row of the box (a row outside it is zero)
    ex = np.zeros_like(flat)
    for kt in range(t0, t1):
        for ky in range(y0, y1):
            base = (kt * y + ky) * x
            for j in range(k):
                s = h - j  # out[p] takes a[p + s]
                if circ_x:
                    s = s % x
                    _add(ex, flat, w[j], base, base + s, x - s)
                    _add(ex, flat, w[j], base + x - s, base, s)
                else:
                    lo = max(0, -s, x0 - s)
                    hi = min(x, x - s, x1 - s)
                    if hi > lo:
                        _add(ex, flat, w[j], base + lo, base + lo + s, hi - lo)
    x0, x1 = _grown(x0, x1, x, k, circ_x)
    # y: each theta layer of the box, whole rows at a time
    ey = np.zeros_like(flat)
    for kt in range(t0, t1):
        base = kt * y * x
        for j in range(k):
            s = h - j
            if circ_y:
                s = s % y
                _add(ey, ex, w[j], base, base + s * x, (y - s) * x)
                _add(ey, ex, w[j], base + (y - s) * x, base, s * x)
            else:
                lo = max(0, -s, y0 - s)
                hi = min(y, y - s, y1 - s)
                if hi > lo:
                    _add(ey, ex, w[j], base + lo * x, base + (lo + s) * x, (hi - lo) * x)
    y0, y1 = _grown(y0, y1, y, k, circ_y)
    # theta: whole layers, from the box's layers only
    et = np.zeros_like(flat)
    layer = y * x
    for j in range(k):
        s = h - j
        if circ_t:
            s = s % t
            _add(et, ey, w[j], 0, s * layer, (t - s) * layer)
            _add(et, ey, w[j], (t - s) * layer, 0, s * layer)
        else:
            lo = max(0, -s, t0 - s)
            hi = min(t, t - s, t1 - s)
            if hi > lo:
                _add(et, ey, w[j], lo * layer, (lo + s) * layer, (hi - lo) * layer)
    t0, t1 = _grown(t0, t1, t, k, circ_t)
    out_box = np.empty((3, 2), np.int64)
    out_box[0, 0], out_box[0, 1] = t0, t1
    out_box[1, 0], out_box[1, 1] = y0, y1
    out_box[2, 0], out_box[2, 1] = x0, x1
    return et.reshape((t, y, x)), out_box


@njit_cached(nogil=True)
def conv3(  # pragma: no cover - compiled
    a: np.ndarray, w: np.ndarray, circ_t: bool, circ_y: bool, circ_x: bool
) -> np.ndarray:
    """The separable 3D convolution of ``a`` by the 1D kernel ``w`` on every axis:
    x, then y, then theta, each output cell ``out[p] = sum_j w[j] * a[p + h - j]``
    (``h = len(w) // 2``), the taps added in the order of ``j``; indices wrap on a
    circular axis, else the array is zero outside it (:func:`conv3_box` on the whole
    array).

    Shape:
        a: ``(T, Y, X)`` C-contiguous; w: ``(K,)`` of ``a``'s dtype; returns ``(T, Y, X)``.
    """
    box = np.zeros((3, 2), np.int64)
    for ax in range(3):
        box[ax, 1] = a.shape[ax]
    return conv3_box(a, w, circ_t, circ_y, circ_x, box)[0]
