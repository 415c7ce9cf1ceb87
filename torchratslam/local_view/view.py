"""Local view cells: a tensor template bank with batched, exact SAD matching.

The local view decides, for every camera frame, whether the scene is familiar (which
visual template, at which column offset) or new, following OpenRatSLAM's
``LocalViewMatch`` (see ``shared/reference/ratslam-algorithm.md``):

* :func:`preprocess` turns an image into a template: crop, grey, block averaging to
  ``template_x_size`` x ``template_y_size``, optional global normalisation
  (``vt_normalisation``), optional patch normalisation (``vt_patch_normalise``).
* :class:`TemplateBank` keeps every template in one preallocated tensor that grows by
  doubling, with per-template metadata (id = row, mean, creation frame) and the small
  summaries the search uses for its lower bounds.
* :class:`LocalView` compares the view with every template at every column offset by
  mean absolute difference (MAD) and learns a new template when the best error is above
  ``vt_match_threshold``. :class:`FeatureView` runs the same bank and matcher on any 1D
  or 2D feature array (laser scans, another sensor's vector), as xRatSLAM's generic
  ``Sensor`` does.

Offsets (both modes follow OpenRatSLAM):

* normal mode: the view's central ``X - 2s`` columns (``s = vt_shift_match``) are
  compared with the template's columns ``o .. o + X - 2s - 1`` for ``o = 0, step, ...,
  <= 2s``; the mean is over ``(X - 2s) * Y`` pixels and the relative angle is 0. A view
  whose content moved right by ``k`` columns (``view[:, c] = template[:, c - k]``)
  matches at ``o = s - k``. As in OpenRatSLAM, the unshifted comparison ``o = s`` is
  among the offsets only when ``s`` is a multiple of ``vt_step_match``.
* panoramic mode (``vt_panoramic``): view column ``c`` is compared with template column
  ``(c + o) mod X`` for ``o = 0, step, ... < X``, the mean is over all ``X * Y``
  pixels. A view *rotated by +k columns*, ``view = torch.roll(template, -k, dims=-1)``
  (what the camera sees after turning by ``k`` columns towards increasing column
  index), matches at offset ``k``; the relative angle is ``k / X * 2 pi`` wrapped to
  ``(-pi, pi]`` (OpenRatSLAM's sign, which the pose cells add to the template's
  remembered heading).

Exactness: the search returns exactly what a brute-force loop over all templates and
offsets returns (lowest error; ties to the lowest template id, then the lowest offset).
It is fast because whole templates, then single (template, offset) pairs, are skipped
when a cheap lower bound of their error already exceeds the best error found; bounds
are never used to decide a match, only to skip work that cannot change the answer.
Unlike OpenRatSLAM, templates are not skipped by ``|mean difference| >
vt_match_threshold``: that rule is exact in panoramic mode but not in normal mode (the
compared columns are a window, whose mean differs from the template's). ``match()``
always reports the true minimum error; :meth:`LocalView.process` stops as soon as every
candidate is provably above ``vt_match_threshold``, so for a new template its
``ViewMatch.error`` is a lower bound (> threshold) of the best error unless
``exact_errors=True``. The decision is the brute-force one either way.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any, cast

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from torchratslam.config import LocalViewParams
from ratslam_graph.errors import ConfigError, InputError, MapFormatError
from torchratslam.messages import Frame, ViewMatch
from torchratslam.registry import LOCAL_VIEWS

__all__ = [
    "FeatureView",
    "LocalView",
    "TemplateBank",
    "TemplateMatcher",
    "preprocess",
]

STATE_VERSION = 1
# Elements per chunk of the exact and bound computations (bounds the temporary memory).
CHUNK_ELEMENTS = 1 << 19
# Groups of rows whose column sums give the matcher's lower bounds.
GROUPS = 4
# Blocks of columns of the coarse profile bound.
BLOCKS = 8


# --------------------------------------------------------------------------- input


def _as_tensor(array: Any, what: str) -> torch.Tensor:
    """A numpy array or tensor as a CPU/any-device tensor (no copy when possible)."""
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


def _check_finite(x: torch.Tensor, what: str) -> None:
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


def preprocess(
    image: Any,
    params: LocalViewParams,
    *,
    dtype: torch.dtype = torch.float32,
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
    img = _as_tensor(image, "image")
    if img.ndim == 3 and img.shape[-1] in (1, 3):
        channels = img.shape[-1]
    elif img.ndim == 2:
        channels = 1
    else:
        raise InputError(
            f"image: expected (H, W) grey or (H, W, 3) colour, got shape {tuple(img.shape)}"
        )
    if img.numel() == 0:
        raise InputError(f"image: empty image of shape {tuple(img.shape)}")
    is_uint8 = img.dtype == torch.uint8
    if not is_uint8 and not img.is_floating_point():
        raise InputError(
            f"image: dtype {img.dtype} is not supported; pass uint8 or float in [0, 1]"
        )
    _check_finite(img, "image")
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
        v = _patch_normalise(v, params.vt_patch_normalise, params.vt_min_patch_normalisation_std)
    return v.to(dtype)


def _patch_normalise(v: torch.Tensor, r: int, min_std: float) -> torch.Tensor:
    """Local contrast normalisation over (2r+1)^2 patches with replicated borders."""
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


# ---------------------------------------------------------------------------- bank


class TemplateBank:
    """All templates in one preallocated tensor that grows by doubling.

    Row ``i`` holds template id ``i``. Per template the bank also keeps its mean, its
    creation frame and any small summaries a matcher asks for (computed once, when the
    template is added; see :meth:`TemplateMatcher.make_bank`).

    Args:
        y_size: template height (rows).
        x_size: template width (columns).
        summaries: function computing the summaries of a batch ``(K, Y, X)`` of templates.
        summary_shapes: name -> per-template shape of each summary.
        capacity: initial number of rows.
        dtype: template dtype.
        device: template device.
    """

    # Allocated by _alloc (setattr): the rows, their means and the matcher's summaries.
    _data: torch.Tensor
    _means: torch.Tensor
    _gsort: torch.Tensor
    _pool: torch.Tensor
    _cols: torch.Tensor
    _pairs: torch.Tensor

    def __init__(
        self,
        y_size: int,
        x_size: int,
        *,
        summaries: Callable[[torch.Tensor], dict[str, torch.Tensor]] | None = None,
        summary_shapes: Mapping[str, tuple[int, ...]] | None = None,
        capacity: int = 64,
        dtype: torch.dtype = torch.float32,
        device: torch.device | str | None = None,
    ) -> None:
        if y_size <= 0 or x_size <= 0:
            raise ConfigError(f"template size must be positive, got {x_size}x{y_size}")
        self.y_size, self.x_size = int(y_size), int(x_size)
        self._summarise = summaries
        self._summary_shapes = dict(summary_shapes or {})
        self.dtype, self.device = dtype, torch.device(device) if device is not None else None
        self._n = 0
        self._capacity = 0
        self._alloc(max(1, int(capacity)))

    def _shapes(self) -> dict[str, tuple[int, ...]]:
        return {"data": (self.y_size, self.x_size), "means": (), **self._summary_shapes}

    def _alloc(self, capacity: int) -> None:
        for name, shape in self._shapes().items():
            tensor = torch.zeros(capacity, *shape, dtype=self.dtype, device=self.device)
            old = getattr(self, "_" + name, None)
            if old is not None:
                tensor[: self._n] = old[: self._n]
            setattr(self, "_" + name, tensor)
        frames = torch.full((capacity,), -1, dtype=torch.int64, device=self.device)
        old = getattr(self, "_frames", None)
        if old is not None:
            frames[: self._n] = old[: self._n]
        self._frames = frames
        self._capacity = capacity

    @property
    def capacity(self) -> int:
        """Rows allocated (grows by doubling)."""
        return self._capacity

    def __len__(self) -> int:
        return self._n

    @property
    def data(self) -> torch.Tensor:
        """The templates, shape ``(N, Y, X)`` (a view; do not modify)."""
        return self._data[: self._n]

    @property
    def means(self) -> torch.Tensor:
        """Mean of each template, shape ``(N,)``."""
        return self._means[: self._n]

    @property
    def frames(self) -> torch.Tensor:
        """Frame at which each template was created (-1 if unknown), shape ``(N,)``."""
        return self._frames[: self._n]

    @property
    def ids(self) -> torch.Tensor:
        """Template ids, shape ``(N,)`` (the row numbers)."""
        return torch.arange(self._n, device=self.device)

    def bytes_per_template(self) -> int:
        """Memory per stored template: data, summaries and metadata."""
        floats = sum(math.prod(shape) for shape in self._shapes().values())
        return floats * (torch.finfo(self.dtype).bits // 8) + 8

    def append(self, templates: torch.Tensor, frames: torch.Tensor | int | None = None) -> range:
        """Append templates; returns their ids.

        Args:
            templates: the templates.
            frames: creation frame of each (or one for all); -1 if None.

        Shape:
            templates: ``(K, Y, X)`` or ``(Y, X)``.
        """
        t = torch.as_tensor(templates, dtype=self.dtype, device=self.device)
        if t.ndim == 2:
            t = t[None]
        if t.ndim != 3 or tuple(t.shape[1:]) != (self.y_size, self.x_size):
            raise InputError(
                f"templates of shape {tuple(t.shape)} do not fit a bank of {self.x_size}x"
                f"{self.y_size} templates (expected (K, {self.y_size}, {self.x_size}))"
            )
        _check_finite(t, "templates")
        k = t.shape[0]
        if self._n + k > self._capacity:
            cap = self._capacity
            while cap < self._n + k:
                cap *= 2
            self._alloc(cap)
        sl = slice(self._n, self._n + k)
        self._data[sl] = t
        self._means[sl] = t.mean(dim=(1, 2))
        if self._summarise is not None:
            for name, value in self._summarise(t).items():
                getattr(self, "_" + name)[sl] = value
        if frames is None:
            frames = -1
        self._frames[sl] = torch.as_tensor(frames, dtype=torch.int64, device=self.device)
        self._n += k
        return range(self._n - k, self._n)


# ------------------------------------------------------------------------- matcher
def _check_dtype(dtype: torch.dtype) -> None:
    if dtype not in (torch.float32, torch.float64):
        raise ConfigError(f"dtype must be torch.float32 or torch.float64, got {dtype}")


class TemplateMatcher:
    """Exact best (template, offset) by mean absolute difference, with exact pruning.

    The search is a cascade of lower bounds of a pair's sum of absolute differences
    (SAD), each cheaper than the next level: a template or a pair is skipped only when
    its bound exceeds the best SAD already found (plus a rounding margin), so the answer
    equals a brute-force loop's. With ``G = min(4, Y)`` groups of rows, the triangle
    inequality gives (successive elimination, as in block matching):

    * panoramic, per template (valid at every offset): the L1 distance between the
      view's and the template's group column sums, each sorted along the columns
      (sorting gives the least L1 over all column permutations, circular shifts
      included);
    * per (template, offset): the L1 distance between the compared pixels summed over
      the G row groups and ``B = min(8, W)`` blocks of columns (the templates' pooled
      sums are computed once, when they are added: at every offset in normal mode).

    Exact errors are then evaluated for the surviving pairs in increasing order of their
    bound, in chunks that grow geometrically, stopping when the next bound exceeds the
    best error.

    Args:
        y_size: template rows.
        x_size: template columns.
        panoramic: circular matching over all offsets (``vt_panoramic``).
        shift: ``vt_shift_match`` (normal mode).
        step: ``vt_step_match``.
        device: device of the index tensors.
    """

    def __init__(
        self,
        y_size: int,
        x_size: int,
        *,
        panoramic: bool,
        shift: int,
        step: int,
        device: torch.device | str | None = None,
    ) -> None:
        self.y_size, self.x_size = y_size, x_size
        self.groups = min(GROUPS, y_size)
        self.panoramic, self.shift, self.step = bool(panoramic), int(shift), int(step)
        if step <= 0:
            raise ConfigError(f"vt_step_match must be positive, got {step}")
        if self.panoramic:
            self.width = x_size
            offs = torch.arange(0, x_size, step)
        else:
            self.width = x_size - 2 * shift
            if self.width <= 0:
                raise ConfigError(
                    f"template_x_size {x_size} must exceed 2 * vt_shift_match = {2 * shift} in "
                    "normal (non-panoramic) mode; lower vt_shift_match or widen the template"
                )
            offs = torch.arange(0, 2 * shift + 1, step)
        self.offsets = offs.to(device)
        self._offsets_np = offs.numpy().astype(np.int64)
        self.n_offsets = int(offs.numel())
        # the last stage by compiled early-exit sums on the CPU (False: torch chunks)
        self.compiled = True
        self.npix = y_size * self.width
        # panoramic: the view rolled so that its column c - o faces template column c
        cols = torch.arange(x_size)
        roll = (cols[None, :] - offs[:, None]) % x_size  # (K, X): view column facing c
        self._roll_flat = (
            (torch.arange(y_size)[None, :, None] * x_size + roll[:, None, :]).reshape(-1).to(device)
        )
        self.blocks = nb = min(BLOCKS, self.width)
        # 0/1 matrices: row groups (G, Y); column blocks of the compared width (W, B)
        groups = torch.zeros(self.groups, y_size, dtype=torch.float64)
        for i, rows in enumerate(torch.tensor_split(torch.arange(y_size), self.groups)):
            groups[i, rows] = 1
        blocks = torch.zeros(self.width, nb, dtype=torch.float64)
        for j, c in enumerate(torch.tensor_split(torch.arange(self.width), nb)):
            blocks[c, j] = 1
        if self.panoramic:
            # (X, K*B): view column c' lands in block j of offset k
            shifted = blocks[(cols[None, :] + offs[:, None]) % x_size]  # (K, X, B)
        else:
            # (X, K*B): template column c lies in block j of offset k's window
            shifted = torch.zeros(self.n_offsets, x_size, nb, dtype=torch.float64)
            for k, o in enumerate(offs.tolist()):
                shifted[k, o : o + self.width] = blocks
        # the compiled search's pair bound: sums of adjacent column pairs starting at even
        # and at odd columns; block j of offset o's window is pair o // 2 + j of phase o % 2
        self.pair_blocks = self.width // 2
        self.half = x_size // 2
        self._mats = {
            "groups": groups.to(device),
            "blocks": blocks.to(device),
            "shifted": shifted.permute(1, 0, 2).reshape(x_size, -1).to(device),
        }
        self._mat_cache: dict[tuple[str, torch.dtype], torch.Tensor] = {}

    def make_bank(self, *, dtype: torch.dtype, device: torch.device | str | None) -> TemplateBank:
        """An empty bank with the summaries this matcher's bounds need."""
        g, nb, x = self.groups, self.blocks, self.x_size
        if self.panoramic:
            shapes = {"gsort": (g * x,), "pool": (g * nb,)}
        else:
            shapes = {
                "pool": (self.n_offsets * g * nb,),
                "cols": (x,),
                "pairs": (2 * self.half,),
            }
        return TemplateBank(
            self.y_size,
            x,
            summaries=self.summarise,
            summary_shapes=shapes,
            dtype=dtype,
            device=device,
        )

    def summarise(self, t: torch.Tensor) -> dict[str, torch.Tensor]:
        """Per-template summaries for the bounds.

        Panoramic: the column sums of ``G`` row groups sorted along the columns
        (``gsort``) and summed over ``B`` blocks of columns (``pool``). Normal mode: the
        compared window of every offset, pooled the same way (``pool``, ``(K, G, B)``).

        Shape:
            t: ``(M, Y, X)``.
        """
        m, g, nb = t.shape[0], self.groups, self.blocks
        gsum = self._mat("groups", t.dtype) @ t  # (M, G, X)
        if self.panoramic:
            return {
                "gsort": gsum.sort(-1).values.reshape(m, -1),
                "pool": (gsum @ self._mat("blocks", t.dtype)).reshape(m, -1),
            }
        pool = (gsum @ self._mat("shifted", t.dtype)).view(m, g, self.n_offsets, nb)
        # (M, K, G, B); and for the compiled search's bounds, the column sums (M, X) and
        # the sums of adjacent column pairs from even and from odd columns (M, 2 * (X // 2))
        cols = t.sum(1)
        return {
            "pool": pool.permute(0, 2, 1, 3).reshape(m, -1),
            "cols": cols,
            "pairs": self._pair_sums(cols),
        }

    def _pair_sums(self, cols: torch.Tensor) -> torch.Tensor:
        """``[c0 + c1, c2 + c3, ...]`` then ``[c1 + c2, c3 + c4, ...]`` (zero-padded) of
        column sums ``(M, X)``: ``(M, 2 * (X // 2))``."""
        h, x = self.half, self.x_size
        out = torch.zeros(cols.shape[0], 2 * h, dtype=cols.dtype, device=cols.device)
        out[:, :h] = cols[:, 0 : 2 * h : 2] + cols[:, 1 : 2 * h : 2]
        odd = (x - 1) // 2
        out[:, h : h + odd] = cols[:, 1 : 2 * odd : 2] + cols[:, 2 : 2 * odd + 1 : 2]
        return out

    def _mat(self, name: str, dtype: torch.dtype) -> torch.Tensor:
        key = (name, dtype)
        if key not in self._mat_cache:
            self._mat_cache[key] = self._mats[name].to(dtype)
        return self._mat_cache[key]

    # ----------------------------------------------------------------- view side

    def _view_parts(self, view: torch.Tensor) -> dict[str, torch.Tensor]:
        """Per-frame view summaries used by the bounds and the exact kernel."""
        g, nb, kk = self.groups, self.blocks, self.n_offsets
        groups = self._mat("groups", view.dtype)
        if self.panoramic:
            gsum = groups @ view  # (G, X)
            pool = (gsum @ self._mat("shifted", view.dtype)).view(g, kk, nb)
            return {
                "rolled": view.reshape(-1).index_select(0, self._roll_flat).view(kk, -1),
                "gsort": gsum.sort(-1).values.reshape(-1),
                "pool": pool.permute(1, 0, 2).reshape(kk, -1),  # (K, G*B)
            }
        block = view[:, self.shift : self.shift + self.width].contiguous()
        return {"block": block, "pool": groups @ block @ self._mat("blocks", view.dtype)}

    # -------------------------------------------------------------- exact errors

    def _by_offset(self, k: torch.Tensor) -> list[tuple[int, torch.Tensor]]:
        """Pairs grouped by offset index (normal mode has a few offsets)."""
        order = torch.argsort(k, stable=True)
        counts = torch.bincount(k, minlength=self.n_offsets).tolist()
        out, s = [], 0
        for kk, c in enumerate(counts):
            if c:
                out.append((kk, order[s : s + c]))
            s += c
        return out

    def pair_sad(
        self, bank: TemplateBank, parts: dict, t: torch.Tensor, k: torch.Tensor
    ) -> torch.Tensor:
        """Exact sums of absolute differences of (template ``t``, offset index ``k``) pairs.

        Shape:
            t, k: ``(P,)`` -> ``(P,)``.
        """
        out = torch.empty(t.numel(), dtype=bank.dtype, device=t.device)
        if t.numel() == 0:
            return out
        per = max(1, CHUNK_ELEMENTS // (self.y_size * self.x_size))
        if self.panoramic:
            flat = bank._data.view(bank.capacity, -1)
            rolled = parts["rolled"]
            for s in range(0, t.numel(), per):
                e = s + per
                rows = flat.index_select(0, t[s:e]) - rolled.index_select(0, k[s:e])
                out[s:e] = rows.abs_().sum(1)
            return out
        block, w = parts["block"], self.width
        for kk, sel in self._by_offset(k):
            o = int(self.offsets[kk])
            for s in range(0, sel.numel(), per):
                idx = sel[s : s + per]
                win = bank._data.index_select(0, t.index_select(0, idx))[:, :, o : o + w]
                out[idx] = (win - block).abs_().sum(dim=(1, 2))
        return out

    def errors(
        self, bank: TemplateBank, view: torch.Tensor, ids: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Exact mean absolute error of every selected template at every offset.

        Args:
            bank: the templates.
            view: the view template.
            ids: template ids (default: all).

        Returns:
            Errors, shape ``(M, K)`` with ``K = len(offsets)``.

        Shape:
            view: ``(Y, X)``; ids: ``(M,)``.
        """
        if ids is None:
            ids = torch.arange(len(bank), device=view.device)
        m, kk = ids.numel(), self.n_offsets
        t = ids.repeat_interleave(kk)
        k = torch.arange(kk, device=view.device).repeat(m)
        sad = self.pair_sad(bank, self._view_parts(view), t, k)
        return (sad / self.npix).reshape(m, kk)

    # -------------------------------------------------------------- lower bounds

    def template_bound(self, bank: TemplateBank, parts: dict) -> torch.Tensor:
        """Panoramic: lower bound of every template's SAD at any offset, ``(N,)``."""
        n = len(bank)
        out = torch.empty(n, dtype=bank.dtype, device=bank._data.device)
        gsort = bank._gsort.view(bank.capacity, -1)
        vs = parts["gsort"]
        per = max(1, CHUNK_ELEMENTS // vs.numel())
        for s in range(0, n, per):
            e = min(s + per, n)
            out[s:e] = (gsort[s:e] - vs).abs_().sum(1)
        return out

    def coarse_bound(
        self, bank: TemplateBank, parts: dict, ids: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Block-pooled group-profile bound of the templates ``ids`` at every offset.

        Returns:
            Shape ``(M, K)``, in SAD units (``M = N`` when ``ids`` is None: all).

        Shape:
            ids: ``(M,)``.
        """
        kk = self.n_offsets
        m = len(bank) if ids is None else ids.numel()
        out = torch.empty(m, kk, dtype=bank.dtype, device=bank._data.device)
        pool = parts["pool"]

        def rows(s: int, e: int) -> torch.Tensor:
            if ids is None:
                return bank._pool[s:e]
            return bank._pool.index_select(0, ids[s:e])

        if self.panoramic:  # template pooled once, view pooled at every offset
            per = max(1, CHUNK_ELEMENTS // pool.numel())
            for s in range(0, m, per):
                e = min(s + per, m)
                out[s:e] = (rows(s, e)[:, None, :] - pool[None]).abs_().sum(-1)
            return out
        tiled = pool.reshape(-1).repeat(kk)  # templates are pooled at every offset
        per = max(1, CHUNK_ELEMENTS // tiled.numel())
        for s in range(0, m, per):
            e = min(s + per, m)
            out[s:e] = (rows(s, e) - tiled).abs_().view(-1, kk, pool.numel()).sum(-1)
        return out

    # -------------------------------------------------------------------- search

    def search(
        self,
        bank: TemplateBank,
        view: torch.Tensor,
        *,
        hint: int = -1,
        prune: bool = True,
        threshold: float | None = None,
    ) -> tuple[int, int, float]:
        """The exact best (template id, offset, mean error); ``(-1, 0, inf)`` if empty.

        Args:
            bank: the templates.
            view: the view template.
            hint: a template id likely to match well (the current one); only speeds up.
            prune: skip work with the lower bounds (False: evaluate every pair).
            threshold: when given, the result is exact whenever the best mean error is at
                most ``threshold``; otherwise ``(-1, 0, e)`` is returned, ``e`` a lower
                bound of the best error with ``e > threshold`` (much faster for novel
                views).

        Shape:
            view: ``(Y, X)``.
        """
        n = len(bank)
        if n == 0:
            return -1, 0, math.inf
        kk = self.n_offsets
        dev = view.device
        if not prune:
            err = self.errors(bank, view).reshape(-1)
            i = int(torch.argmin(err))  # the first minimum: lowest id, then lowest offset
            best_err = float(err[i])
            if threshold is not None and best_err > threshold:
                return -1, 0, best_err
            return i // kk, int(self.offsets[i % kk]), best_err
        parts = self._view_parts(view)
        # bounds and exact SADs are rounded differently: never prune within this margin
        margin = (1e-5 if view.dtype != torch.float64 else 1e-11) * self.npix
        cap = math.inf if threshold is None else threshold * self.npix
        best = (math.inf, n, kk)  # (SAD, template id, offset index), lexicographic
        pruned = math.inf  # least bound of everything skipped

        def cut() -> float:
            return min(best[0], cap) + margin

        def evaluate(t: torch.Tensor, k: torch.Tensor) -> None:
            nonlocal best
            if t.numel():
                sad = self.pair_sad(bank, parts, t, k)
                m = sad.min()
                key = int(torch.where(sad == m, t * kk + k, torch.full_like(t, n * kk)).min())
                best = min(best, (float(m), key // kk, key % kk))

        def keep(bound: torch.Tensor) -> torch.Tensor:
            nonlocal pruned
            ok = bound <= cut()
            if not bool(ok.all()):
                pruned = min(pruned, float(bound.masked_fill(ok, math.inf).min()))
            return ok

        if not self.panoramic and self.compiled and bank._data.device.type == "cpu":
            # every pair through the compiled column-sum bound and early-exit sums; the
            # pairs it keeps are evaluated exactly here, so the answer is the same
            from torchratslam.local_view._sad import search_normal

            vcols = parts["block"].sum(0)
            nb = self.pair_blocks
            vpairs = vcols[0 : 2 * nb : 2] + vcols[1 : 2 * nb : 2]
            pt, pk, ps, m, best64, low = search_normal(
                bank._data.numpy(),
                bank._cols.numpy(),
                bank._pairs.numpy(),
                n,
                np.ascontiguousarray(view.numpy()),
                np.ascontiguousarray(vcols.numpy()),
                np.ascontiguousarray(vpairs.numpy()),
                self._offsets_np,
                self.width,
                self.shift,
                hint if 0 <= hint < n else -1,
                math.inf,
                cap,
                margin,
            )
            pruned = low
            sel = ps[:m] <= min(best64, cap) + margin
            evaluate(torch.from_numpy(pt[:m][sel]), torch.from_numpy(pk[:m][sel]))
            if best[0] > cap:
                return -1, 0, min(best[0], pruned) / self.npix
            return best[1], int(self.offsets[best[2]]), best[0] / self.npix
        all_k = torch.arange(kk, device=dev)
        if self.panoramic:
            tb = self.template_bound(bank, parts)  # (N,)
            seed = int(torch.argmin(tb))
        else:
            tb = None
            cb = self.coarse_bound(bank, parts)  # (N, K)
            seed = int(torch.argmin(cb)) // kk
        seeds = torch.tensor(sorted({seed, hint} if 0 <= hint < n else {seed}), device=dev)
        evaluate(seeds.repeat_interleave(kk), all_k.repeat(seeds.numel()))
        if tb is not None:
            ids = keep(tb).nonzero()[:, 0]
            cb = torch.maximum(self.coarse_bound(bank, parts, ids), tb[ids][:, None])
        else:
            ids = torch.arange(n, device=dev)
        pairs = keep(cb).nonzero()
        t, k = ids[pairs[:, 0]], pairs[:, 1]
        lb = cb[pairs[:, 0], pairs[:, 1]]
        if t.numel():
            order = torch.argsort(lb, stable=True)
            lb, t, k = lb[order], t[order], k[order]
        if t.numel() and self.compiled and bank._data.device.type == "cpu":
            # screened by the compiled early-exit sums; the pairs it keeps are evaluated
            # exactly here, so the answer is the same
            from torchratslam.local_view._sad import screen_pairs

            sad64, best64, low = screen_pairs(
                bank._data.numpy(),
                np.ascontiguousarray(view.numpy()),
                t.numpy(),
                k.numpy(),
                lb.double().numpy(),
                self._offsets_np,
                self.panoramic,
                self.width,
                self.shift,
                best[0],
                cap,
                margin,
            )
            pruned = min(pruned, low)
            keep64 = torch.from_numpy(sad64 <= min(best64, cap) + margin)
            evaluate(t[keep64], k[keep64])
        elif t.numel():
            s, size = 0, 16
            per = max(64, CHUNK_ELEMENTS // (self.y_size * self.x_size))
            while s < t.numel():
                first = float(lb[s])
                if first > cut():
                    pruned = min(pruned, first)
                    break
                e = min(s + size, t.numel())
                ok = keep(lb[s:e])
                evaluate(t[s:e][ok], k[s:e][ok])
                s, size = e, min(size * 2, per)
        if best[0] > cap:
            return -1, 0, min(best[0], pruned) / self.npix
        return best[1], int(self.offsets[best[2]]), best[0] / self.npix


# --------------------------------------------------------------------- the modules


class _TemplateView(nn.Module):
    """Shared machinery of :class:`LocalView` and :class:`FeatureView`.

    A ``torch.nn.Module`` without parameters: ``.to(device, dtype)``, ``.double()``,
    ``.float()``, ``.cpu()`` and ``.cuda()`` move the template bank and rebuild what is
    derived from it (the matcher's index tensors and per-template summaries) in the new
    dtype and device; ``state_dict()`` holds the whole state (all templates, their
    creation frames, the current and previous template, the frame counter) as CPU
    tensors and Python scalars under ``_extra_state``, so ``torch.save`` /
    ``torch.load(weights_only=True)`` and ``load_state_dict`` round-trip it.
    """

    kind = "base"

    def __init__(
        self,
        params: LocalViewParams,
        *,
        dtype: torch.dtype = torch.float32,
        device: torch.device | str | None = None,
        prune: bool = True,
        exact_errors: bool = False,
    ) -> None:
        if not isinstance(params, LocalViewParams):
            raise ConfigError(f"expected LocalViewParams, got {type(params).__name__}")
        _check_dtype(dtype)
        super().__init__()
        self.params = params
        self.dtype = dtype
        self.device = torch.device(device) if device is not None else torch.device("cpu")
        self.prune = prune
        self.exact_errors = exact_errors
        self.bank: TemplateBank | None = None
        self.matcher: TemplateMatcher | None = None
        self.current_id = -1
        self.previous_id = -1
        self.frame_counter = 0

    # -- setup
    def _setup(self, y_size: int, x_size: int) -> None:
        p = self.params
        self.matcher = TemplateMatcher(
            y_size,
            x_size,
            panoramic=p.vt_panoramic,
            shift=p.vt_shift_match,
            step=p.vt_step_match,
            device=self.device,
        )
        self.bank = self.matcher.make_bank(dtype=self.dtype, device=self.device)

    @property
    def template_shape(self) -> tuple[int, int] | None:
        """``(Y, X)`` of the templates (None before the size is known)."""
        return None if self.bank is None else (self.bank.y_size, self.bank.x_size)

    _trusted_templates = False
    """True when :meth:`_to_template` always returns finite templates of the bank's
    shape, dtype and device (then :meth:`process` skips re-checking them)."""

    def _to_template(self, observation: Any) -> torch.Tensor:
        raise NotImplementedError

    # -- bank access
    @property
    def templates(self) -> torch.Tensor:
        """All templates, shape ``(N, Y, X)``."""
        if self.bank is None:
            return torch.zeros(0, 0, 0, dtype=self.dtype, device=self.device)
        return self.bank.data

    def __len__(self) -> int:
        return 0 if self.bank is None else len(self.bank)

    @property
    def offsets(self) -> torch.Tensor:
        """The compared column offsets, shape ``(K,)``."""
        if self.matcher is None:
            raise InputError("no template size yet: process one observation first")
        return self.matcher.offsets

    def relative_rad(self, offset: int) -> float:
        """Relative view angle of a match at ``offset`` (0 in normal mode)."""
        if not self.params.vt_panoramic or self.bank is None:
            return 0.0
        rad = offset / self.bank.x_size * 2.0 * math.pi
        return rad - 2.0 * math.pi if rad > math.pi else rad

    def _check_template(self, template: Any) -> torch.Tensor:
        t = _as_tensor(template, "template").to(device=self.device, dtype=self.dtype)
        if self.bank is not None and tuple(t.shape) != self.template_shape:
            raise InputError(
                f"template of shape {tuple(t.shape)} does not match the bank's "
                f"{self.template_shape}"
            )
        _check_finite(t, "template")
        return t

    # -- matching
    def match(self, template: Any, *, threshold: float | None = None) -> tuple[int, int, float]:
        """Best (template id, offset, mean error) for a preprocessed template; no learning.

        Exactly what a brute-force loop over all templates and offsets returns (ties: the
        lowest id, then the lowest offset); ``(-1, 0, inf)`` when the bank is empty.

        Args:
            template: the view template.
            threshold: if given and the best error is above it, return ``(-1, 0, e)``
                with ``e`` a lower bound (> threshold) of the best error; faster for
                novel views. At or below the threshold the result is exact.

        Shape:
            template: ``(Y, X)``.
        """
        return self._search(self._check_template(template), threshold)

    def _search(self, t: torch.Tensor, threshold: float | None) -> tuple[int, int, float]:
        """:meth:`match` of an already checked template (``process`` made it itself)."""
        if self.bank is None or len(self.bank) == 0:
            return -1, 0, math.inf
        assert self.matcher is not None
        return self.matcher.search(
            self.bank, t, hint=self.current_id, prune=self.prune, threshold=threshold
        )

    def errors(self, template: Any, ids: Any = None) -> torch.Tensor:
        """Exact mean absolute error of the template against templates at every offset.

        Returns:
            Shape ``(M, K)``: row per template id in ``ids`` (default all), column per
            entry of :attr:`offsets`.

        Shape:
            template: ``(Y, X)``.
        """
        t = self._check_template(template)
        if self.bank is None:
            raise InputError("the template bank is empty")
        sel = None if ids is None else torch.as_tensor(ids, dtype=torch.int64, device=self.device)
        assert self.matcher is not None
        return self.matcher.errors(self.bank, t, sel)

    def process(self, observation: Any, frame_index: int | None = None) -> ViewMatch:
        """Match one observation against the bank; learn a new template if none matches.

        Args:
            observation: an image / feature array, or a :class:`~torchratslam.messages.Frame`.
            frame_index: recorded as the creation frame of a new template (default: the
                number of observations processed so far).

        Returns:
            The :class:`~torchratslam.messages.ViewMatch`.
        """
        frame = self.frame_counter if frame_index is None else int(frame_index)
        view = self._to_template(observation)
        self.frame_counter += 1
        threshold = None if self.exact_errors else self.params.vt_match_threshold
        if not self._trusted_templates:
            view = self._check_template(view)
        tid, offset, err = self._search(view, threshold)
        self.previous_id = self.current_id
        if tid >= 0 and err <= self.params.vt_match_threshold:
            self.current_id = tid
            return ViewMatch(tid, self.relative_rad(offset), err, offset, False)
        assert self.bank is not None  # _to_template set it up
        new = self.bank.append(view, frame)[0]
        self.current_id = new
        return ViewMatch(new, 0.0, err, 0, True)

    def forward(self, observation: Any, frame_index: int | None = None) -> ViewMatch:
        """``module(observation)`` is :meth:`process` (the ``nn.Module`` call)."""
        return self.process(observation, frame_index)

    def add_templates(self, templates: Any, frames: Any = None) -> range:
        """Append templates (e.g. from a merged map); returns their new ids.

        Shape:
            templates: ``(K, Y, X)``.
        """
        t = _as_tensor(templates, "templates").to(device=self.device, dtype=self.dtype)
        if t.ndim != 3:
            raise InputError(f"templates: expected (K, Y, X), got shape {tuple(t.shape)}")
        if self.bank is None:
            self._setup(t.shape[1], t.shape[2])
        assert self.bank is not None
        return self.bank.append(t, frames)

    # -- state
    def get_state(self) -> dict:
        """Everything needed to resume: numpy arrays and Python scalars only."""
        shape = self.template_shape or (0, 0)
        n = len(self)
        bank = cast(TemplateBank, self.bank)  # set up whenever n > 0
        return {
            "kind": self.kind,
            "version": STATE_VERSION,
            "template_shape": np.asarray(shape, dtype=np.int64),
            "templates": (
                bank.data.cpu().numpy().copy() if n else np.zeros((0, *shape), np.float32)
            ),
            "means": bank.means.cpu().numpy().copy() if n else np.zeros(0, np.float32),
            "frames": bank.frames.cpu().numpy().copy() if n else np.zeros(0, np.int64),
            "current_id": int(self.current_id),
            "previous_id": int(self.previous_id),
            "frame_counter": int(self.frame_counter),
            **self._extra_state(),
        }

    def set_state(self, state: dict) -> None:
        """Restore :meth:`get_state`'s output (replaces the bank)."""
        try:
            version = int(state.get("version", -1))
            templates = np.asarray(state["templates"])
            frames = np.asarray(state.get("frames", np.full(len(templates), -1)), dtype=np.int64)
            shape = tuple(
                int(s) for s in np.asarray(state.get("template_shape", templates.shape[1:]))
            )
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise MapFormatError(
                f"local view state is malformed ({exc!r}); was it saved by get_state()?"
            ) from None
        if version != STATE_VERSION:
            raise MapFormatError(
                f"local view state version {version} is not supported (expected {STATE_VERSION})"
            )
        if templates.ndim != 3 or (len(templates) and tuple(templates.shape[1:]) != shape):
            raise MapFormatError(
                f"local view state: templates of shape {templates.shape} are not (N, {shape})"
            )
        self._validate_shape(shape)
        if len(frames) != len(templates):
            raise MapFormatError("local view state: 'frames' and 'templates' differ in length")
        if not np.isfinite(templates).all():
            raise MapFormatError("local view state: templates contain NaN or infinite values")
        self.bank = None
        self.matcher = None
        if shape != (0, 0):
            self._setup(*shape)
            if len(templates):
                cast(TemplateBank, self.bank).append(
                    torch.as_tensor(templates), torch.as_tensor(frames)
                )
        self.current_id = int(state.get("current_id", -1))
        self.previous_id = int(state.get("previous_id", -1))
        self.frame_counter = int(state.get("frame_counter", 0))
        self._set_extra_state(state)

    def _extra_state(self) -> dict:
        return {}

    def _set_extra_state(self, state: dict) -> None:
        pass

    # -- torch.nn.Module behaviour
    def _apply(self, fn: Callable[[torch.Tensor], torch.Tensor], recurse: bool = True) -> Any:
        """Follow ``.to`` / ``.double`` / ``.float`` / ``.cuda``: rebuild the bank and matcher
        in the dtype and device that ``fn`` gives a floating tensor."""
        probe = fn(torch.zeros((), dtype=self.dtype, device=self.device))
        if (probe.dtype, probe.device) != (self.dtype, self.device):
            _check_dtype(probe.dtype)
            state = self.get_state()
            self.dtype, self.device = probe.dtype, probe.device
            self.set_state(state)  # the summaries and index tensors are derived again
        return super()._apply(fn, recurse)

    def get_extra_state(self) -> dict:
        """:meth:`get_state` with arrays as CPU tensors (what ``state_dict()`` stores)."""
        return {
            k: torch.from_numpy(np.ascontiguousarray(v)) if isinstance(v, np.ndarray) else v
            for k, v in self.get_state().items()
        }

    def set_extra_state(self, state: Any) -> None:
        """Restore :meth:`get_extra_state`'s output (``load_state_dict()``)."""
        if not isinstance(state, dict):
            raise MapFormatError(f"local view state_dict entry is a {type(state).__name__}")
        self.set_state(
            {k: v.numpy() if isinstance(v, torch.Tensor) else v for k, v in state.items()}
        )

    def _validate_shape(self, shape: tuple[int, ...]) -> None:
        pass

    def memory_bytes(self) -> int:
        """Bytes held by the bank (allocated capacity)."""
        if self.bank is None:
            return 0
        return self.bank.capacity * self.bank.bytes_per_template()


@LOCAL_VIEWS.register("ratslam")
class LocalView(_TemplateView):
    """RatSLAM local view cells on camera images (OpenRatSLAM's ``LocalViewMatch``).

    Args:
        params: local view parameters.
        dtype: template dtype (float32 or float64).
        device: template device.
        prune: skip work with exact lower bounds (False: evaluate every pair; same result).
        exact_errors: report the exact best error of novel views too (slower); by
            default a new template's ``ViewMatch.error`` is a lower bound (above
            ``vt_match_threshold``) of the best error, the decision being the same.

    Example:
        >>> lv = LocalView(LocalViewParams(template_x_size=8, template_y_size=4))
        >>> lv.process(np.zeros((4, 8), np.uint8)).is_new
        True
    """

    kind = "ratslam"
    _trusted_templates = True  # preprocess() checks images and yields finite templates

    def __init__(
        self,
        params: LocalViewParams,
        *,
        dtype: torch.dtype = torch.float32,
        device: torch.device | str | None = None,
        prune: bool = True,
        exact_errors: bool = False,
    ) -> None:
        super().__init__(params, dtype=dtype, device=device, prune=prune, exact_errors=exact_errors)
        self.image_shape: tuple[int, ...] | None = None  # (H, W) of the processed frames
        self._setup(params.template_y_size, params.template_x_size)

    def preprocess(self, image: Any) -> torch.Tensor:
        """:func:`preprocess` with this module's parameters, dtype and device.

        Shape:
            image: ``(H, W)`` or ``(H, W, 3)`` -> ``(Y, X)``.
        """
        return preprocess(image, self.params, dtype=self.dtype, device=self.device)

    def _to_template(self, observation: Any) -> torch.Tensor:
        if isinstance(observation, Frame):
            observation = observation.image
        shape = tuple(getattr(observation, "shape", ()))[:2]
        if self.image_shape is None:
            template = self.preprocess(observation)
            self.image_shape = shape  # recorded once the first image passed the checks
            return template
        if shape != self.image_shape:
            raise InputError(
                f"image of shape {shape} differs from the earlier frames' {self.image_shape}; "
                "one local view processes one camera (use a new LocalView for another)"
            )
        return self.preprocess(observation)

    def _extra_state(self) -> dict:
        return {"image_shape": np.asarray(self.image_shape or (), dtype=np.int64)}

    def _set_extra_state(self, state: dict) -> None:
        shape = tuple(int(v) for v in np.asarray(state.get("image_shape", ())).reshape(-1))
        self.image_shape = shape if len(shape) == 2 else None

    def _validate_shape(self, shape: tuple[int, ...]) -> None:
        want = (self.params.template_y_size, self.params.template_x_size)
        if shape != want:
            raise MapFormatError(
                f"saved templates are {shape[1]}x{shape[0]} but the configuration asks for "
                f"{want[1]}x{want[0]} (template_x_size x template_y_size); use the saved config"
            )


@LOCAL_VIEWS.register("features")
class FeatureView(_TemplateView):
    """Local view cells on any 1D or 2D feature array (a laser scan, a descriptor).

    The same bank and matcher as :class:`LocalView`, without image preprocessing: a 1D
    array of N values is a 1 x N template, a 2D array is used as is. The template size is
    fixed by the first observation. ``vt_panoramic`` makes the matching circular (a 360
    degree scan); the error is the mean absolute difference in the feature's units
    (times ``scale``), compared with ``vt_match_threshold``.

    Args:
        params: local view parameters (matching keys only; crop/size keys are unused).
        dtype: template dtype.
        device: template device.
        key: when given a :class:`~torchratslam.messages.Frame`, read ``frame.scans[key]``
            (None: ``frame.image``).
        scale: multiply features by this before matching.
        prune: skip work with exact lower bounds.
        exact_errors: report the exact best error of novel views too (slower).
    """

    kind = "features"

    def __init__(
        self,
        params: LocalViewParams,
        *,
        dtype: torch.dtype = torch.float32,
        device: torch.device | str | None = None,
        key: str | None = None,
        scale: float = 1.0,
        prune: bool = True,
        exact_errors: bool = False,
    ) -> None:
        super().__init__(params, dtype=dtype, device=device, prune=prune, exact_errors=exact_errors)
        if not math.isfinite(scale) or scale <= 0:
            raise ConfigError(f"scale must be a positive finite number, got {scale}")
        self.key, self.scale = key, float(scale)

    def _to_template(self, observation: Any) -> torch.Tensor:
        if isinstance(observation, Frame):
            if self.key is None:
                observation = observation.image
            elif self.key not in observation.scans:
                raise InputError(
                    f"frame {observation.index} has no scan {self.key!r} "
                    f"(available: {', '.join(sorted(observation.scans)) or 'none'})"
                )
            else:
                observation = observation.scans[self.key]
        x = _as_tensor(observation, "features")
        if x.numel() == 0:
            raise InputError("features: empty array")
        if x.ndim == 1:
            x = x[None]
        if x.ndim != 2:
            raise InputError(f"features: expected a 1D or 2D array, got shape {tuple(x.shape)}")
        x = x.to(device=self.device, dtype=self.dtype)
        _check_finite(x, "features")
        if self.scale != 1.0:
            x = x * self.scale
        if self.bank is None:
            self._setup(x.shape[0], x.shape[1])
        elif tuple(x.shape) != self.template_shape:
            raise InputError(
                f"features of shape {tuple(x.shape)} differ from the first observation's "
                f"{self.template_shape}; every observation must have the same size"
            )
        return x
