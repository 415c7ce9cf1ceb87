"""The compiled searches: what they keep and skip, against brute-force float64 loops."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from torchratslam.local_view._sad import search_normal, search_panoramic
from torchratslam.local_view.matcher import TemplateMatcher


def _sad_loops(bank: np.ndarray, view: np.ndarray, offsets, panoramic: bool, shift: int):
    """Float64 SAD of every (template, offset) pair, one column at a time."""
    n, _, x = bank.shape
    w = x if panoramic else x - 2 * shift
    out = np.zeros((n, len(offsets)))
    for t in range(n):
        for k, o in enumerate(offsets):
            for c in range(w):
                if panoramic:  # view column c against template column c + o
                    out[t, k] += np.abs(view[:, c] - bank[t, :, (c + o) % x]).sum()
                else:
                    out[t, k] += np.abs(view[:, shift + c] - bank[t, :, o + c]).sum()
    return out


def _bank_and_views(rng: np.random.Generator, n: int, y: int, x: int):
    """Smooth templates, some near-duplicates; views: rotated or shifted templates
    plus noise, and one unrelated view."""
    a = rng.random((n, y, x))
    a = (a + np.roll(a, 1, -1) + np.roll(a, -1, -1)) / 3
    a[n // 2 :] = np.clip(a[: n - n // 2] + 1e-3 * rng.standard_normal((n - n // 2, y, x)), 0, 1)
    views = [rng.random((y, x))]
    for i in range(5):
        t = a[int(rng.integers(n))]
        views.append(np.clip(np.roll(t, 2 * i - 3, -1) + 0.02 * rng.random((y, x)), 0, 1))
    return a.astype(np.float32), [v.astype(np.float32) for v in views]


def _check_screen(sad, pt, pk, ps, m, best, pruned, cap, margin):
    """The screen's contract: the pairs kept carry their float64 SAD; the best is the
    true least SAD whenever that is within the cut; every pair skipped has a SAD of at
    least ``pruned`` up to rounding (the bounds come from float32 summaries; the margin
    covers that)."""
    kept = np.zeros(sad.shape, bool)
    kept[pt[:m], pk[:m]] = True
    np.testing.assert_allclose(ps[:m], sad[pt[:m], pk[:m]], rtol=1e-12, atol=1e-9)
    low = sad.min()
    if low <= cap:
        t, k = np.unravel_index(np.argmin(sad), sad.shape)
        assert kept[t, k] and best == pytest.approx(low, abs=1e-9)
    else:
        assert best > cap - 1e-9 or m == 0
    skipped = sad[~kept]
    if skipped.size:
        assert pruned <= skipped.min() + margin / 10
        assert pruned >= min(low, cap) - margin - 1e-9  # nothing below the answer
    # what the caller keeps for the exact kernel: the best and its near-ties only
    near = ps[:m] <= min(best, cap) + margin
    assert np.all(sad[pt[:m][near], pk[:m][near]] <= min(low, cap) + 2 * margin + 1e-9)


@pytest.mark.parametrize(("y", "x", "step"), [(6, 16, 1), (4, 13, 3), (1, 9, 2), (5, 8, 8)])
@pytest.mark.parametrize("cap", [math.inf, 0.05])
def test_panoramic_search_keeps_the_best_and_bounds_what_it_skips(y, x, step, cap):
    rng = np.random.default_rng(10 * x + y)
    n = 40
    bank_np, views = _bank_and_views(rng, n, y, x)
    m = TemplateMatcher(y, x, panoramic=True, shift=0, step=step)
    bank = m.make_bank(dtype=torch.float32, device=None)
    bank.append(torch.from_numpy(bank_np))
    margin = 1e-5 * m.npix
    for i, view in enumerate(views):
        sad = _sad_loops(bank_np.astype(np.float64), view.astype(np.float64),
                         m.offsets_np, True, 0)  # fmt: skip
        for hint in (-1, i, n - 1):
            out = search_panoramic(
                bank.array("data"), bank.array("gsort"), bank.array("pool"), n, view,
                m.group_of_row, m.block_of_col, m.offsets_np, hint, cap * m.npix, margin,
            )  # fmt: skip
            _check_screen(sad, *out, cap * m.npix, margin)


@pytest.mark.parametrize(("y", "x", "shift", "step"), [(6, 20, 4, 1), (3, 11, 3, 2), (2, 5, 2, 1)])
@pytest.mark.parametrize("cap", [math.inf, 0.05])
def test_normal_search_keeps_the_best_and_bounds_what_it_skips(y, x, shift, step, cap):
    rng = np.random.default_rng(10 * x + shift)
    n = 40
    bank_np, views = _bank_and_views(rng, n, y, x)
    m = TemplateMatcher(y, x, panoramic=False, shift=shift, step=step)
    bank = m.make_bank(dtype=torch.float32, device=None)
    bank.append(torch.from_numpy(bank_np))
    margin = 1e-5 * m.npix
    for i, view in enumerate(views):
        sad = _sad_loops(bank_np.astype(np.float64), view.astype(np.float64),
                         m.offsets_np, False, shift)  # fmt: skip
        for hint in (-1, i):
            out = search_normal(
                bank.array("data"), bank.array("cols"), bank.array("pairs"), n, view,
                m.offsets_np, m.width, m.shift, hint, math.inf, cap * m.npix, margin,
            )  # fmt: skip
            _check_screen(sad, *out, cap * m.npix, margin)


def test_panoramic_search_on_equal_templates_keeps_every_tie():
    """Every pair ties (flat templates): all are kept, so the exact kernel picks the
    lowest id and offset."""
    m = TemplateMatcher(3, 6, panoramic=True, shift=0, step=1)
    bank = m.make_bank(dtype=torch.float32, device=None)
    bank.append(torch.full((5, 3, 6), 0.25))
    view = np.full((3, 6), 0.5, np.float32)
    pt, pk, _, k, best, pruned = search_panoramic(
        bank.array("data"), bank.array("gsort"), bank.array("pool"), 5, view,
        m.group_of_row, m.block_of_col, m.offsets_np, 2, math.inf, 1e-5 * m.npix,
    )  # fmt: skip
    assert k == 5 * 6 and best == pytest.approx(0.25 * 18) and pruned == math.inf
    assert sorted(zip(pt[:k].tolist(), pk[:k].tolist())) == [
        (t, o) for t in range(5) for o in range(6)
    ]


@pytest.mark.parametrize("panoramic", [True, False])
def test_compiled_summaries_are_torchs_up_to_rounding_and_a_loops_sums(panoramic):
    from torchratslam.local_view import bounds

    rng = np.random.default_rng(11)
    y, x, shift = 9, 22, 3
    bank, _ = _bank_and_views(rng, 7, y, x)
    m = TemplateMatcher(y, x, panoramic=panoramic, shift=shift, step=1)
    t = torch.from_numpy(bank)
    got = m.summarise(t)  # CPU: the compiled summaries
    want = bounds.template_summaries(
        t.double(),
        m._mats["groups"],
        m._mats["blocks"],
        m._mats["shifted"],
        panoramic=panoramic,
    )
    assert set(got) == set(want)
    for name, value in got.items():
        assert isinstance(value, np.ndarray) and value.dtype == np.float32
        np.testing.assert_allclose(value, want[name].numpy(), rtol=1e-6, atol=1e-6)
    # a loop over rows and columns: the group sums, their sorted profile, the blocks
    g, nb, b64 = m.groups, m.blocks, bank.astype(np.float64)
    gs = np.zeros((len(bank), g, x))
    for t_i in range(len(bank)):
        for r in range(y):
            gs[t_i, m.group_of_row[r]] += b64[t_i, r]
    if panoramic:
        np.testing.assert_array_equal(
            got["gsort"], np.sort(gs, -1).reshape(len(bank), -1).astype(np.float32)
        )
        pool = np.zeros((len(bank), g, nb))
        for c in range(x):
            pool[:, :, m.block_of_col[c]] += gs[:, :, c]
        np.testing.assert_allclose(got["pool"], pool.reshape(len(bank), -1), rtol=1e-6)
    else:
        np.testing.assert_allclose(got["cols"], b64.sum(1), rtol=1e-6)
        pairs = [b64.sum(1)[:, c] + b64.sum(1)[:, c + 1] for c in range(0, x - 1, 2)]
        pairs += [b64.sum(1)[:, c] + b64.sum(1)[:, c + 1] for c in range(1, x - 1, 2)]
        np.testing.assert_allclose(got["pairs"][:, : len(pairs)], np.stack(pairs, 1), rtol=1e-6)
