"""The compiled fixed-order convolution against a loop written here, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from torchratslam.pose_cells import functional as F
from torchratslam.pose_cells._taps import conv3, conv3_box


def brute_axis(a: np.ndarray, w: np.ndarray, axis: int, circular: bool) -> np.ndarray:
    """``out[p] = 0 + w[0] a[p + h] + w[1] a[p + h - 1] + ...``, one rounding per step."""
    h = len(w) // 2
    moved = np.moveaxis(a, axis, -1)
    out = np.zeros_like(moved)
    n = moved.shape[-1]
    for idx in np.ndindex(moved.shape[:-1]):
        for p in range(n):
            acc = moved.dtype.type(0)
            for j in range(len(w)):
                k = p + h - j
                if circular:
                    k %= n
                elif not 0 <= k < n:
                    continue
                acc = acc + w[j] * moved[(*idx, k)]
            out[(*idx, p)] = acc
    return np.moveaxis(out, -1, axis)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize(
    ("shape", "circ"),
    [
        ((9, 6, 7), (True, False, False)),
        ((5, 8, 4), (False, True, True)),
        ((3, 4, 11), (True, True, False)),  # rings shorter than the kernel
    ],
)
def test_conv3_is_the_fixed_order_sum(dtype, shape, circ):
    rng = np.random.default_rng(len(shape) + sum(shape))
    a = rng.random(shape).astype(dtype)
    a[a < 0.4] = 0  # sparse, like a packet
    w = F.gaussian_kernel_1d(7, 1).astype(dtype)
    want = a
    for axis in (2, 1, 0):  # x, then y, then theta
        want = brute_axis(want, w, axis, circ[axis])
    got = conv3(a, w, *circ)
    assert got.dtype == dtype
    assert np.array_equal(got, want)


def test_conv3_is_the_ring_matrix_convolution():
    rng = np.random.default_rng(3)
    a = rng.random((12, 10, 9))
    kern = F.gaussian_kernel_1d(5, 2)
    circ = (True, False, True)
    mats = [F.ring_matrix(kern, n, c) for n, c in zip(a.shape, circ, strict=True)]
    want = np.einsum("ti,yj,xk,ijk->tyx", *mats, a)
    np.testing.assert_allclose(conv3(a, kern, *circ), want, rtol=1e-13, atol=0)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_conv3_box_skips_only_zeros(dtype):
    # an input that is zero outside a box (values of both signs inside, as OpenRatSLAM's
    # one-cell path integration leaves them): the same bits as the whole array's loop,
    # signs of zero included, and the returned box holds every non-zero cell
    rng = np.random.default_rng(21)
    for trial in range(120):
        shape = tuple(int(v) for v in rng.integers(2, 12, 3))
        circ = tuple(bool(v) for v in rng.integers(0, 2, 3))
        w = F.gaussian_kernel_1d((7, 5, 4, 3)[trial % 4], 1.5).astype(dtype)
        lo = [int(rng.integers(0, s)) for s in shape]
        hi = [int(rng.integers(a, s + 1)) for a, s in zip(lo, shape, strict=True)]
        inside = tuple(slice(a, b) for a, b in zip(lo, hi, strict=True))
        a = np.zeros(shape, dtype)
        a[inside] = rng.uniform(-0.3, 1.0, a[inside].shape)
        a[np.abs(a) < 0.3] = 0
        want = a
        for axis in (2, 1, 0):
            want = brute_axis(want, w, axis, circ[axis])
        got, box = conv3_box(a, w, *circ, np.array([lo, hi], np.int64).T.copy())
        assert got.dtype == dtype
        assert np.array_equal(got, want) and np.array_equal(np.signbit(got), np.signbit(want))
        nz = np.argwhere(got != 0)
        if len(nz):
            assert (nz.min(0) >= box[:, 0]).all() and (nz.max(0) < box[:, 1]).all()
        else:
            assert not a.any() or not want.any()
