"""Exact sums of absolute differences (SAD) of (template, offset) pairs, in chunks.

These kernels decide every answer of the search: the bounds and the compiled screening
only skip pairs. Each chunk holds at most :data:`~torchratslam.local_view.bounds.CHUNK_ELEMENTS`
temporary elements.
"""

from __future__ import annotations

import torch

from torchratslam.local_view.bounds import CHUNK_ELEMENTS

__all__ = ["by_offset", "rolled_sad", "window_sad"]


def by_offset(k: torch.Tensor, n_offsets: int) -> list[tuple[int, torch.Tensor]]:
    """Pair positions grouped by offset index (normal mode has a few offsets).

    Returns:
        ``(offset index, positions of its pairs in k)`` for every offset index present.

    Shape:
        k: ``(P,)``.
    """
    order = torch.argsort(k, stable=True)
    counts = torch.bincount(k, minlength=n_offsets).tolist()
    out, s = [], 0
    for kk, c in enumerate(counts):
        if c:
            out.append((kk, order[s : s + c]))
        s += c
    return out


def rolled_sad(
    data: torch.Tensor, rolled: torch.Tensor, t: torch.Tensor, k: torch.Tensor
) -> torch.Tensor:
    """Panoramic: SAD of template ``t[i]`` against the view rolled to offset ``k[i]``.

    Args:
        data: the templates.
        rolled: the view rolled to every offset, flattened
            (:func:`~torchratslam.local_view.bounds.view_summaries`' ``rolled``).
        t: template ids.
        k: offset indices.

    Shape:
        data: ``(N, Y, X)``; rolled: ``(K, Y * X)``; t, k: ``(P,)`` -> ``(P,)``.
    """
    out = torch.empty(t.numel(), dtype=data.dtype, device=t.device)
    per = max(1, CHUNK_ELEMENTS // (data.shape[1] * data.shape[2]))
    flat = data.view(data.shape[0], -1)
    for s in range(0, t.numel(), per):
        e = s + per
        rows = flat.index_select(0, t[s:e]) - rolled.index_select(0, k[s:e])
        out[s:e] = rows.abs_().sum(1)
    return out


def window_sad(
    data: torch.Tensor,
    block: torch.Tensor,
    t: torch.Tensor,
    k: torch.Tensor,
    offsets: torch.Tensor,
) -> torch.Tensor:
    """Normal mode: SAD of template ``t[i]``'s columns ``o .. o + W - 1`` (``o =
    offsets[k[i]]``) against the view's compared columns ``block``.

    Args:
        data: the templates.
        block: the view's compared columns.
        t: template ids.
        k: offset indices.
        offsets: the column offset of each offset index.

    Shape:
        data: ``(N, Y, X)``; block: ``(Y, W)``; t, k: ``(P,)``; offsets: ``(K,)``
        -> ``(P,)``.
    """
    out = torch.empty(t.numel(), dtype=data.dtype, device=t.device)
    per = max(1, CHUNK_ELEMENTS // (data.shape[1] * data.shape[2]))
    w = block.shape[1]
    for kk, sel in by_offset(k, offsets.numel()):
        o = int(offsets[kk])
        for s in range(0, sel.numel(), per):
            idx = sel[s : s + per]
            win = data.index_select(0, t.index_select(0, idx))[:, :, o : o + w]
            out[idx] = (win - block).abs_().sum(dim=(1, 2))
    return out
