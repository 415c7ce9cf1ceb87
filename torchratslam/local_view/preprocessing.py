"""Preprocessing: a camera image or feature array turned into a view template.

:func:`preprocess` does what OpenRatSLAM's ``LocalViewMatch`` does to a frame before
matching: crop, grey, block averaging to ``template_x_size`` x ``template_y_size``,
optional global normalisation (``vt_normalisation``) and optional patch normalisation
(``vt_patch_normalise``, :func:`patch_normalise`). :func:`as_tensor` and
:func:`check_finite` are the input checks every local view shares.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from torchratslam.config import LocalViewParams
from torchratslam.errors import InputError

__all__ = ["as_tensor", "block_means_uint8", "check_finite", "patch_normalise", "preprocess"]


def as_tensor(array: Any, what: str) -> torch.Tensor:
    """A numpy array or tensor as a tensor (no copy when possible).

    Args:
        array: a tensor, a uint8 or float numpy array, or anything numpy turns into floats.
        what: the argument's name, used in error messages.

    Raises:
        InputError: None, an integer or boolean array, or something that is not an array.
    """
    if isinstance(array, torch.Tensor):
        return array
    if isinstance(array, np.ndarray):
        if array.dtype == np.uint8 or np.issubdtype(array.dtype, np.floating):
            return torch.from_numpy(np.ascontiguousarray(array))
        if array.dtype == np.bool_ or np.issubdtype(array.dtype, np.integer):
            raise InputError(
                f"{what}: integer dtype {array.dtype} is not supported; pass uint8 (0..255) "
                "or floats in [0, 1]"
            )
        raise InputError(f"{what}: unsupported dtype {array.dtype}; pass uint8 or float")
    if array is None:
        raise InputError(f"{what}: got None (a frame without an image?)")
    try:
        return torch.as_tensor(np.asarray(array, dtype=np.float64))
    except (TypeError, ValueError):
        raise InputError(
            f"{what}: expected a numpy array or tensor, got {type(array).__name__}"
        ) from None


def check_finite(x: torch.Tensor, what: str) -> None:
    """Raise :class:`InputError` if a floating tensor holds NaN or infinite values."""
    if x.is_floating_point() and not bool(torch.isfinite(x).all()):
        bad = int((~torch.isfinite(x)).sum())
        raise InputError(f"{what}: {bad} NaN or infinite value(s); clean or fill them first")


def _crop_bounds(size: int, lo: int, hi: int, axis: str) -> tuple[int, int]:
    end = size if hi == -1 else hi
    if not (0 <= lo < end <= size):
        raise InputError(
            f"crop {axis} range [{lo}, {hi}) does not fit an image of {size} pixels along {axis}; "
            f"fix image_crop_{axis}_min/_max (-1 means the image edge)"
        )
    return lo, end


_NUMPY = {torch.float32: np.float32, torch.float64: np.float64}


def _on_cpu(device: torch.device | str | None) -> bool:
    if device is None or isinstance(device, torch.device):  # no new device object
        return device is None or device.type == "cpu"
    return torch.device(device).type == "cpu"


def _channels(shape: tuple[int, ...]) -> int:
    """The image's channels (1 or 3); raises on other shapes and empty images."""
    if len(shape) == 3 and shape[-1] in (1, 3):
        channels = shape[-1]
    elif len(shape) == 2:
        channels = 1
    else:
        raise InputError(f"image: expected (H, W) grey or (H, W, 3) colour, got shape {shape}")
    if math.prod(shape) == 0:
        raise InputError(f"image: empty image of shape {shape}")
    return channels


def _blocks(img: Any, params: LocalViewParams) -> tuple[int, int, int, int, int, int]:
    """``(y0, x0, ty, by, tx, bx)``: the crop's corner, the template size and the
    averaged block's size."""
    h, w = img.shape[0], img.shape[1]
    y0, y1 = _crop_bounds(h, params.image_crop_y_min, params.image_crop_y_max, "y")
    x0, x1 = _crop_bounds(w, params.image_crop_x_min, params.image_crop_x_max, "x")
    ty, tx = params.template_y_size, params.template_x_size
    by, bx = (y1 - y0) // ty, (x1 - x0) // tx
    if by == 0 or bx == 0:
        raise InputError(
            f"template {tx}x{ty} is larger than the {x1 - x0}x{y1 - y0} crop of the "
            f"{w}x{h} image; lower template_x_size/template_y_size or widen the crop"
        )
    return y0, x0, ty, by, tx, bx


def block_means_uint8(
    img: np.ndarray, y0: int, x0: int, ty: int, by: int, tx: int, bx: int
) -> np.ndarray:
    """:func:`preprocess`'s crop, grey and block averaging of a uint8 image, in numpy.

    The pixel sums are integers (exact in any order), then one division: the float64
    block means :func:`preprocess` computes in torch, bit for bit, in one compiled call
    (:func:`torchratslam.local_view._blocks.block_means`).

    Args:
        img: the uint8 image.
        y0, x0: the crop's first row and column.
        ty, tx: template rows and columns.
        by, bx: rows and columns of each averaged block.

    Shape:
        img: ``(H, W)`` or ``(H, W, C)`` -> ``(ty, tx)`` float64.
    """
    from torchratslam.local_view._blocks import block_means

    channels = img.shape[2] if img.ndim == 3 else 1
    pixels = img.reshape(img.shape[0], img.shape[1], channels)
    return block_means(pixels, y0, x0, ty, by, tx, bx, 255.0 * channels * by * bx)


