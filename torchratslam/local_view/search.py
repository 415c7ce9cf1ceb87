"""Search strategies of the template matcher: the exact best (template, offset) pair.

Every strategy returns what a brute-force loop over all templates and offsets returns
(lowest SAD; ties to the lowest template id, then the lowest offset index): pairs are
skipped only when a lower bound of their SAD exceeds the best SAD found so far plus a
rounding margin, and the answer is always picked by the exact torch kernel
(:meth:`TemplateMatcher.pair_sad <torchratslam.local_view.matcher.TemplateMatcher.pair_sad>`).

* :func:`exhaustive`: every pair (``prune=False``).
* :func:`compiled_windows`: normal mode on the CPU; every pair through the compiled
  column-sum bounds and early-exit sums of :mod:`~torchratslam.local_view._sad`.
* :func:`compiled_panoramic`: panoramic mode on the CPU; the view's summaries, the
  template bound, the coarse per-pair bound and the early-exit sums in one compiled
  call.
* :func:`cascade`: in torch (any device, batched): seeds (the best-bounded template
  and the hint), then the template bound (panoramic) and the coarse per-pair bound,
  then the surviving pairs in increasing order of their bound, evaluated in
  geometrically growing chunks (:func:`screen_chunks`) until the next bound exceeds
  the best.

The compiled strategies screen in float64 and return the pairs within the rounding
margin of the best; those few are evaluated by the exact kernel
(:meth:`TemplateMatcher.sparse_sad
<torchratslam.local_view.matcher.TemplateMatcher.sparse_sad>`), which picks the answer.

One strategy answers a different question: :func:`newest_first` (xRatSLAM's RecodedLV)
returns the *newest* template whose best error is at most the threshold, not the best
template; it searches from the newest template backwards and stops at the first match.

:class:`SearchState` carries the incumbent and the least bound of everything skipped
through these steps and turns them into the answer.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import torch

from torchratslam.local_view.bounds import CHUNK_ELEMENTS

if TYPE_CHECKING:
    from torchratslam.local_view.bank import TemplateBank
    from torchratslam.local_view.matcher import TemplateMatcher

__all__ = [
    "SearchState",
    "cascade",
    "compiled_panoramic",
    "compiled_windows",
    "exhaustive",
    "newest_first",
    "screen_chunks",
]


def exhaustive(
    matcher: TemplateMatcher, bank: TemplateBank, view: torch.Tensor, threshold: float | None
) -> tuple[int, int, float]:
    """Every (template, offset) pair evaluated exactly; the first minimum wins.

    Returns:
        ``(template id, offset, mean error)``; ``(-1, 0, error)`` when ``threshold`` is
        given and the best error is above it.

    Shape:
        view: ``(Y, X)``.
    """
    kk = matcher.n_offsets
    err = matcher.errors(bank, view).reshape(-1)
    i = int(torch.argmin(err))  # the first minimum: lowest id, then lowest offset
    best_err = float(err[i])
    if threshold is not None and best_err > threshold:
        return -1, 0, best_err
    return i // kk, int(matcher.offsets[i % kk]), best_err


class SearchState:
    """The incumbent of one pruned search: best SAD and pair, least skipped bound.

    Args:
        matcher: the matcher (geometry and exact kernel).
        bank: the templates (not empty).
        view: the view template.
        threshold: mean error above which the exact best is not needed (None: always).

    Shape:
        view: ``(Y, X)``.
    """

    def __init__(
        self,
        matcher: TemplateMatcher,
        bank: TemplateBank,
        view: torch.Tensor,
        threshold: float | None,
    ) -> None:
        self.matcher, self.bank, self.view = matcher, bank, view
        self.n, self.kk = len(bank), matcher.n_offsets
        self._parts: dict[str, torch.Tensor] | None = None
        # bounds and exact SADs are rounded differently: never prune within this margin
        self.margin = (1e-5 if view.dtype != torch.float64 else 1e-11) * matcher.npix
        self.cap = math.inf if threshold is None else threshold * matcher.npix
        self.best = (math.inf, self.n, self.kk)  # (SAD, template id, offset index)
        self.pruned = math.inf  # least bound of everything skipped

    @property
    def parts(self) -> dict[str, torch.Tensor]:
        """The view's summaries (:meth:`TemplateMatcher.view_parts
        <torchratslam.local_view.matcher.TemplateMatcher.view_parts>`), made on first use."""
        if self._parts is None:
            self._parts = self.matcher.view_parts(self.view)
        return self._parts

    def cut(self) -> float:
        """SADs above this cannot change the answer."""
        return min(self.best[0], self.cap) + self.margin

    def evaluate(self, t: torch.Tensor, k: torch.Tensor) -> None:
        """Exact SADs of the pairs ``(t, k)``; the least (lowest id, then offset) may
        become the incumbent.

        Shape:
            t, k: ``(P,)``.
        """
        if t.numel():
            kk = self.kk
            sad = self.matcher.pair_sad(self.bank, self.parts, t, k)
            m = sad.min()
            key = int(torch.where(sad == m, t * kk + k, torch.full_like(t, self.n * kk)).min())
            self.best = min(self.best, (float(m), key // kk, key % kk))

    def evaluate_screened(
        self, t: np.ndarray, k: np.ndarray, sad64: np.ndarray, best64: float, low: float
    ) -> None:
        """Take a compiled screen's output: the pairs whose float64 SAD is within the
        margin of the best (or of the cap) are evaluated exactly (on the CPU, from the
        view alone); ``low`` is the least bound of everything the screen skipped.

        Shape:
            t, k, sad64: ``(P,)``.
        """
        self.pruned = min(self.pruned, low)
        sel = sad64 <= min(best64, self.cap) + self.margin
        if sel.size == 1 and sel[0]:  # the usual single pair
            one = float(self.matcher.sparse_sad(self.bank, self.view, t, k)[0])
            self.best = min(self.best, (one, int(t[0]), int(k[0])))
            return
        t, k = t[sel], k[sel]
        if t.size:
            kk = self.kk
            sad = self.matcher.sparse_sad(self.bank, self.view, t, k).numpy()
            m = sad.min()
            key = int(np.where(sad == m, t * kk + k, self.n * kk).min())
            self.best = min(self.best, (float(m), key // kk, key % kk))

    def keep(self, bound: torch.Tensor) -> torch.Tensor:
        """Which bounds are within the cut; the others lower :attr:`pruned`.

        Shape:
            bound: any -> the same, bool.
        """
        ok = bound <= self.cut()
        if not bool(ok.all()):
            self.pruned = min(self.pruned, float(bound.masked_fill(ok, math.inf).min()))
        return ok

    def result(self) -> tuple[int, int, float]:
        """``(template id, offset, mean error)``, or ``(-1, 0, e)`` above the threshold
        with ``e`` a lower bound of the best mean error."""
        npix = self.matcher.npix
        if self.best[0] > self.cap:
            return -1, 0, min(self.best[0], self.pruned) / npix
        return self.best[1], int(self.matcher.offsets_np[self.best[2]]), self.best[0] / npix


def compiled_windows(state: SearchState, hint: int) -> None:
    """Normal mode on the CPU: every pair through the compiled column-sum bounds and
    early-exit sums (:func:`~torchratslam.local_view._sad.search_normal`); the pairs
    it keeps are evaluated exactly here, so the answer is the same."""
    from torchratslam.local_view._sad import search_normal

    matcher, bank, n = state.matcher, state.bank, state.n
    pt, pk, ps, m, best64, low = search_normal(
        bank.array("data"),
        bank.array("cols"),
        bank.column_major("pairs", np.float32),
        n,
        np.ascontiguousarray(state.view.numpy()),
        matcher.offsets_np,
        matcher.width,
        matcher.shift,
        hint if 0 <= hint < n else -1,
        math.inf,
        state.cap,
        state.margin,
    )
    state.evaluate_screened(pt[:m], pk[:m], ps[:m], best64, low)


def compiled_panoramic(state: SearchState, hint: int) -> None:
    """Panoramic mode on the CPU: the whole cascade in one compiled call
    (:func:`~torchratslam.local_view._sad.search_panoramic`); the pairs it keeps are
    evaluated exactly here, so the answer is the same."""
    from torchratslam.local_view._sad import search_panoramic

    matcher, bank, n = state.matcher, state.bank, state.n
    pt, pk, ps, m, best64, low = search_panoramic(
        bank.array("data"),
        bank.array("gsort"),
        bank.array("pool"),
        n,
        np.ascontiguousarray(state.view.numpy()),
        matcher.group_of_row,
        matcher.block_of_col,
        matcher.offsets_np,
        hint if 0 <= hint < n else -1,
        state.cap,
        state.margin,
    )
    state.evaluate_screened(pt[:m], pk[:m], ps[:m], best64, low)


def cascade(state: SearchState, hint: int) -> None:
    """Seeds, then the bounds, then the surviving pairs in increasing order of their
    bound (:func:`screen_chunks`), in torch."""
    t, k, lb = _candidates(state, _seed(state, hint))
    if t.numel():
        screen_chunks(state, t, k, lb)


def _seed(state: SearchState, hint: int) -> torch.Tensor:
    """Evaluate every offset of the best-bounded template and of the hint.

    Returns:
        The first bound: per template (panoramic, :meth:`TemplateMatcher.template_bound
        <torchratslam.local_view.matcher.TemplateMatcher.template_bound>`, ``(N,)``) or
        per pair (normal mode, the coarse bound, ``(N, K)``).
    """
    matcher, bank, parts, n, kk = state.matcher, state.bank, state.parts, state.n, state.kk
    dev = state.view.device
    if matcher.panoramic:
        bound = matcher.template_bound(bank, parts)  # (N,)
        seed = int(torch.argmin(bound))
    else:
        bound = matcher.coarse_bound(bank, parts)  # (N, K)
        seed = int(torch.argmin(bound)) // kk
    seeds = torch.tensor(sorted({seed, hint} if 0 <= hint < n else {seed}), device=dev)
    all_k = torch.arange(kk, device=dev)
    state.evaluate(seeds.repeat_interleave(kk), all_k.repeat(seeds.numel()))
    return bound


def _candidates(
    state: SearchState, first: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The pairs whose bounds are within the cut, in increasing order of their bound.

    Args:
        state: the search.
        first: :func:`_seed`'s bound.

    Returns:
        ``(t, k, lb)``: template ids, offset indices and bounds, each ``(P,)``.
    """
    if state.matcher.panoramic:
        ids = state.keep(first).nonzero()[:, 0]
        cb = torch.maximum(
            state.matcher.coarse_bound(state.bank, state.parts, ids), first[ids][:, None]
        )
    else:
        ids = torch.arange(state.n, device=state.view.device)
        cb = first
    pairs = state.keep(cb).nonzero()
    t, k = ids[pairs[:, 0]], pairs[:, 1]
    lb = cb[pairs[:, 0], pairs[:, 1]]
    if t.numel():
        order = torch.argsort(lb, stable=True)
        lb, t, k = lb[order], t[order], k[order]
    return t, k, lb


def screen_chunks(state: SearchState, t: torch.Tensor, k: torch.Tensor, lb: torch.Tensor) -> None:
    """Evaluate the sorted pairs exactly in chunks that grow geometrically, stopping
    when the next bound exceeds the cut.

    Shape:
        t, k, lb: ``(P,)``, sorted by ``lb``.
    """
    s, size = 0, 16
    per = max(64, CHUNK_ELEMENTS // (state.matcher.y_size * state.matcher.x_size))
    while s < t.numel():
        first = float(lb[s])
        if first > state.cut():
            state.pruned = min(state.pruned, first)
            break
        e = min(s + size, t.numel())
        ok = state.keep(lb[s:e])
        state.evaluate(t[s:e][ok], k[s:e][ok])
        s, size = e, min(size * 2, per)


def newest_first(
    matcher: TemplateMatcher,
    bank: TemplateBank,
    view: torch.Tensor,
    threshold: float,
    *,
    first: int = 16,
) -> tuple[int, int, float]:
    """xRatSLAM's RecodedLV search: the newest template whose best mean error is at most
    ``threshold``, searching from the newest template backwards.

    The templates are taken newest first in chunks that grow geometrically (``first``,
    then doubling); in each chunk the pairs whose coarse lower bound is above the
    threshold are skipped and the others evaluated exactly; the search stops at the
    first chunk holding a match and returns its newest matching template, at that
    template's best offset (ties: the lowest offset). What a loop from the newest
    template down to template 0, stopping at the first whose error (minimum over the
    offsets) is at most ``threshold``, returns.

    Returns:
        ``(template id, offset, mean error)``; ``(-1, 0, e)`` when no template matches,
        ``e`` a lower bound (above ``threshold``) of the best mean error.

    Shape:
        view: ``(Y, X)``.
    """
    n, kk, npix = len(bank), matcher.n_offsets, matcher.npix
    parts = matcher.view_parts(view)
    margin = (1e-5 if view.dtype != torch.float64 else 1e-11) * npix
    cut = threshold * npix + margin
    per = max(first, CHUNK_ELEMENTS // (matcher.y_size * matcher.x_size * kk))
    low = math.inf  # least mean error (or bound of a skipped pair) seen
    hi, size = n, first
    while hi > 0:
        lo = max(0, hi - size)
        ids = torch.arange(lo, hi, device=view.device)
        bound = matcher.coarse_bound(bank, parts, ids)  # (M, K)
        ok = bound <= cut
        if not bool(ok.all()):
            low = min(low, float(bound.masked_fill(ok, math.inf).min()) / npix)
        pairs = ok.nonzero()
        err = torch.full((hi - lo, kk), math.inf, dtype=view.dtype, device=view.device)
        if pairs.numel():
            sad = matcher.pair_sad(bank, parts, ids[pairs[:, 0]], pairs[:, 1])
            err[pairs[:, 0], pairs[:, 1]] = sad / npix
        per_t, k_best = err.min(1)  # the first minimum: the lowest offset
        hit = (per_t <= threshold).nonzero()
        if hit.numel():
            j = int(hit[-1, 0])  # the newest match of the chunk
            return lo + j, int(matcher.offsets[int(k_best[j])]), float(per_t[j])
        low = min(low, float(per_t.min()))
        hi, size = lo, min(size * 2, per)
    return -1, 0, low
