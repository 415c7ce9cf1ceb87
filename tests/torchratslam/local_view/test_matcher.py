"""The matcher's exact kernel on a few pairs: the same bits as on every pair."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchratslam.local_view.matcher import TemplateMatcher


@pytest.mark.parametrize(
    ("panoramic", "y", "x", "shift", "step"),
    [(True, 5, 14, 0, 1), (True, 5, 14, 0, 3), (False, 5, 14, 4, 2), (True, 16, 64, 0, 5),
     (False, 10, 60, 25, 5), (True, 128, 130, 0, 5), (False, 128, 130, 4, 1)],
)  # fmt: skip
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_sparse_sad_is_pair_sad_bit_for_bit(panoramic, y, x, shift, step, dtype):
    """``sparse_sad`` (a few pairs, from the view alone) against ``pair_sad`` on every
    pair (the view's full summaries), and against a float64 loop; more pairs than a
    chunk holds (128 x 130 templates) take the chunked kernels."""
    rng = np.random.default_rng(shift + step)
    n = 12
    bank_np = rng.random((n, y, x))
    view_np = rng.random((y, x))
    m = TemplateMatcher(y, x, panoramic=panoramic, shift=shift, step=step)
    bank = m.make_bank(dtype=dtype, device=None)
    bank.append(torch.from_numpy(bank_np))
    view = torch.from_numpy(view_np).to(dtype)
    kk = m.n_offsets
    t_all = torch.arange(n).repeat_interleave(kk)
    k_all = torch.arange(kk).repeat(n)
    every = m.pair_sad(bank, m.view_parts(view), t_all, k_all).reshape(n, kk)
    for t, k in (
        ([3], [1]),  # one pair
        ([0, 7, 7], [2, 2, 2]),  # one offset
        ([5, 1, 5, 11], [0, kk - 1, 1, 0]),  # mixed offsets
        (list(range(n)) * 2, [i % kk for i in range(2 * n)]),  # more pairs than offsets
        (t_all.tolist(), k_all.tolist()),  # every pair: above one chunk for 128 x 130
    ):
        t_np, k_np = np.array(t, np.int64), np.array(k, np.int64)
        got = m.sparse_sad(bank, view, t_np, k_np)
        assert torch.equal(got, every[t_np, k_np])
        o = m.offsets_np[k_np]
        for i in range(len(t)):  # and the value, by a loop
            if panoramic:
                cols = (np.arange(x) + o[i]) % x
                want = np.abs(view_np - bank_np[t[i]][:, cols]).sum()
            else:
                w = x - 2 * shift
                want = np.abs(
                    view_np[:, shift : shift + w] - bank_np[t[i]][:, o[i] : o[i] + w]
                ).sum()
            assert float(got[i]) == pytest.approx(want, rel=1e-5)


def test_pooling_indices_agree_with_the_pooling_matrices():
    m = TemplateMatcher(7, 10, panoramic=True, shift=0, step=1)
    groups = [list(np.nonzero(m.group_of_row == g)[0]) for g in range(m.groups)]
    blocks = [list(np.nonzero(m.block_of_col == b)[0]) for b in range(m.blocks)]
    assert groups == [[0, 1], [2, 3], [4, 5], [6]]  # contiguous, the larger first
    assert [c for b in blocks for c in b] == list(range(10))
    assert all(len(b) in (1, 2) for b in blocks)
    assert m.roll_rows_np.shape == (10, 70)
    np.testing.assert_array_equal(m.roll_rows_np.reshape(-1), m.roll_flat.numpy())
