"""The pose-cell functions against brute-force loops written here."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from torchratslam.errors import InputError
from torchratslam.pose_cells import functional as F

F64 = torch.float64


def brute_circular_conv(a: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Every cell scatters its activity with the outer-product kernel, wrapping."""
    n_t, n_y, n_x = a.shape
    h = len(k) // 2
    out = np.zeros_like(a)
    for t in range(n_t):
        for y in range(n_y):
            for x in range(n_x):
                for i, wi in enumerate(k):
                    for j, wj in enumerate(k):
                        for m, wm in enumerate(k):
                            tt, yy, xx = (t + i - h) % n_t, (y + j - h) % n_y, (x + m - h) % n_x
                            out[tt, yy, xx] += a[t, y, x] * wi * wj * wm
    return out


@pytest.mark.parametrize("dim", [3, 4, 5])
def test_both_convolutions_equal_the_scatter_loop(dim):
    rng = np.random.default_rng(dim)
    a = rng.uniform(0, 1, (1, 6, 7, 5))
    k = F.gaussian_kernel_1d(dim, 1.3)
    want = brute_circular_conv(a[0], k)
    at = torch.from_numpy(a)
    mats = [torch.from_numpy(F.ring_matrix(k, n, True)) for n in a.shape[1:]]
    np.testing.assert_allclose(F.separable_conv3d(at, *mats)[0].numpy(), want, atol=1e-12)
    np.testing.assert_allclose(F.circular_conv3d(at, k)[0].numpy(), want, atol=1e-12)


def test_gaussian_kernel_uses_the_variance_as_standard_deviation():
    k = F.gaussian_kernel_1d(5, 2.0)
    w = [math.exp(-(d * d) / 8.0) for d in range(-2, 3)]
    np.testing.assert_allclose(k, np.array(w) / sum(w), rtol=1e-15)


def test_toeplitz_ring_matrix_drops_what_leaves_the_ring():
    k = np.array([0.25, 0.5, 0.25])
    m = F.ring_matrix(k, 4, circular=False)
    v = np.array([1.0, 0.0, 0.0, 2.0])
    want = [sum(k[d + 1] * v[p - d] for d in (-1, 0, 1) if 0 <= p - d < 4) for p in range(4)]
    np.testing.assert_allclose(m @ v, want)


def test_inhibition_and_normalisation():
    a = torch.tensor([[[[0.5, 0.1], [0.0, 0.3]]]], dtype=F64)
    g = F.global_inhibition(a, 0.2)
    assert g.flatten().tolist() == pytest.approx([0.3, 0.0, 0.0, 0.1])
    n = F.normalise(g)
    assert float(n.sum()) == pytest.approx(1.0) and float(n.min()) >= 0
    with pytest.raises(InputError, match="died out"):
        F.normalise(F.global_inhibition(a, 0.6))


def test_minimal_arcs_equal_an_exhaustive_search():
    rng = np.random.default_rng(1)
    occ = rng.random((200, 9)) < 0.25
    start, length = F.minimal_arcs(occ)
    for row, s, ln in zip(occ, start, length, strict=True):
        on = set(np.flatnonzero(row).tolist())
        if not on:
            assert ln == 0
            continue
        best = min(
            L for s0 in range(9) for L in range(1, 10) if on <= {(s0 + i) % 9 for i in range(L)}
        )
        assert ln == best and on <= {(s + i) % 9 for i in range(ln)}


@pytest.mark.parametrize("rot", [0.0, 1.0, -2.0, 0.3, -1.7, 3.25])
def test_theta_rotation_is_linear_between_floor_and_ceil(rot):
    a = np.random.default_rng(2).uniform(0, 1, (7, 2, 3))
    got = F.rotate_theta(a, rot)
    r = abs(rot)
    w = r - math.floor(r) or 1.0
    sign = -1 if rot < 0 else 1
    lo, hi = sign * math.floor(r), sign * math.ceil(r)
    want = np.empty_like(a)
    for t in range(7):
        want[t] = a[(t - lo) % 7] * (1 - w) + a[(t - hi) % 7] * w
    np.testing.assert_allclose(got, want, atol=1e-15)


def test_shift_axis_moves_each_layer_by_its_own_fraction():
    rng = np.random.default_rng(3)
    a = rng.uniform(0, 1, (2, 3, 5, 6))
    shift = rng.uniform(-4, 4, (2, 3))
    pool = [torch.from_numpy(a.copy()), torch.empty(2, 3, 5, 6, dtype=F64)]
    cache: dict = {}
    F.shift_axis_(pool, shift, 3, cache)
    want = np.empty_like(a)
    for b in range(2):
        for t in range(3):
            fl = math.floor(shift[b, t])
            w = shift[b, t] - fl
            want[b, t] = (1 - w) * np.roll(a[b, t], fl, axis=1) + w * np.roll(
                a[b, t], fl + 1, axis=1
            )
    np.testing.assert_allclose(pool[0].numpy(), want, atol=1e-14)
    assert len(cache) == 1


def test_injection_and_peak():
    act = torch.zeros(2, 3, 4, 5, dtype=F64)
    F.inject_(act, np.array([1, 2]), np.array([3, 0]), np.array([4, 1]), np.array([0.5, 0.25]))
    F.inject_(act, np.array([1, 0]), np.array([3, 0]), np.array([4, 0]), np.array([0.5, 0.0]))
    assert float(act[0, 1, 3, 4]) == 1.0 and float(act[1, 2, 0, 1]) == 0.25
    assert float(act.sum()) == 1.25
    assert list(F.peak_index(act)) == [1 * 20 + 3 * 5 + 4, 2 * 20 + 0 * 5 + 1]


def test_as_batch_checks_the_shape():
    assert F.as_batch(2.0, 3, "v").tolist() == [2.0, 2.0, 2.0]
    with pytest.raises(InputError, match=r"^v: expected shape \(3,\)"):
        F.as_batch([1.0, 2.0], 3, "v")
