"""Ray casting compiled with numba (imported lazily): the nearest wall of every ray in
one pass over rays x segments, without the (rays, segments) temporaries.

The arithmetic is :func:`torchratslam.sim.render.cast_rays`'s, operation for operation
(the same products, differences, reciprocal and comparisons, no fused multiply-add),
and the first of equal nearest hits wins as ``argmin`` picks it, so distances,
segments and positions along them are the same bit for bit.

Compiled functions are cached on disk by numba (``cache=True``); the first use in a
fresh environment compiles them (a few seconds).
"""

from __future__ import annotations

import numpy as np

from ratslam_graph._jit import njit_cached


@njit_cached(nogil=True, error_model="numpy")
def nearest_hits(  # pragma: no cover - compiled
    rx: np.ndarray,
    ry: np.ndarray,
    px: np.ndarray,
    py: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    lengths: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per ray the nearest segment hit ahead of the origin.

    Args:
        rx, ry: ray directions (cos, sin). Shape: (R,).
        px, py: segments' first ends relative to the origin. Shape: (S,).
        ex, ey: segments' direction vectors (second end - first). Shape: (S,).
        lengths: segments' lengths. Shape: (S,).

    Returns:
        distance (inf where nothing is hit), segment (-1 there) and the position along
        the hit segment (0 there). Shape: (R,) each.
    """
    nr, ns = rx.shape[0], px.shape[0]
    dist = np.empty(nr)
    seg = np.empty(nr, np.int64)
    u = np.empty(nr)
    for r in range(nr):
        cx, cy = rx[r], ry[r]
        best = np.inf
        bi = 0
        bs = 0.0
        for j in range(ns):
            denom = cx * ey[j] - cy * ex[j]
            inv = 1.0 / denom
            t = (px[j] * ey[j] - py[j] * ex[j]) * inv
            s = (px[j] * cy - py[j] * cx) * inv
            if t > 1e-9 and s >= 0.0 and s <= 1.0 and t < best:
                best, bi, bs = t, j, s
        dist[r] = best
        if best < np.inf:
            seg[r] = bi
            u[r] = bs * lengths[bi]
        else:
            seg[r] = -1
            u[r] = 0.0 * lengths[0] if ns else 0.0
    return dist, seg, u
