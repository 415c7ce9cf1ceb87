"""The template matcher: exact best (template, offset) by mean absolute difference.

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
when a cheap lower bound of their error (:mod:`~torchratslam.local_view.bounds`) already
exceeds the best error found; bounds are never used to decide a match, only to skip
work that cannot change the answer (the strategies: :mod:`~torchratslam.local_view.search`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import torch

from torchratslam.errors import ConfigError
from torchratslam.local_view import bounds
from torchratslam.local_view.bank import TemplateBank
from torchratslam.local_view.exact import few_rolled_sad, few_window_sad, rolled_sad, window_sad
from torchratslam.local_view.search import (
    SearchState,
    cascade,
    compiled_panoramic,
    compiled_windows,
    exhaustive,
)

__all__ = ["TemplateMatcher"]


class TemplateMatcher:
    """Exact best (template, offset) by mean absolute difference, with exact pruning.

    Holds what depends only on the template size and the offsets (the offsets, the
    compared width, the pooling matrices, the panoramic roll index) and calls the math
    of :mod:`~torchratslam.local_view.bounds` (summaries, lower bounds),
    :mod:`~torchratslam.local_view.exact` (exact SADs) and
    :mod:`~torchratslam.local_view.search` (the search strategies).

    The search is a cascade of lower bounds of a pair's sum of absolute differences
    (SAD), each cheaper than the next level: a template or a pair is skipped only when
    its bound exceeds the best SAD already found (plus a rounding margin), so the answer
    equals a brute-force loop's. Exact errors are then evaluated for the surviving pairs
    in increasing order of their bound, stopping when the next bound exceeds the best
    error.

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
        self.groups = min(bounds.GROUPS, y_size)
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
        self.offsets_np = offs.numpy().astype(np.int64)
        self.n_offsets = int(offs.numel())
        # one compiled call per search on the CPU (False: the torch cascade)
        self.compiled = True
        self.npix = y_size * self.width
        # panoramic: the view rolled so that its column c - o faces template column c
        cols = torch.arange(x_size)
        roll = (cols[None, :] - offs[:, None]) % x_size  # (K, X): view column facing c
        flat = (torch.arange(y_size)[None, :, None] * x_size + roll[:, None, :]).reshape(-1)
        self.roll_flat = flat.to(device)
        self.roll_rows_np = flat.numpy().reshape(self.n_offsets, -1)  # (K, Y * X)
        self.blocks = min(bounds.BLOCKS, self.width)
        blocks = bounds.column_blocks(self.width, self.blocks)
        # the compiled search's pair bound: sums of adjacent column pairs starting at even
        # and at odd columns; block j of offset o's window is pair o // 2 + j of phase o % 2
        self.pair_blocks = self.width // 2
        self.half = x_size // 2
        self._mats = {
            "groups": bounds.row_groups(y_size, self.groups).to(device),
            "blocks": blocks.to(device),
            "shifted": bounds.offset_blocks(blocks, offs, x_size, panoramic=self.panoramic).to(
                device
            ),
        }
        self._mat_cache: dict[tuple[str, torch.dtype], torch.Tensor] = {}
        # the compiled panoramic search's pooling: the group of each row, the block of
        # each template column
        self.group_of_row = self._mats["groups"].argmax(0).cpu().numpy().astype(np.int64)
        self.block_of_col = blocks.argmax(1).numpy().astype(np.int64)

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
            # normal mode: the compiled search reads no pool (the torch cascade and
            # the newest-first search do, when used)
            lazy=() if self.panoramic else ("pool",),
        )

    def _mat(self, name: str, dtype: torch.dtype) -> torch.Tensor:
        key = (name, dtype)
        if key not in self._mat_cache:
            self._mat_cache[key] = self._mats[name].to(dtype)
        return self._mat_cache[key]

    def summarise(self, t: torch.Tensor) -> Mapping[str, torch.Tensor | np.ndarray]:
        """Per-template summaries for the bounds (:func:`~.bounds.template_summaries`).

        On the CPU one compiled call computes them (numpy arrays, sums in float64:
        :func:`~torchratslam.local_view._sad.summaries_panoramic` and
        :func:`~torchratslam.local_view._sad.summaries_normal`; a few torch calls per new
        template cost more than the search); elsewhere torch does (tensors). The two
        differ in rounding only, which the search's margin covers.

        Shape:
            t: ``(M, Y, X)``.
        """
        if t.device.type == "cpu":
            return self._summarise_compiled(np.ascontiguousarray(t.detach().numpy()))
        return bounds.template_summaries(
            t,
            self._mat("groups", t.dtype),
            self._mat("blocks", t.dtype),
            self._mat("shifted", t.dtype),
            panoramic=self.panoramic,
        )

    def _summarise_compiled(self, a: np.ndarray) -> dict[str, torch.Tensor | np.ndarray]:
        from torchratslam.local_view._sad import summaries_normal, summaries_panoramic

        m, g, nb, x = a.shape[0], self.groups, self.blocks, self.x_size
        rows, cols = self.group_of_row, self.block_of_col
        if self.panoramic:
            gsort = np.empty((m, g * x), a.dtype)
            pool = np.empty((m, g * nb), a.dtype)
            summaries_panoramic(a, rows, cols, g, nb, gsort, pool)
            return {"gsort": gsort, "pool": pool}
        pool = np.empty((m, self.n_offsets * g * nb), a.dtype)
        sums = np.empty((m, x), a.dtype)
        pairs = np.empty((m, 2 * self.half), a.dtype)
        summaries_normal(a, rows, cols, self.offsets_np, g, nb, pool, sums, pairs)
        return {"pool": pool, "cols": sums, "pairs": pairs}

    def view_parts(self, view: torch.Tensor) -> dict[str, torch.Tensor]:
        """Per-frame view summaries used by the bounds and the exact kernel
        (:func:`~.bounds.view_summaries`).

        Shape:
            view: ``(Y, X)``.
        """
        return bounds.view_summaries(
            view,
            self._mat("groups", view.dtype),
            self._mat("blocks", view.dtype),
            self._mat("shifted", view.dtype),
            self.roll_flat,
            panoramic=self.panoramic,
            shift=self.shift,
            width=self.width,
        )

    # -------------------------------------------------------------- exact errors

    def pair_sad(
        self, bank: TemplateBank, parts: dict, t: torch.Tensor, k: torch.Tensor
    ) -> torch.Tensor:
        """Exact sums of absolute differences of (template ``t``, offset index ``k``) pairs.

        Shape:
            t, k: ``(P,)`` -> ``(P,)``.
        """
        if t.numel() == 0:
            return torch.empty(0, dtype=bank.dtype, device=t.device)
        if self.panoramic:
            return rolled_sad(bank.data, parts["rolled"], t, k)
        return window_sad(bank.data, parts["block"], t, k, self.offsets)

    def sparse_sad(
        self, bank: TemplateBank, view: torch.Tensor, t: np.ndarray, k: np.ndarray
    ) -> torch.Tensor:
        """:meth:`pair_sad` of the pairs a compiled search keeps, on the CPU, from the
        view alone: the same bits (:func:`~.exact.few_rolled_sad`,
        :func:`~.exact.few_window_sad`; more pairs than one chunk holds, e.g. exact
        ties, go through :func:`~.exact.rolled_sad` and :func:`~.exact.window_sad`
        with only the view rows they need).

        Shape:
            view: ``(Y, X)``; t, k: ``(P,)`` int64 -> ``(P,)``.
        """
        v = view.numpy()
        if t.size <= max(1, bounds.CHUNK_ELEMENTS // (self.y_size * self.x_size)):
            data = bank.array("data")
            if self.panoramic:
                return few_rolled_sad(data, v, self.roll_rows_np, t, k)
            return few_window_sad(data, v, t, self.offsets_np[k], self.shift, self.width)
        tt, kt = torch.from_numpy(t), torch.from_numpy(k)
        if self.panoramic:
            ku, inv = np.unique(k, return_inverse=True)
            rolled = torch.from_numpy(v.reshape(-1)[self.roll_rows_np[ku]])  # (U, Y * X)
            return rolled_sad(bank.data, rolled, tt, torch.from_numpy(inv.reshape(-1)))
        block = view[:, self.shift : self.shift + self.width].contiguous()
        return window_sad(bank.data, block, tt, kt, self.offsets)

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
        sad = self.pair_sad(bank, self.view_parts(view), t, k)
        return (sad / self.npix).reshape(m, kk)

    # -------------------------------------------------------------- lower bounds

    def template_bound(self, bank: TemplateBank, parts: dict) -> torch.Tensor:
        """Panoramic: lower bound of every template's SAD at any offset, ``(N,)``."""
        return bounds.template_bound(bank.summary("gsort"), parts["gsort"])

    def coarse_bound(
        self, bank: TemplateBank, parts: dict, ids: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Block-pooled group-profile bound of the templates ``ids`` at every offset.

        Returns:
            Shape ``(M, K)``, in SAD units (``M = N`` when ``ids`` is None: all).

        Shape:
            ids: ``(M,)``.
        """
        return bounds.coarse_bound(
            bank.summary("pool"), parts["pool"], panoramic=self.panoramic, ids=ids
        )

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

        Dispatches to a strategy of :mod:`~torchratslam.local_view.search`: every pair
        (``prune=False``), one compiled call on the CPU (the window search in normal
        mode, the panoramic cascade), or the torch bound cascade (other devices, or
        :attr:`compiled` off).

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
        if len(bank) == 0:
            return -1, 0, math.inf
        if not prune:
            return exhaustive(self, bank, view, threshold)
        state = SearchState(self, bank, view, threshold)
        if not self.compiled or not bank.on_cpu:
            cascade(state, hint)
        elif self.panoramic:
            compiled_panoramic(state, hint)
        else:
            compiled_windows(state, hint)
        return state.result()
