"""The block averaging of a uint8 image compiled with numba (imported lazily): integer
pixel sums (exact in any order), then one division per template pixel, so the result is
:func:`torchratslam.local_view.preprocessing.block_means_uint8`'s numpy result bit for
bit. Compiled functions are cached on disk by numba (``cache=True``).
"""

from __future__ import annotations

import numpy as np

from ratslam_graph._jit import njit_cached


@njit_cached(nogil=True)
def block_means(  # pragma: no cover - compiled
    img: np.ndarray, y0: int, x0: int, ty: int, by: int, tx: int, bx: int, scale: float
) -> np.ndarray:
    """The mean of each ``by x bx`` block of all channels of the crop from ``(y0, x0)``:
    the block's integer sum divided by ``scale`` (``255 * channels * by * bx``).

    Shape:
        img: ``(H, W, C)`` uint8 -> ``(ty, tx)`` float64.
    """
    nc = img.shape[2]
    sums = np.zeros((ty, tx), np.int64)
    for i in range(ty):
        for r in range(y0 + i * by, y0 + (i + 1) * by):
            for j in range(tx):
                s = 0
                for c in range(x0 + j * bx, x0 + (j + 1) * bx):
                    for k in range(nc):
                        s += img[r, c, k]
                sums[i, j] += s
    out = np.empty((ty, tx))
    for i in range(ty):
        for j in range(tx):
            out[i, j] = sums[i, j] / scale
    return out
