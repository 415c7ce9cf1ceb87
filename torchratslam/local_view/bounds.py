"""Summaries of templates and views, and the lower bounds of their SAD built from them.

With ``G = min(4, Y)`` groups of rows and ``B = min(8, W)`` blocks of the ``W``
compared columns, the triangle inequality gives lower bounds of a (template, offset)
pair's sum of absolute differences (SAD), as in block matching's successive elimination:

* panoramic, per template (valid at every offset, :func:`template_bound`): the L1
  distance between the view's and the template's group column sums, each sorted along
  the columns (sorting gives the least L1 over all column permutations, circular shifts
  included);
* per (template, offset) (:func:`coarse_bound`): the L1 distance between the compared
  pixels summed over the ``G`` row groups and ``B`` column blocks (the templates' pooled
  sums are computed once, when they are added: at every offset in normal mode).

The 0/1 pooling matrices are built once per template size (:func:`row_groups`,
:func:`column_blocks`, :func:`offset_blocks`); the per-template summaries
(:func:`template_summaries`) are kept by the bank, the view's (:func:`view_summaries`)
are computed once per frame. Every chunked computation holds at most
:data:`CHUNK_ELEMENTS` temporary elements.
"""

from __future__ import annotations

import torch

__all__ = [
    "BLOCKS",
    "CHUNK_ELEMENTS",
    "GROUPS",
    "coarse_bound",
    "column_blocks",
    "offset_blocks",
    "pair_sums",
    "row_groups",
    "template_bound",
    "template_summaries",
    "view_summaries",
]

# Elements per chunk of the exact and bound computations (bounds the temporary memory).
CHUNK_ELEMENTS = 1 << 19
# Groups of rows whose column sums give the matcher's lower bounds.
GROUPS = 4
# Blocks of columns of the coarse profile bound.
BLOCKS = 8


# ------------------------------------------------------------------ pooling matrices


def row_groups(y_size: int, groups: int) -> torch.Tensor:
    """0/1 matrix summing ``groups`` contiguous groups of rows (float64).

    Shape:
        ``(G, Y)``.
    """
    out = torch.zeros(groups, y_size, dtype=torch.float64)
    for i, rows in enumerate(torch.tensor_split(torch.arange(y_size), groups)):
        out[i, rows] = 1
    return out


def column_blocks(width: int, blocks: int) -> torch.Tensor:
    """0/1 matrix summing ``blocks`` contiguous blocks of ``width`` columns (float64).

    Shape:
        ``(W, B)``.
    """
    out = torch.zeros(width, blocks, dtype=torch.float64)
    for j, c in enumerate(torch.tensor_split(torch.arange(width), blocks)):
        out[c, j] = 1
    return out


def offset_blocks(
    blocks: torch.Tensor, offsets: torch.Tensor, x_size: int, *, panoramic: bool
) -> torch.Tensor:
    """The column blocks of every offset's compared window, over all template columns.

    Panoramic: view column ``c'`` lands in block ``j`` of offset ``k``; normal: template
    column ``c`` lies in block ``j`` of offset ``k``'s window ``o .. o + W - 1``.

    Args:
        blocks: :func:`column_blocks` of the compared width.
        offsets: the column offsets (CPU).
        x_size: template columns.
        panoramic: circular matching.

    Shape:
        blocks: ``(W, B)``; offsets: ``(K,)`` -> ``(X, K * B)``.
    """
    width, nb = blocks.shape
    if panoramic:
        cols = torch.arange(x_size)
        shifted = blocks[(cols[None, :] + offsets[:, None]) % x_size]  # (K, X, B)
    else:
        shifted = torch.zeros(offsets.numel(), x_size, nb, dtype=torch.float64)
        for k, o in enumerate(offsets.tolist()):
            shifted[k, o : o + width] = blocks
    return shifted.permute(1, 0, 2).reshape(x_size, -1)


# ------------------------------------------------------------------------ summaries


def pair_sums(cols: torch.Tensor) -> torch.Tensor:
    """Sums of adjacent column pairs from even columns, then from odd columns.

    ``[c0 + c1, c2 + c3, ...]`` then ``[c1 + c2, c3 + c4, ...]`` (zero-padded): block
    ``j`` of offset ``o``'s window is entry ``(o % 2) * (X // 2) + o // 2 + j``.

    Shape:
        cols: ``(M, X)`` -> ``(M, 2 * (X // 2))``.
    """
    x = cols.shape[1]
    h = x // 2
    out = torch.zeros(cols.shape[0], 2 * h, dtype=cols.dtype, device=cols.device)
    out[:, :h] = cols[:, 0 : 2 * h : 2] + cols[:, 1 : 2 * h : 2]
    odd = (x - 1) // 2
    out[:, h : h + odd] = cols[:, 1 : 2 * odd : 2] + cols[:, 2 : 2 * odd + 1 : 2]
    return out


