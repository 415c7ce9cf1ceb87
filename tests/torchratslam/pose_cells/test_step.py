"""The compiled step on the crop against numpy written here, bit for bit.

The reference is the step in numpy, one array operation at a time: gather the crop,
excite and inhibit (``conv3``, checked against loops in ``test_taps.py``), global
inhibition, clamp, the pairwise sum, normalise, OpenRatSLAM's path integration with its edge
loss, the theta shift, scatter, the non-zero arcs, the most active cell and find_best.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from torchratslam.config import PoseCellParams
from torchratslam.errors import InputError
from torchratslam.pose_cells import functional as F
from torchratslam.pose_cells._step import (
    find_best,
    minimal_arc,
    pairwise_sum,
    total,
)
from torchratslam.pose_cells._taps import conv3
from torchratslam.pose_cells.decode import CentreDecoder
from torchratslam.pose_cells.motion import MotionTables
from torchratslam.pose_cells.numpy_engine import NumpyEngine


# ------------------------------------------------------------------ references
def ref_pairwise(a: np.ndarray) -> float:
    """numpy 2's pairwise summation of a flat array, written out: below 8 a running sum;
    up to 128 eight running sums combined in a tree, then the rest; above, two halves
    (the first a multiple of 8)."""
    n, zero = a.size, a.dtype.type(0)
    if n < 8:
        res = zero
        for v in a:
            res = res + v
        return res
    if n <= 128:
        r = [a[m] for m in range(8)]
        end = n - n % 8
        for i in range(8, end, 8):
            for m in range(8):
                r[m] = r[m] + a[i + m]
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        for i in range(end, n):
            res = res + a[i]
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return ref_pairwise(a[:n2]) + ref_pairwise(a[n2:])


def ref_find_best(act: np.ndarray, peak: int, p: PoseCellParams) -> tuple[float, ...]:
    """OpenRatSLAM's find_best in numpy: the cube's sums, the phasors in cell order."""
    n_t, n_y, n_x = act.shape
    c = p.pc_cells_to_avg
    pt, py, px = peak // (n_y * n_x), (peak // n_x) % n_y, peak % n_x
    off = np.arange(-c, c + 1)
    it, iy, ix = (np.remainder(q + off, n) for q, n in ((pt, n_t), (py, n_y), (px, n_x)))
    cube = act[it[:, None, None], iy[None, :, None], ix[None, None, :]].astype(np.float64)
    c2 = cube.sum(axis=0)
    res = []
    axes = ((c2.sum(axis=0), ix, n_x), (c2.sum(axis=1), iy, n_y), (cube.sum(axis=(1, 2)), it, n_t))
    for sums, ring, n in axes:
        ang = (np.arange(n, dtype=np.float64) + 1.0) * 2.0 * math.pi / float(n)
        start = int(np.argmin(ring))
        r = np.concatenate((ring[start:], ring[:start]))
        w = np.concatenate((sums[start:], sums[:start]))
        s1 = float(np.cumsum(np.sin(ang)[r] * w)[-1])
        s2 = float(np.cumsum(np.cos(ang)[r] * w)[-1])
        x = math.atan2(s1, s2) * n / (2.0 * math.pi) - 1.0
        while x < 0:
            x += n
        while x > n:
            x -= n
        res.append(x)
    return tuple(res)


def shift_take(a: np.ndarray, axis: int, shifts: np.ndarray) -> np.ndarray:
    """Layer ``k`` of ``a`` moved by ``shifts[k]`` cells along ``axis``, wrapping on ``a``."""
    return np.stack([np.roll(a[k], int(s), axis=axis - 1) for k, s in enumerate(shifts)])


def ref_translate(a, trans, layers, box_y, box_x, mo: MotionTables, n):
    g = mo.geometry(trans < 0)
    v = abs(trans)
    src = a
    for axis, name in ((2, "x"), (1, "y")):
        if mo.one_cell:
            base = np.zeros(len(layers), dtype=np.int64)
            step = g["step_" + name][layers]
            w = (v * g["coef_" + name][layers]).astype(a.dtype)
        else:
            c = v * g["coef_" + name][layers]
            fl = np.floor(c)
            base, step = fl.astype(np.int64), fl.astype(np.int64) + 1
            w = (c - fl).astype(a.dtype)
        s0, s1 = shift_take(a, axis, base), shift_take(a, axis, step)
        a = s0 + w[:, None, None] * (s1 - s0)
    if not mo.edge_loss:
        return a
    (sy, ly), (sx, lx) = box_y, box_x
    py = [q if q < ly else -1 for q in ((0 - sy) % n, (n - 1 - sy) % n)]
    px = [q if q < lx else -1 for q in ((0 - sx) % n, (n - 1 - sx) % n)]
    sin, cos = g["sin"][layers], g["cos"][layers]
    lost = np.stack([v * sin * (1.0 - v * cos), v * cos * (1.0 - v * sin)], axis=1)
    for k, layer in enumerate(layers):
        take = np.zeros(1, dtype=a.dtype)
        for m in range(2):
            cy, cx = py[g["src"][layer, m, 0]], px[g["src"][layer, m, 1]]
            if cy >= 0 and cx >= 0:
                take += lost[k, m] * src[k, cy, cx]  # float64, rounded to the dtype
        cy, cx = py[g["corner"][layer, 0]], px[g["corner"][layer, 1]]
        if cy >= 0 and cx >= 0 and take[0] != 0:
            a[k, cy, cx] -= take[0]
    return a


def ref_step(act, arcs, trans, rot, p: PoseCellParams):
    """One step in numpy; returns the new arcs, the most active cell and the crop."""
    _, n_y, n_x = act.shape
    eh = max(p.pc_w_e_dim // 2, p.pc_w_e_dim - 1 - p.pc_w_e_dim // 2)
    move_xy = math.ceil(abs(trans)) + 1 if trans != 0 else 0
    move_th = math.ceil(abs(rot)) + 1 if rot != 0 else 0
    boxes = []
    for (start, ln), n, m in zip(arcs, act.shape, (move_th, move_xy, move_xy), strict=True):
        m += eh
        boxes.append((0, n, True) if ln + 2 * m >= n else ((start - m) % n, ln + 2 * m, False))
    idx = [np.remainder(np.arange(s, s + ln), n) for (s, ln, _), n in zip(boxes, act.shape)]
    circ = [b[2] for b in boxes]
    crop = act[np.ix_(*idx)]
    dt = act.dtype
    w_e = F.gaussian_kernel_1d(p.pc_w_e_dim, p.pc_w_e_var).astype(dt)
    w_i = F.gaussian_kernel_1d(p.pc_w_i_dim, p.pc_w_i_var).astype(dt)
    e = conv3(crop, w_e, *circ)
    a = e - conv3(e, w_i, *circ)
    a -= p.pc_global_inhib
    np.maximum(a, 0.0, out=a)
    mass = ref_pairwise(a.reshape(-1))
    if not mass > 0:
        raise InputError(F.DIED_OUT)
    a /= mass
    if trans != 0:
        mo = MotionTables(p)
        a = ref_translate(a, trans, idx[0], boxes[1][:2], boxes[2][:2], mo, n_x)
    if rot != 0:
        a = F.rotate_theta(a, rot)
    act[np.ix_(*idx)] = a
    nz = a != 0
    new = []
    for ax, (start, _, whole), n in zip(range(3), boxes, act.shape, strict=True):
        mask = nz.any(axis=tuple(q for q in range(3) if q != ax))
        on = np.flatnonzero(mask)
        if whole:
            new.append(F.arc(mask))
        else:
            new.append(((start + int(on[0])) % n, int(on[-1] - on[0]) + 1) if on.size else (0, 0))
    hits = np.argwhere(a == a.max())
    cells = (idx[0][hits[:, 0]] * n_y + idx[1][hits[:, 1]]) * n_x + idx[2][hits[:, 2]]
    return new, int(cells.min()), a.shape


# ---------------------------------------------------------------------- pieces
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_sum_is_a_fixed_pairwise_sum(dtype):
    rng = np.random.default_rng(1)
    for n in [*range(1, 140), 255, 256, 1000, 8191, 8193, 15876, 20001]:
        a = (rng.random(n) * 3).astype(dtype)
        assert total(a, 0, dtype(0)) == ref_pairwise(a), n
        if n <= 8192:  # numpy sums that much in one pairwise sum, whatever its version
            assert total(a, 0, dtype(0)) == a.sum(), n
    for shape in [(36, 21, 21), (16, 17, 18), (9, 11, 7)]:
        a = rng.random(shape).astype(dtype)
        assert total(a.reshape(-1), 0, dtype(0)) == ref_pairwise(a.reshape(-1)), shape
        assert pairwise_sum(a[0].reshape(-1), 0, shape[1] * shape[2], dtype(0)) == a[0].sum()


def test_the_minimal_arc_is_functionals():
    rng = np.random.default_rng(2)
    for n in (1, 2, 5, 21, 36):
        for _ in range(60):
            mask = rng.random(n) < rng.random()
            assert minimal_arc(mask) == F.arc(mask), mask


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("avg", [0, 3, 5])
def test_find_best_is_the_numpy_find_best(dtype, avg):
    p = PoseCellParams(pc_dim_xy=9, pc_dim_th=12, pc_cells_to_avg=avg)
    dec = CentreDecoder(p)
    rng = np.random.default_rng(avg)
    for _ in range(40):
        act = rng.random((12, 9, 9)).astype(dtype)
        act[act < 0.5] = 0
        peak = int(rng.integers(act.size))
        act.reshape(-1)[peak] = 2
        want = ref_find_best(act, peak, p)
        assert find_best(act, peak, avg, dec.find_best_tables()) == want
        assert dec.decode_one(act, peak) == want


# ------------------------------------------------------------------ whole step
CASES = [
    {},
    {"pc_axis": "math"},
    {"pc_multi_cell": True, "pc_wrap": "preserve_mass"},
    {"pc_decode": "exact", "pc_dim_xy": 11, "pc_dim_th": 10},  # whole rings more often
]


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("change", CASES)
def test_the_step_is_the_numpy_step_bit_for_bit(dtype, change):
    p = PoseCellParams(**change)
    eng = NumpyEngine(p, dtype)
    act = torch.zeros(1, p.pc_dim_th, p.pc_dim_xy, p.pc_dim_xy, dtype=dtype)
    rng = np.random.default_rng(len(change))
    n_t, n = p.pc_dim_th, p.pc_dim_xy
    cell = (int(rng.integers(n_t)), 0, n - 1)  # a packet on the wrap of x and y
    act[0][cell] = 1.0
    ref = act[0].numpy().copy()
    arcs = [(c, 1) for c in cell]
    steps = [(0.0, 0.0), (0.0, -0.7), (1.0, 0.0), (-2.6, 1.0), (0.3, 2.0)]
    steps += [(float(t), float(r)) for t, r in rng.normal(0, 0.7, (70, 2))]
    crops = set()
    for i, (trans, rot) in enumerate(steps):
        if i % 9 == 4:  # a template's energy elsewhere
            c = tuple(int(rng.integers(d)) for d in ref.shape)
            ref[c] += np.float64(0.2)
            arcs = [F.arc_with(s, q, d) for s, q, d in zip(arcs, c, ref.shape, strict=True)]
            eng.inject(act, *c, np.float64(0.2))
        arcs, peak, crop = ref_step(ref, arcs, trans, rot, p)
        centre = eng.step(act, trans, rot)
        crops.add(crop == ref.shape)
        assert np.array_equal(act[0].numpy(), ref), (i, trans, rot)
        assert eng.last_crop == crop  # the same arcs before this step
        want = ref_find_best(ref, peak, p) if p.pc_decode == "openratslam" else None
        assert centre == (want or CentreDecoder(p).decode_one(ref, peak))
    assert crops == {False, True}  # crops of the packet and of the whole network


def test_a_step_that_dies_out_writes_nothing():
    p = PoseCellParams(pc_global_inhib=0.9)
    eng = NumpyEngine(p, torch.float64)
    act = torch.zeros(1, p.pc_dim_th, p.pc_dim_xy, p.pc_dim_xy, dtype=torch.float64)
    act[0, 3, 4, 5] = 1.0
    before = act.clone()
    with pytest.raises(InputError, match="died out"):
        eng.step(act, 0.5, 0.5)
    assert torch.equal(act, before)
