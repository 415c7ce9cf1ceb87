"""The bounds: every one is at most the exact SAD that a brute-force loop gives."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchratslam.local_view import bounds
from torchratslam.local_view.matcher import TemplateMatcher


def _sad_loops(bank: np.ndarray, view: np.ndarray, offsets, panoramic: bool, shift: int):
    """SAD of every (template, offset) pair, one pixel at a time."""
    n, y, x = bank.shape
    w = x if panoramic else x - 2 * shift
    out = np.zeros((n, len(offsets)))
    for t in range(n):
        for k, o in enumerate(offsets):
            for r in range(y):
                for c in range(w):
                    if panoramic:
                        out[t, k] += abs(view[r, c] - bank[t, r, (c + o) % x])
                    else:
                        out[t, k] += abs(view[r, shift + c] - bank[t, r, o + c])
    return out


@pytest.mark.parametrize(
    ("panoramic", "y", "x", "shift", "step"),
    [(True, 5, 12, 0, 1), (True, 3, 7, 0, 2), (False, 6, 14, 3, 1), (False, 2, 9, 2, 3)],
)
def test_template_and_coarse_bounds_never_exceed_the_exact_sad(panoramic, y, x, shift, step):
    rng = np.random.default_rng(x + y)
    bank_np = rng.random((20, y, x))
    view_np = rng.random((y, x))
    m = TemplateMatcher(y, x, panoramic=panoramic, shift=shift, step=step)
    bank = m.make_bank(dtype=torch.float64, device=None)
    bank.append(torch.from_numpy(bank_np))
    parts = m.view_parts(torch.from_numpy(view_np))
    sad = _sad_loops(bank_np, view_np, m.offsets.tolist(), panoramic, shift)
    t = torch.arange(20).repeat_interleave(m.n_offsets)
    exact = m.pair_sad(bank, parts, t, torch.arange(m.n_offsets).repeat(20))
    np.testing.assert_allclose(exact.numpy().reshape(20, -1), sad, atol=1e-12)
    coarse = m.coarse_bound(bank, parts).numpy()
    assert coarse.shape == sad.shape and np.all(coarse <= sad + 1e-12)
    ids = torch.tensor([3, 0, 17])
    np.testing.assert_array_equal(m.coarse_bound(bank, parts, ids).numpy(), coarse[[3, 0, 17]])
    if panoramic:
        tb = m.template_bound(bank, parts).numpy()
        assert np.all(tb <= sad.min(1) + 1e-12)


def test_pair_sums_are_adjacent_column_pairs_from_even_then_odd_columns():
    cols = torch.arange(14.0).reshape(2, 7) ** 2
    got = bounds.pair_sums(cols)
    for row in range(2):
        c = cols[row].tolist()
        want = [c[0] + c[1], c[2] + c[3], c[4] + c[5], c[1] + c[2], c[3] + c[4], c[5] + c[6]]
        assert got[row].tolist() == want


def test_pooling_matrices_partition_rows_and_columns():
    g = bounds.row_groups(7, 3)
    assert g.sum(0).tolist() == [1.0] * 7 and g.sum(1).tolist() == [3.0, 2.0, 2.0]
    b = bounds.column_blocks(10, 4)
    assert b.sum(1).tolist() == [1.0] * 10 and b.sum(0).tolist() == [3.0, 3.0, 2.0, 2.0]
    # normal mode: offset 2's window covers template columns 2 .. 11, once each
    s = bounds.offset_blocks(b, torch.tensor([0, 2]), 12, panoramic=False).view(12, 2, 4)
    assert s[:, 1].sum(1).tolist() == [0.0, 0.0] + [1.0] * 10
