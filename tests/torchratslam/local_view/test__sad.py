"""The compiled searches: what they keep and skip, against brute-force float64 loops."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from torchratslam.local_view._sad import (
    PAIR_BLOCK,
    _sort_into,
    pair_bounds,
    search_normal,
    search_panoramic,
)
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
                bank.array("data"), bank.array("cols"), bank.column_major("pairs", np.float32),
                n, view, m.offsets_np, m.width, m.shift, hint, math.inf, cap * m.npix, margin,
            )  # fmt: skip
            _check_screen(sad, *out, cap * m.npix, margin)


def test_pair_bounds_are_a_loops_sums_in_entry_order_and_their_least():
    rng = np.random.default_rng(5)
    pairs_t = rng.random((12, 50)) * 4
    vpairs = rng.random(4) * 4
    bases = np.array([0, 6, 1, 7, 2])
    out, least = np.full((5, 64), np.nan), np.full(64, np.nan)
    pair_bounds(pairs_t, 7, 40, vpairs, bases, out, least)
    for i in range(33):
        for k, b in enumerate(bases):
            want = 0.0
            for j in range(4):  # in entry order: the same bits
                want += abs(float(pairs_t[b + j, 7 + i]) - float(vpairs[j]))
            assert out[k, i] == want
        assert least[i] == min(out[:, i])
    assert np.isnan(out[:, 33:]).all() and np.isnan(least[33:]).all()


@pytest.mark.parametrize("cap", [math.inf, 0.04])
def test_normal_search_over_several_blocks_keeps_the_best_and_skips_the_hint_once(cap):
    rng = np.random.default_rng(12)
    y, x, shift, n = 2, 10, 2, 2 * PAIR_BLOCK + 37
    bank_np, views = _bank_and_views(rng, n, y, x)
    m = TemplateMatcher(y, x, panoramic=False, shift=shift, step=1)
    bank = m.make_bank(dtype=torch.float32, device=None)
    bank.append(torch.from_numpy(bank_np))
    margin = 1e-5 * m.npix
    # views made from the first and last template of each block, and two others
    edges = [PAIR_BLOCK - 1, PAIR_BLOCK, 2 * PAIR_BLOCK - 1, 2 * PAIR_BLOCK, n - 1]
    near = [np.clip(bank_np[t] + 1e-4 * rng.random((y, x)), 0, 1).astype(np.float32) for t in edges]
    for view in views[:2] + near:
        v64 = view.astype(np.float64)
        sad = np.stack(
            [np.abs(v64[:, shift : x - shift] - bank_np[:, :, o : o + m.width]).sum((1, 2))
             for o in m.offsets_np], 1,
        )  # fmt: skip
        for hint in (-1, 0, PAIR_BLOCK + 5, n - 1):
            out = search_normal(
                bank.array("data"), bank.array("cols"), bank.column_major("pairs", np.float32),
                n, view, m.offsets_np, m.width, m.shift, hint, math.inf, cap * m.npix, margin,
            )  # fmt: skip
            _check_screen(sad, *out, cap * m.npix, margin)
            pairs = list(zip(out[0][: out[3]].tolist(), out[1][: out[3]].tolist()))
            assert len(pairs) == len(set(pairs))  # no pair screened twice (the hint)


def _visit_pairs(bank_np, view, m, hint, cap, margin):
    """Normal mode's screen written pair by pair: the hint alone, then blocks of
    :data:`PAIR_BLOCK` templates; a template whose least pair bound is above the cut at
    the block's start is skipped; each other pair is decided at its turn with the cut of
    that moment (pair bound, column bound, SAD row by row with early exit)."""
    n, y, x = bank_np.shape
    w, shift, offs = m.width, m.shift, m.offsets_np
    nb = w // 2
    v = view.astype(np.float64)
    vcols = v[:, shift : shift + w].sum(0)
    vpairs = vcols[0::2][:nb] + vcols[1::2][:nb]
    eps = 2.0 * (nb + 4) * 2.0**-24
    slack = eps * float(np.abs(vpairs).sum())
    half = x // 2
    bases = np.array([(o % 2) * half + o // 2 for o in offs], np.int64)
    pairs_t = np.empty((2 * half, n), np.float32)
    cols = bank_np.astype(np.float64).sum(1)
    for t in range(n):  # sums of adjacent column pairs, from even then odd columns
        c = cols[t]
        pairs_t[:half, t] = c[0 : 2 * half : 2] + c[1 : 2 * half : 2]
        pairs_t[half:, t] = np.append(c[1 : 2 * half - 1 : 2] + c[2 : 2 * half : 2], 0.0)
    bound = np.empty((len(offs), n), np.float32)
    least = np.empty(n, np.float32)
    pair_bounds(pairs_t, 0, n, vpairs.astype(np.float32), bases, bound, least)
    best, pruned, kept = math.inf, math.inf, []

    def visit(t, k):
        nonlocal best, pruned
        cut = min(best, cap) + margin
        b = float(bound[k, t]) * (1.0 - eps) - slack
        if cut < b < math.inf:
            pruned = min(pruned, b)
            return
        o = offs[k]
        b = float(np.abs(cols[t, o : o + w] - vcols).sum())
        if b > cut:
            pruned = min(pruned, b)
            return
        s = 0.0
        for r in range(y):
            s += float(np.abs(bank_np[t, r, o : o + w] - v[r, shift : shift + w]).sum())
            if s > cut:
                pruned = min(pruned, s - margin)
                return
        kept.append((t, k))
        best = min(best, s)

    blocks = [(hint, hint + 1)] if 0 <= hint < n else []
    blocks += [(t0, min(t0 + PAIR_BLOCK, n)) for t0 in range(0, n, PAIR_BLOCK)]
    for bi, (t0, t1) in enumerate(blocks):
        cut0 = min(best, cap) + margin
        for t in range(t0, t1):
            if t == hint and (bi > 0 or t1 - t0 > 1):
                continue
            b = float(least[t]) * (1.0 - eps) - slack
            if cut0 < b < math.inf:
                pruned = min(pruned, b)
                continue
            for k in range(len(offs)):
                visit(t, k)
    return kept, best, pruned


@pytest.mark.parametrize("cap", [math.inf, 0.04])
def test_normal_search_decides_each_pair_at_its_turn_as_a_loop_does(cap):
    """The compiled screen keeps the pairs a pair-by-pair loop keeps, in its order, and
    its least skipped bound is the loop's: the cut falls inside blocks (near-copies of
    the view late in the first and second blocks), so a pair is decided with the cut of
    its turn, not of its block's start."""
    rng = np.random.default_rng(21)
    y, x, shift, n = 2, 10, 2, 2 * PAIR_BLOCK + 37
    bank_np = rng.random((n, y, x))
    m = TemplateMatcher(y, x, panoramic=False, shift=shift, step=1)
    bank = m.make_bank(dtype=torch.float64, device=None)
    views = []
    for far, near in ((PAIR_BLOCK - 40, PAIR_BLOCK - 3), (PAIR_BLOCK + 50, 2 * PAIR_BLOCK + 9)):
        v = rng.random((y, x))
        bank_np[far] = v + 0.02 * rng.standard_normal((y, x))  # a good match first
        bank_np[near] = v + 0.002 * rng.standard_normal((y, x))  # then a better one
        views.append(v)
    views.append(rng.random((y, x)))  # unrelated
    bank.append(torch.from_numpy(bank_np))
    margin = 1e-9 * m.npix
    for view in views:
        for hint in (-1, 3, PAIR_BLOCK + 7):
            pt, pk, _, k, best, pruned = search_normal(
                bank.array("data"), bank.array("cols"), bank.column_major("pairs", np.float32),
                n, view, m.offsets_np, m.width, m.shift, hint, math.inf, cap * m.npix, margin,
            )  # fmt: skip
            kept, want_best, want_pruned = _visit_pairs(
                bank_np, view, m, hint, cap * m.npix, margin
            )
            assert list(zip(pt[:k].tolist(), pk[:k].tolist())) == kept
            assert best == pytest.approx(want_best, rel=1e-12)
            assert pruned == pytest.approx(want_pruned, rel=1e-12)
            assert len(kept) > 1 or cap < math.inf  # the cut fell at least once


