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
    w = tx * bx
    acc = np.empty(w * nc, np.int64)
    out = np.empty((ty, tx))
    for i in range(ty):
        # the block row's pixels summed column by column (one long loop per image row),
        # then each block's columns: the same integers as summing block by block
        acc[:] = 0
        for r in range(y0 + i * by, y0 + (i + 1) * by):
            if nc == 1:
                grey = img[r, x0 : x0 + w, 0]
                for q in range(w):
                    acc[q] += grey[q]
            else:
                row = img[r, x0 : x0 + w].ravel()  # a view of a C-contiguous image's row
                for q in range(w * nc):
                    acc[q] += row[q]
        for j in range(tx):
            s = 0
            for q in range(j * bx * nc, (j + 1) * bx * nc):
                s += acc[q]
            out[i, j] = s / scale
    return out
