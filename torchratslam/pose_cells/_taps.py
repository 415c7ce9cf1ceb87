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


@njit_cached(nogil=True)
def conv_axis(  # pragma: no cover - compiled
    a: np.ndarray, w: np.ndarray, outer: int, n: int, inner: int, circular: bool
) -> np.ndarray:
    """One axis of the convolution on ``a`` seen as ``(outer, n, inner)``.

    ``out[o, p, q] = sum_j w[j] * a[o, p + h - j, q]`` (``h = len(w) // 2``), the taps
    added in the order of ``j``; indices wrap when ``circular``, else the array is zero
    outside ``0 .. n - 1`` (the taps that fall outside are skipped: adding a zero
    product changes no non-negative sum).

    Shape:
        a: flat ``(outer * n * inner,)``; w: ``(K,)``; returns the same as ``a``.
    """
    out = np.zeros_like(a)
    h = w.size // 2
    for o in range(outer):
        base = o * n * inner
        for j in range(w.size):
            wj = w[j]
            s = h - j  # out[p] takes a[p + s]
            if circular:
                s = s % n
                # p in [0, n - s): k = p + s; p in [n - s, n): k = p + s - n
                _add(out, a, wj, base, base + s * inner, (n - s) * inner)
                _add(out, a, wj, base + (n - s) * inner, base, s * inner)
            else:
                lo = max(0, -s)
                hi = min(n, n - s)
                if hi > lo:
                    _add(out, a, wj, base + lo * inner, base + (lo + s) * inner, (hi - lo) * inner)
    return out


@njit_cached(nogil=True)
def conv3(  # pragma: no cover - compiled
    a: np.ndarray, w: np.ndarray, circ_t: bool, circ_y: bool, circ_x: bool
) -> np.ndarray:
    """The separable 3D convolution of ``a`` by the 1D kernel ``w`` on every axis:
    x, then y, then theta (see :func:`conv_axis`).

    Shape:
        a: ``(T, Y, X)`` C-contiguous; w: ``(K,)`` of ``a``'s dtype; returns ``(T, Y, X)``.
    """
    t, y, x = a.shape
    flat = a.reshape(t * y * x)
    flat = conv_axis(flat, w, t * y, x, 1, circ_x)
    flat = conv_axis(flat, w, t, y, x, circ_y)
    flat = conv_axis(flat, w, 1, t, y * x, circ_t)
    return flat.reshape((t, y, x))