def test_pair_bounds_in_float32_and_a_value_out_of_range_poisons_the_least():
    rng = np.random.default_rng(6)
    pairs_t = (rng.random((8, 20)) * 4).astype(np.float32)
    pairs_t[2, 5] = np.nan  # a sum past float32's range, as the bank's copy stores it
    pairs_t[6, 9] = np.inf
    vpairs = (rng.random(3) * 4).astype(np.float32)
    bases = np.array([0, 4, 5])
    out, least = np.empty((3, 20), np.float32), np.empty(20, np.float32)
    pair_bounds(pairs_t, 0, 20, vpairs, bases, out, least)
    for i in range(20):
        for k, b in enumerate(bases):
            want = np.float32(0.0)
            for j in range(3):  # float32 arithmetic, in entry order
                want = np.float32(want + np.float32(abs(pairs_t[b + j, i] - vpairs[j])))
            np.testing.assert_array_equal(out[k, i], want)
        if i in (5, 9):  # offsets whose window holds the NaN or the infinity
            assert np.isnan(least[i])
        else:
            assert least[i] == out[:, i].min()


@pytest.mark.parametrize("seed", range(6))
def test_normal_search_in_float64_keeps_bounds_below_sads_despite_float32_rounding(seed):
    """Templates that are the view plus a constant, one offset: each pair bound is its
    SAD in exact arithmetic, and every pair but the best is skipped on that bound alone,
    so the least bound skipped is a rounded bound: rounded up past its SAD, it would
    claim more than is true."""
    rng = np.random.default_rng(seed)
    y, x, shift = 3, 12, 0  # one offset
    view = 100 * rng.random((y, x)) + 50
    consts = 0.3 + 1e-3 * np.arange(10)
    bank_np = np.stack([view + c for c in consts])
    m = TemplateMatcher(y, x, panoramic=False, shift=shift, step=1)
    bank = m.make_bank(dtype=torch.float64, device=None)
    bank.append(torch.from_numpy(bank_np))
    sad = _sad_loops(bank_np, view, m.offsets_np, False, shift)
    margin = 1e-11 * m.npix
    for cap in (math.inf, 0.3 * (1 - 1e-9)):  # the first matches; none matches
        out = search_normal(
            bank.array("data"), bank.array("cols"), bank.column_major("pairs", np.float32),
            len(bank_np), view, m.offsets_np, m.width, m.shift, -1, math.inf,
            cap * m.npix, margin,
        )  # fmt: skip
        _check_screen(sad, *out, cap * m.npix, margin)