def template_summaries(
    t: torch.Tensor,
    groups: torch.Tensor,
    blocks: torch.Tensor,
    shifted: torch.Tensor,
    *,
    panoramic: bool,
) -> dict[str, torch.Tensor]:
    """Per-template summaries for the bounds.

    Panoramic: the column sums of ``G`` row groups sorted along the columns (``gsort``)
    and summed over ``B`` blocks of columns (``pool``). Normal mode: the compared window
    of every offset, pooled the same way (``pool``, ``(K, G, B)`` flattened), the column
    sums (``cols``) and their :func:`pair_sums` (``pairs``).

    Args:
        t: the templates.
        groups: :func:`row_groups`, in ``t``'s dtype.
        blocks: :func:`column_blocks`, in ``t``'s dtype.
        shifted: :func:`offset_blocks`, in ``t``'s dtype.
        panoramic: circular matching.

    Shape:
        t: ``(M, Y, X)``; groups: ``(G, Y)``; blocks: ``(W, B)``; shifted:
        ``(X, K * B)``.
    """
    m, g, nb = t.shape[0], groups.shape[0], blocks.shape[1]
    gsum = groups @ t  # (M, G, X)
    if panoramic:
        return {
            "gsort": gsum.sort(-1).values.reshape(m, -1),
            "pool": (gsum @ blocks).reshape(m, -1),
        }
    pool = (gsum @ shifted).view(m, g, shifted.shape[1] // nb, nb)
    # (M, K, G, B); and for the compiled search's bounds, the column sums (M, X) and
    # the sums of adjacent column pairs from even and from odd columns (M, 2 * (X // 2))
    cols = t.sum(1)
    return {
        "pool": pool.permute(0, 2, 1, 3).reshape(m, -1),
        "cols": cols,
        "pairs": pair_sums(cols),
    }


def view_summaries(
    view: torch.Tensor,
    groups: torch.Tensor,
    blocks: torch.Tensor,
    shifted: torch.Tensor,
    roll_flat: torch.Tensor,
    *,
    panoramic: bool,
    shift: int,
    width: int,
) -> dict[str, torch.Tensor]:
    """Per-frame view summaries used by the bounds and the exact kernel.

    Panoramic: the view rolled to every offset (``rolled``), its sorted group column
    sums (``gsort``) and its group-block sums at every offset (``pool``). Normal mode:
    the compared columns (``block``) and their group-block sums (``pool``).

    Args:
        view: the view template.
        groups: :func:`row_groups`, in the view's dtype.
        blocks: :func:`column_blocks`, in the view's dtype.
        shifted: :func:`offset_blocks`, in the view's dtype.
        roll_flat: panoramic: the flat index of the view pixel facing each template
            pixel at each offset.
        panoramic: circular matching.
        shift: first compared view column (normal mode).
        width: compared columns (normal mode).

    Shape:
        view: ``(Y, X)``; roll_flat: ``(K * Y * X,)``.
    """
    g, nb = groups.shape[0], blocks.shape[1]
    if panoramic:
        kk = shifted.shape[1] // nb
        gsum = groups @ view  # (G, X)
        pool = (gsum @ shifted).view(g, kk, nb)
        return {
            "rolled": view.reshape(-1).index_select(0, roll_flat).view(kk, -1),
            "gsort": gsum.sort(-1).values.reshape(-1),
            "pool": pool.permute(1, 0, 2).reshape(kk, -1),  # (K, G*B)
        }
    block = view[:, shift : shift + width].contiguous()
    return {"block": block, "pool": groups @ block @ blocks}


# --------------------------------------------------------------------- lower bounds


def template_bound(gsort: torch.Tensor, view_gsort: torch.Tensor) -> torch.Tensor:
    """Panoramic: a lower bound of every template's SAD at any offset.

    Args:
        gsort: the templates' sorted group column sums.
        view_gsort: the view's.

    Shape:
        gsort: ``(N, G * X)``; view_gsort: ``(G * X,)`` -> ``(N,)``.
    """
    n = gsort.shape[0]
    out = torch.empty(n, dtype=gsort.dtype, device=gsort.device)
    per = max(1, CHUNK_ELEMENTS // view_gsort.numel())
    for s in range(0, n, per):
        e = min(s + per, n)
        out[s:e] = (gsort[s:e] - view_gsort).abs_().sum(1)
    return out


def coarse_bound(
    pool: torch.Tensor,
    view_pool: torch.Tensor,
    *,
    panoramic: bool,
    ids: torch.Tensor | None = None,
) -> torch.Tensor:
    """Block-pooled group-profile bound of the templates ``ids`` at every offset.

    Args:
        pool: every template's pooled sums (normal mode: at every offset).
        view_pool: the view's pooled sums (panoramic: at every offset).
        panoramic: circular matching.
        ids: the templates to bound (None: all).

    Returns:
        Shape ``(M, K)``, in SAD units (``M = N`` when ``ids`` is None).

    Shape:
        pool: ``(N, G * B)`` panoramic, ``(N, K * G * B)`` normal; view_pool:
        ``(K, G * B)`` panoramic, ``(G, B)`` normal; ids: ``(M,)``.
    """
    m = pool.shape[0] if ids is None else ids.numel()

    def rows(s: int, e: int) -> torch.Tensor:
        if ids is None:
            return pool[s:e]
        return pool.index_select(0, ids[s:e])

    if panoramic:  # template pooled once, view pooled at every offset
        kk = view_pool.shape[0]
        out = torch.empty(m, kk, dtype=pool.dtype, device=pool.device)
        per = max(1, CHUNK_ELEMENTS // view_pool.numel())
        for s in range(0, m, per):
            e = min(s + per, m)
            out[s:e] = (rows(s, e)[:, None, :] - view_pool[None]).abs_().sum(-1)
        return out
    kk = pool.shape[1] // view_pool.numel()
    out = torch.empty(m, kk, dtype=pool.dtype, device=pool.device)
    tiled = view_pool.reshape(-1).repeat(kk)  # templates are pooled at every offset
    per = max(1, CHUNK_ELEMENTS // tiled.numel())
    for s in range(0, m, per):
        e = min(s + per, m)
        out[s:e] = (rows(s, e) - tiled).abs_().view(-1, kk, view_pool.numel()).sum(-1)
    return out
