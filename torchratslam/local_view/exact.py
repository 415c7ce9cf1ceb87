"""Exact sums of absolute differences (SAD) of (template, offset) pairs, in chunks.

These kernels decide every answer of the search: the bounds and the compiled screening
only skip pairs. Each chunk holds at most :data:`~torchratslam.local_view.bounds.CHUNK_ELEMENTS`
temporary elements.

:func:`few_rolled_sad` and :func:`few_window_sad` evaluate the few pairs a compiled
search keeps (one chunk) from numpy arrays: the absolute differences are taken in numpy
(exactly rounded there as in torch), the sums by torch over the same contiguous rows as
:func:`rolled_sad` and :func:`window_sad`, so the bits are the same, without a dozen
torch calls on tiny tensors.
"""

from __future__ import annotations

import numpy as np
import torch

from torchratslam.local_view.bounds import CHUNK_ELEMENTS

__all__ = [
    "by_offset",
    "few_rolled_sad",
    "few_window_sad",
    "rolled_sad",
    "window_sad",
    "window_sad_at",
]


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
            (:func:`~torchratslam.local_view.bounds.view_summaries`' ``rolled``), or to
            some offsets (then ``k`` indexes its rows).
        t: template ids.
        k: offset indices.

    Shape:
        data: ``(N, Y, X)``; rolled: ``(K, Y * X)``; t, k: ``(P,)`` -> ``(P,)``.
    """
    per = max(1, CHUNK_ELEMENTS // (data.shape[1] * data.shape[2]))
    flat = data.view(data.shape[0], -1)
    if t.numel() <= per:  # one chunk
        return (flat.index_select(0, t) - rolled.index_select(0, k)).abs_().sum(1)
    out = torch.empty(t.numel(), dtype=data.dtype, device=t.device)
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
    for kk, sel in by_offset(k, offsets.numel()):
        out[sel] = window_sad_at(data, block, t.index_select(0, sel), int(offsets[kk]))
    return out


def window_sad_at(data: torch.Tensor, block: torch.Tensor, t: torch.Tensor, o: int) -> torch.Tensor:
    """Normal mode, one offset: SAD of template ``t[i]``'s columns ``o .. o + W - 1``
    against the view's compared columns ``block``.

    Shape:
        data: ``(N, Y, X)``; block: ``(Y, W)``; t: ``(P,)`` -> ``(P,)``.
    """
    per = max(1, CHUNK_ELEMENTS // (data.shape[1] * data.shape[2]))
    w = block.shape[1]
    if t.numel() <= per:  # one chunk
        return (data.index_select(0, t)[:, :, o : o + w] - block).abs_().sum(dim=(1, 2))
    out = torch.empty(t.numel(), dtype=data.dtype, device=t.device)
    for s in range(0, t.numel(), per):
        win = data.index_select(0, t[s : s + per])[:, :, o : o + w]
        out[s : s + per] = (win - block).abs_().sum(dim=(1, 2))
    return out


def few_rolled_sad(
    data: np.ndarray, view: np.ndarray, roll_rows: np.ndarray, t: np.ndarray, k: np.ndarray
) -> torch.Tensor:
    """:func:`rolled_sad` of a few pairs (one chunk), from numpy arrays, bit for bit.

    Args:
        data: the templates (rows past the bank's length are not read).
        view: the view template.
        roll_rows: the flat index of the view pixel facing each template pixel at each
            offset.
        t: template ids.
        k: offset indices.

    Shape:
        data: ``(N, Y, X)``; view: ``(Y, X)``; roll_rows: ``(K, Y * X)``; t, k:
        ``(P,)`` -> ``(P,)``.
    """
    flat = data.reshape(data.shape[0], -1)
    diff = np.abs(flat[t] - view.reshape(-1)[roll_rows[k]])  # (P, Y * X), contiguous
    return torch.from_numpy(diff).sum(1)


def few_window_sad(
    data: np.ndarray, view: np.ndarray, t: np.ndarray, o: np.ndarray, shift: int, width: int
) -> torch.Tensor:
    """:func:`window_sad` of a few pairs (one chunk), from numpy arrays, bit for bit.

    Args:
        data: the templates (rows past the bank's length are not read).
        view: the view template.
        t: template ids.
        o: the column offset of each pair.
        shift: first compared view column.
        width: compared columns.

    Shape:
        data: ``(N, Y, X)``; view: ``(Y, X)``; t, o: ``(P,)`` -> ``(P,)``.
    """
    cols = o[:, None, None] + np.arange(width)  # (P, 1, W)
    rows = np.arange(data.shape[1])[:, None]  # (Y, 1)
    win = data[t[:, None, None], rows, cols]  # (P, Y, W), contiguous
    diff = np.abs(win - view[:, shift : shift + width])
    return torch.from_numpy(diff).sum(dim=(1, 2))