def test_normal_search_with_sums_past_float32s_range_falls_back_to_float64():
    rng = np.random.default_rng(14)
    y, x, shift = 2, 8, 1
    bank_np = rng.random((6, y, x))
    bank_np[2] *= 1e39  # pair sums past float32's range
    view = bank_np[4] + 1e-3
    m = TemplateMatcher(y, x, panoramic=False, shift=shift, step=1)
    bank = m.make_bank(dtype=torch.float64, device=None)
    bank.append(torch.from_numpy(bank_np))
    p32 = bank.column_major("pairs", np.float32)
    assert np.isnan(p32[:, 2]).any() and np.isfinite(p32[:, [0, 1, 3, 4, 5]]).all()
    sad = _sad_loops(bank_np, view, m.offsets_np, False, shift)
    margin = 1e-11 * m.npix
    out = search_normal(
        bank.array("data"), bank.array("cols"), p32, 6, view, m.offsets_np, m.width,
        m.shift, -1, math.inf, math.inf, margin,
    )  # fmt: skip
    _check_screen(sad, *out, math.inf, margin)
    # a view past float32's range: no float32 bound prunes; the float64 stages decide
    big = view * 1e39
    sad = _sad_loops(bank_np, big, m.offsets_np, False, shift)
    pt, pk, _, k, best, _ = search_normal(
        bank.array("data"), bank.array("cols"), p32, 6, big, m.offsets_np, m.width,
        m.shift, -1, math.inf, math.inf, margin,
    )  # fmt: skip
    t, o = np.unravel_index(np.argmin(sad), sad.shape)
    assert (t, o) in set(zip(pt[:k].tolist(), pk[:k].tolist()))
    assert best == pytest.approx(sad.min(), rel=1e-12)


def test_sort_into_is_numpys_sort():
    rng = np.random.default_rng(15)
    for n in (0, 1, 2, 7, 64, 65):
        for a in (rng.standard_normal(n), rng.integers(-3, 3, n).astype(np.float64)):
            out = np.full(n, np.nan)
            _sort_into(a, out)
            np.testing.assert_array_equal(out, np.sort(a))


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