def preprocess(
    image: Any,
    params: LocalViewParams,
    *,
    dtype: torch.dtype = torch.float64,
    device: torch.device | str | None = None,
) -> torch.Tensor:
    """Turn a camera image into a view template, as OpenRatSLAM does.

    Steps: crop ``[image_crop_y_min:y_max, image_crop_x_min:x_max]`` (-1 = image edge);
    grey = the equal-weight mean of the channels for colour images (so BGR and RGB give
    the same result); block averaging, each template pixel the mean of an integer block
    of ``(crop_h // template_y_size) x (crop_w // template_x_size)`` pixels (leftover
    pixels at the right and bottom are ignored); uint8 is scaled by 1/255 (floats must
    already be in [0, 1]); then global normalisation (``vt_normalisation > 0``: scale to
    that mean, clip to [0, 1]) and patch normalisation (``vt_patch_normalise = r > 0``:
    ``clip(((v - mean) / std + 3) / 6, 0, 1)`` over the ``(2r+1)^2`` neighbourhood with
    replicated borders, 0.5 where ``std < vt_min_patch_normalisation_std`` or std is 0),
    in OpenRatSLAM's order. Computed in float64, returned in ``dtype``.

    Args:
        image: uint8 or float image, grey ``(H, W)`` / ``(H, W, 1)`` or colour ``(H, W, 3)``,
            numpy array or tensor.
        params: local view parameters.
        dtype: dtype of the result.
        device: device of the result.

    Returns:
        The template, shape ``(template_y_size, template_x_size)``, values in [0, 1].

    Shape:
        image: ``(H, W)`` or ``(H, W, C)`` with C in {1, 3} -> ``(Y, X)``.

    Raises:
        InputError: empty image, wrong shape or channels, NaN values, a crop outside the
            image, or a template larger than the crop.
    """
    if isinstance(image, np.ndarray) and image.dtype == np.uint8 and _on_cpu(device):
        _channels(image.shape)  # the checks
        means = block_means_uint8(image, *_blocks(image, params))
        if params.vt_patch_normalise <= 0 and dtype in _NUMPY:
            if params.vt_normalisation > 0:  # torch's mean, then torch's operations in numpy
                level = float(torch.from_numpy(means).mean())
                if level > 0:  # number / tensor is torch's reciprocal times the number
                    scale = (1.0 / level) * params.vt_normalisation
                    means = np.clip(means * scale, 0.0, 1.0)
            return torch.from_numpy(means.astype(_NUMPY[dtype]))  # rounded as torch rounds
        v = torch.from_numpy(means)
    else:
        img = as_tensor(image, "image")
        channels = _channels(tuple(img.shape))
        is_uint8 = img.dtype == torch.uint8
        if not is_uint8 and not img.is_floating_point():
            raise InputError(
                f"image: dtype {img.dtype} is not supported; pass uint8 or float in [0, 1]"
            )
        check_finite(img, "image")
        y0, x0, ty, by, tx, bx = _blocks(img, params)
        crop = img[y0 : y0 + ty * by, x0 : x0 + tx * bx].to(device=device, dtype=torch.float64)
        if channels > 1:
            crop = crop.sum(-1)
        elif crop.ndim == 3:
            crop = crop[..., 0]
        v = crop.reshape(ty, by, tx, bx).sum(dim=(1, 3))
        v = v / ((255.0 if is_uint8 else 1.0) * channels * by * bx)
    if params.vt_normalisation > 0:
        mean = v.mean()
        if float(mean) > 0:
            v = (v * (params.vt_normalisation / mean)).clamp(0.0, 1.0)
    if params.vt_patch_normalise > 0:
        v = patch_normalise(v, params.vt_patch_normalise, params.vt_min_patch_normalisation_std)
    return v.to(dtype)


def patch_normalise(v: torch.Tensor, r: int, min_std: float) -> torch.Tensor:
    """Local contrast normalisation over ``(2r+1)^2`` patches with replicated borders.

    Each value becomes ``clip(((v - mean) / std + 3) / 6, 0, 1)`` over its patch, or 0.5
    where ``std < min_std`` or std is 0.

    Args:
        v: the template.
        r: patch radius (``vt_patch_normalise``).
        min_std: ``vt_min_patch_normalisation_std``.

    Shape:
        v: ``(Y, X)`` -> ``(Y, X)``.
    """
    ty, tx = v.shape
    k = 2 * r + 1
    # replicate padding by index clamping (F.pad's replicate mode limits the pad width)
    rows = torch.arange(-r, ty + r, device=v.device).clamp(0, ty - 1)
    cols = torch.arange(-r, tx + r, device=v.device).clamp(0, tx - 1)
    padded = v[rows][:, cols]
    patches = F.unfold(padded[None, None], kernel_size=k)[0]  # (k*k, ty*tx)
    mean = patches.mean(0)
    std = ((patches - mean).pow(2).mean(0)).sqrt()
    flat = v.reshape(-1)
    out = (((flat - mean) / std.clamp_min(1e-300) + 3.0) / 6.0).clamp(0.0, 1.0)
    out = torch.where((std < min_std) | (std <= 1e-12), torch.full_like(out, 0.5), out)
    return out.reshape(ty, tx)
