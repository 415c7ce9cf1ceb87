"""The compiled block averaging against numpy's integer sums and torch's float64 path."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchratslam.config import LocalViewParams
from torchratslam.local_view.preprocessing import block_means_uint8, preprocess


def _numpy_means(img, y0, x0, ty, by, tx, bx):
    crop = img[y0 : y0 + ty * by, x0 : x0 + tx * bx].astype(np.int64)
    channels = crop.shape[2] if crop.ndim == 3 else 1
    sums = crop.reshape(ty, by, tx, bx, -1).sum(axis=(1, 3, 4))
    return sums / (255.0 * channels * by * bx)


@pytest.mark.parametrize("shape", [(37, 53), (40, 66, 3), (24, 31, 1)])
def test_block_means_are_the_integer_sums_divided_once(shape):
    rng = np.random.default_rng(sum(shape))
    img = rng.integers(0, 256, shape, dtype=np.uint8)
    crops = [(0, 0, 5, 7, 8, 6), (3, 2, 4, 5, 7, 4), (1, 1, 1, 1, 1, 1), (0, 0, 3, 8, 10, 3)]
    for y0, x0, ty, by, tx, bx in crops:
        if y0 + ty * by > shape[0] or x0 + tx * bx > shape[1]:
            continue
        got = block_means_uint8(img, y0, x0, ty, by, tx, bx)
        want = _numpy_means(img, y0, x0, ty, by, tx, bx)
        assert got.dtype == np.float64 and got.shape == (ty, tx)
        np.testing.assert_array_equal(got, want)
    # a strided view (every other column) gives the same as its copy
    view = img[:, ::2]
    np.testing.assert_array_equal(
        block_means_uint8(view, 0, 0, 3, 4, 5, 3),
        block_means_uint8(np.ascontiguousarray(view), 0, 0, 3, 4, 5, 3),
    )


def test_preprocess_of_uint8_gives_the_torch_paths_bits():
    rng = np.random.default_rng(5)
    img = rng.integers(0, 256, (48, 96, 3), dtype=np.uint8)
    params = LocalViewParams(template_x_size=24, template_y_size=12, image_crop_x_min=3)
    fast = preprocess(img, params, dtype=torch.float64)
    slow = preprocess(torch.from_numpy(img), params, dtype=torch.float64)
    assert torch.equal(fast, slow)
