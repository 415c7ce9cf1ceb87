"""Preprocessing: image -> template against pixel loops, input forms, clear errors."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchratslam.config import LocalViewParams
from torchratslam.errors import InputError
from torchratslam.local_view.preprocessing import patch_normalise, preprocess


def brute_preprocess(img: np.ndarray, p: LocalViewParams) -> np.ndarray:
    """Pixel loops: crop, grey, block average, global then patch normalisation."""
    img = img.astype(np.float64)
    scale = 255.0
    if img.ndim == 3:
        img = img.sum(-1)
        scale *= 3
    h, w = img.shape
    x1 = w if p.image_crop_x_max == -1 else p.image_crop_x_max
    y1 = h if p.image_crop_y_max == -1 else p.image_crop_y_max
    bx = (x1 - p.image_crop_x_min) // p.template_x_size
    by = (y1 - p.image_crop_y_min) // p.template_y_size
    out = np.zeros((p.template_y_size, p.template_x_size))
    for j in range(p.template_y_size):
        for i in range(p.template_x_size):
            y0 = p.image_crop_y_min + j * by
            x0 = p.image_crop_x_min + i * bx
            out[j, i] = img[y0 : y0 + by, x0 : x0 + bx].sum() / (scale * bx * by)
    if p.vt_normalisation > 0:
        out = np.clip(out * p.vt_normalisation / out.mean(), 0, 1)
    r = p.vt_patch_normalise
    if r > 0:
        ty, tx = out.shape
        src = out.copy()
        for j in range(ty):
            for i in range(tx):
                vals = [
                    src[min(max(jj, 0), ty - 1), min(max(ii, 0), tx - 1)]
                    for jj in range(j - r, j + r + 1)
                    for ii in range(i - r, i + r + 1)
                ]
                mean, std = np.mean(vals), np.std(vals)
                if std < p.vt_min_patch_normalisation_std or std == 0:
                    out[j, i] = 0.5
                else:
                    out[j, i] = min(1.0, max(0.0, ((src[j, i] - mean) / std + 3) / 6))
    return out


@pytest.mark.parametrize(
    "keys",
    [
        {"template_x_size": 7, "template_y_size": 3},
        {"template_x_size": 10, "template_y_size": 4, "image_crop_x_min": 3,
         "image_crop_x_max": 45, "image_crop_y_min": 2, "image_crop_y_max": 17},
        {"template_x_size": 9, "template_y_size": 5, "vt_normalisation": 0.4},
        {"template_x_size": 9, "template_y_size": 6, "vt_patch_normalise": 2},
        {"template_x_size": 8, "template_y_size": 5, "vt_patch_normalise": 1,
         "vt_min_patch_normalisation_std": 0.05, "vt_normalisation": 0.5},
    ],
)  # fmt: skip
@pytest.mark.parametrize("colour", [False, True])
def test_preprocess_equals_pixel_loops(keys, colour):
    rng = np.random.default_rng(len(keys))
    p = LocalViewParams(**keys)
    img = rng.integers(0, 256, (20, 50, 3) if colour else (20, 50)).astype(np.uint8)
    img[:6, :12] = 90  # a flat area for the patch normalisation's std = 0 case
    got = preprocess(img, p, dtype=torch.float64).numpy()
    assert got.shape == (p.template_y_size, p.template_x_size)
    np.testing.assert_allclose(got, brute_preprocess(img, p), atol=1e-12)
    assert got.min() >= 0 and got.max() <= 1


def test_preprocess_input_forms_agree():
    rng = np.random.default_rng(1)
    p = LocalViewParams(template_x_size=8, template_y_size=4)
    grey = rng.integers(0, 256, (16, 32)).astype(np.uint8)
    ref = preprocess(grey, p)
    assert torch.allclose(preprocess(grey.astype(np.float32) / 255, p), ref, atol=1e-6)
    assert torch.equal(preprocess(torch.from_numpy(grey), p), ref)
    assert torch.equal(preprocess(grey[..., None], p), ref)
    bgr = rng.integers(0, 256, (16, 32, 3)).astype(np.uint8)
    assert torch.equal(preprocess(bgr, p), preprocess(bgr[..., ::-1], p))  # BGR == RGB
    assert preprocess(grey, p, dtype=torch.float64).dtype == torch.float64


@pytest.mark.parametrize(
    "keys",
    [
        {"template_x_size": 7, "template_y_size": 3},
        {"template_x_size": 10, "template_y_size": 4, "image_crop_x_min": 3,
         "image_crop_x_max": 45, "image_crop_y_min": 2, "image_crop_y_max": 17},
        {"template_x_size": 50, "template_y_size": 20},
        {"template_x_size": 9, "template_y_size": 5, "vt_normalisation": 0.4},
        {"template_x_size": 8, "template_y_size": 5, "vt_patch_normalise": 1},
    ],
)  # fmt: skip
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_uint8_arrays_give_the_torch_path_bit_for_bit(keys, dtype):
    """numpy uint8 images are block-averaged in numpy: the same bits as a uint8 tensor
    (the torch path) gives, grey, one channel or colour."""
    rng = np.random.default_rng(len(keys))
    p = LocalViewParams(**keys)
    for shape in ((20, 50), (20, 50, 1), (20, 50, 3), (23, 57, 3)):
        for _ in range(20):
            img = rng.integers(0, 256, shape).astype(np.uint8)
            got = preprocess(img, p, dtype=dtype)
            want = preprocess(torch.from_numpy(img), p, dtype=dtype)
            assert got.dtype == dtype and torch.equal(got, want)


@pytest.mark.parametrize(
    ("image", "keys", "pattern"),
    [
        (np.zeros((0, 10), np.uint8), {}, "empty"),
        (np.zeros((10, 10, 4), np.uint8), {}, r"\(H, W, 3\)"),
        (np.zeros((2, 10, 10), np.uint8), {}, "shape"),
        (np.full((10, 10), np.nan, np.float32), {}, "NaN"),
        (np.zeros((10, 10), np.int32), {}, "uint8"),
        (np.zeros((10, 10), np.uint8), {"template_x_size": 11}, "larger than"),
        (np.zeros((10, 10), np.uint8), {"image_crop_x_max": 12}, "does not fit"),
        (np.zeros((10, 10), np.uint8), {"image_crop_y_min": 10}, "does not fit"),
        (None, {}, "None"),
    ],
)
def test_bad_images_are_clear_errors(image, keys, pattern):
    p = LocalViewParams(**{"template_x_size": 5, "template_y_size": 2, **keys})
    with pytest.raises(InputError, match=pattern):
        preprocess(image, p)


def test_patch_normalise_flat_patches_are_one_half_and_values_stay_in_range():
    rng = np.random.default_rng(3)
    v = torch.from_numpy(rng.random((6, 9)))
    v[:3, :4] = 0.25  # flat: std 0 in the patches inside it
    out = patch_normalise(v, 1, 0.0)
    assert out.shape == v.shape and out.dtype == v.dtype
    assert torch.all(out[1, 1:3] == 0.5)
    assert float(out.min()) >= 0 and float(out.max()) <= 1
    # min_std above every patch's std: everything is 0.5
    assert torch.all(patch_normalise(v, 1, 10.0) == 0.5)
