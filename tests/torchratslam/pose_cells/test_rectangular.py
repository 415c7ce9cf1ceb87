"""Pose-cell networks with X != Y (``pc_dim_x``, ``pc_dim_y``) against a per-cell reference.

The reference below is one step written cell by cell from the definitions (no engine
code): excitation and inhibition by the 3D Gaussian with wrap on every axis, global
inhibition, normalisation, path integration in the global frame (each theta layer moves
along ``(sin, cos)`` of its heading in ``(x, y)``, OpenRatSLAM's four-neighbour weights
and its edge loss, or a bilinear move of any length with all of the activity wrapping),
the theta shift, and ``find_best``'s centre. Every engine on a 7 x 5 x 6 network (and
the cropping engines on a larger one, where the box is smaller than the rings) follows
it for several steps whose packet crosses the wrap in x, in y and in theta.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import torchratslam.pipeline.defaults  # noqa: F401  (registers the default stages)
from torchratslam.config import PoseCellParams, RatSLAMConfig
from torchratslam.errors import ConfigError, MapFormatError
from torchratslam.messages import ViewMatch
from torchratslam.pose_cells.network import PoseCellNetwork
from torchratslam.pose_cells.stage import PoseCells
from torchratslam.pose_cells.state import PoseCellState

OPENRATSLAM: dict = {}  # the defaults: one-cell weights, edge loss, find_best
PROJECT = {
    "pc_decode": "exact",
    "pc_axis": "openratslam",
    "pc_wrap": "preserve_mass",
    "pc_multi_cell": True,
}


# ------------------------------------------------------------------ reference
def ref_kernel(dim: int, var: float) -> np.ndarray:
    """``exp(-(i^2 + j^2 + k^2) / (2 var^2))`` around ``dim // 2``, normalised."""
    c = dim // 2
    w = np.zeros((dim, dim, dim))
    for k in range(dim):
        for j in range(dim):
            for i in range(dim):
                w[k, j, i] = math.exp(-((i - c) ** 2 + (j - c) ** 2 + (k - c) ** 2) / (2 * var**2))
    return w / w.sum()


def ref_conv(a: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Every cell gathers its wrapped neighbours through the kernel (axes th, y, x)."""
    nt, ny, nx = a.shape
    c = w.shape[0] // 2
    out = np.zeros_like(a)
    for t in range(nt):
        for y in range(ny):
            for x in range(nx):
                s = 0.0
                for k in range(w.shape[0]):
                    for j in range(w.shape[0]):
                        for i in range(w.shape[0]):
                            s += (
                                w[k, j, i] * a[(t - k + c) % nt, (y - j + c) % ny, (x - i + c) % nx]
                            )
                out[t, y, x] = s
    return out


def ref_translate(a: np.ndarray, trans: float, p: PoseCellParams) -> np.ndarray:
    """Each layer ``k`` moves ``trans`` cells along ``(sin, cos)(k 2 pi / TH)`` in (x, y)."""
    nt, ny, nx = a.shape
    out = np.zeros_like(a)
    v = abs(trans)
    for k in range(nt):
        d = k * 2 * math.pi / nt + (math.pi if trans < 0 else 0.0)
        mx, my = v * math.sin(d), v * math.cos(d)
        if p.pc_multi_cell:  # bilinear, any distance, everything wraps
            fx, fy = math.floor(mx), math.floor(my)
            wx, wy = mx - fx, my - fy
            for y in range(ny):
                for x in range(nx):
                    out[k, y, x] = (
                        (1 - wy) * (1 - wx) * a[k, (y - fy) % ny, (x - fx) % nx]
                        + (1 - wy) * wx * a[k, (y - fy) % ny, (x - fx - 1) % nx]
                        + wy * (1 - wx) * a[k, (y - fy - 1) % ny, (x - fx) % nx]
                        + wy * wx * a[k, (y - fy - 1) % ny, (x - fx - 1) % nx]
                    )
            continue
        # OpenRatSLAM: a quadrant's signs (its half-open quarter turns), one-cell weights
        q = math.floor(d * 2 / math.pi) % 4
        sx = 1 if q in (0, 1) else -1
        sy = 1 if q in (0, 3) else -1
        wx, wy = abs(mx), abs(my)
        for y in range(ny):
            for x in range(nx):
                out[k, y, x] = (
                    (1 - wy) * (1 - wx) * a[k, y, x]
                    + (1 - wy) * wx * a[k, y, (x - sx) % nx]
                    + wy * (1 - wx) * a[k, (y - sy) % ny, x]
                    + wy * wx * a[k, (y - sy) % ny, (x - sx) % nx]
                )
        if p.pc_wrap == "openratslam":
            # the corner the layer enters in both axes does not receive what crosses
            # the x wrap along its row, nor what crosses the y wrap along its column
            cy, cx = (0 if sy > 0 else ny - 1), (0 if sx > 0 else nx - 1)
            out[k, cy, cx] -= (
                wx * (1 - wy) * a[k, cy, (cx - sx) % nx] + wy * (1 - wx) * a[k, (cy - sy) % ny, cx]
            )
    return out


def ref_rotate(a: np.ndarray, rot: float) -> np.ndarray:
    """Layer ``k`` takes ``(1 - w)`` of layer ``k - floor`` and ``w`` of ``k - ceil``."""
    nt = a.shape[0]
    r = abs(rot)
    w = r - math.floor(r) or 1.0
    sign = -1 if rot < 0 else 1
    s1, s2 = sign * math.floor(r), sign * math.ceil(r)
    out = np.zeros_like(a)
    for k in range(nt):
        out[k] = (1 - w) * a[(k - s1) % nt] + w * a[(k - s2) % nt]
    return out


def ref_centre(a: np.ndarray, p: PoseCellParams) -> tuple[float, float, float]:
    """The centre of the cube of ``+-pc_cells_to_avg`` cells around the most active cell,
    per axis on its own ring."""
    nt, ny, nx = a.shape
    pt, py, px = np.unravel_index(int(np.argmax(a)), a.shape)
    c = p.pc_cells_to_avg
    sums: list[dict[int, float]] = [{}, {}, {}]  # x, y, th: ring index -> summed activity
    for dk in range(-c, c + 1):
        for dj in range(-c, c + 1):
            for di in range(-c, c + 1):
                t, y, x = (pt + dk) % nt, (py + dj) % ny, (px + di) % nx
                v = a[t, y, x]
                for axis, cell in enumerate((x, y, t)):
                    sums[axis][cell] = sums[axis].get(cell, 0.0) + v
    out = []
    for axis, n in enumerate((nx, ny, nt)):
        off = 1.0 if p.pc_decode == "openratslam" else 0.0
        s1 = sum(math.sin((i + off) * 2 * math.pi / n) * s for i, s in sums[axis].items())
        s2 = sum(math.cos((i + off) * 2 * math.pi / n) * s for i, s in sums[axis].items())
        pos = math.atan2(s1, s2) * n / (2 * math.pi) - off
        out.append(pos % n)
    return out[0], out[1], out[2]


def ref_step(a: np.ndarray, trans: float, rot: float, p: PoseCellParams) -> np.ndarray:
    we = ref_kernel(p.pc_w_e_dim, p.pc_w_e_var)
    wi = ref_kernel(p.pc_w_i_dim, p.pc_w_i_var)
    e = ref_conv(a, we)
    b = np.maximum(e - ref_conv(e, wi) - p.pc_global_inhib, 0.0)
    b = b / b.sum()
    if trans != 0:
        b = ref_translate(b, trans, p)
    if rot != 0:
        b = ref_rotate(b, rot)
    return b


def ring_gap(u: float, v: float, n: int) -> float:
    d = abs(u - v) % n
    return min(d, n - d)


# ------------------------------------------------------------------ the runs
# (vtrans cells, rot cells, injection (x, y, th, energy) or None) per step: the packet
# starts in the last cell of every axis and moves forward, then back, across each wrap
STEPS = [
    (0.8, 0.7, None),
    (0.9, 0.6, None),
    (0.6, 1.0, (1, 3, 2, 0.2)),
    (0.7, 0.0, None),
    (-0.9, -0.8, None),
    (0.0, -1.4, None),
]


def _run(p: PoseCellParams, method: str, batch: int, start: tuple[int, int, int], device=None):
    net = PoseCellNetwork(p, batch, method=method, device=device)
    net.place_packet(*start)
    n_th = p.pc_dim_th
    got, want = [], []
    ref = np.zeros((n_th, p.dim_y, p.dim_x))
    ref[start[2], start[1], start[0]] = 1.0
    for vt, rc, inj in STEPS:
        vrot = rc * (2 * math.pi / n_th)
        if batch == 1:
            c = net.step(float(vt), float(vrot), 1.0)
        else:  # the batch: network b runs the same odometry scaled (b = 0 the listed one)
            scale = np.linspace(1.0, 0.5, batch)
            c = net.step(vt * scale, vrot * np.ones(batch), np.ones(batch))
        rot = vrot * 1.0 / (2.0 * math.pi / n_th)
        ref = ref_step(ref, vt, rot, p)
        got.append((net.activity[0].cpu().numpy().copy(), c[0].tolist()))
        want.append((ref.copy(), ref_centre(ref, p)))
        if inj is not None:
            x, y, th, e = inj
            net.inject(x, y, th, e)
            ref[th, y, x] += e
    return got, want


@pytest.mark.parametrize("profile", ["openratslam", "project"])
@pytest.mark.parametrize(
    ("method", "batch"),
    [("numpy", 1), ("crop", 1), ("separable", 1), ("conv3d", 1), ("separable", 3), ("crop", 2)],
)
def test_every_engine_follows_the_per_cell_reference_on_a_7x5x6_network(profile, method, batch):
    extra = OPENRATSLAM if profile == "openratslam" else PROJECT
    p = PoseCellParams(pc_dim_x=7, pc_dim_y=5, pc_dim_th=6, **extra)
    got, want = _run(p, method, batch, start=(6, 4, 5))
    for i, ((act, centre), (ref, ref_c)) in enumerate(zip(got, want, strict=True)):
        assert act.shape == (6, 5, 7)
        np.testing.assert_allclose(act, ref, rtol=0, atol=1e-12, err_msg=f"step {i}")
        for axis, n in enumerate((7, 5, 6)):
            assert ring_gap(centre[axis], ref_c[axis], n) < 1e-9, (i, axis, centre, ref_c)


@pytest.mark.parametrize("profile", ["openratslam", "project"])
@pytest.mark.parametrize("method", ["numpy", "crop"])
def test_the_cropping_engines_follow_the_reference_where_the_box_is_smaller(profile, method):
    """Small kernels on 13 x 9 x 10: the box around the packet is smaller than each ring,
    so the crop itself has to wrap at each edge (the packet starts in the last cells)."""
    extra = OPENRATSLAM if profile == "openratslam" else PROJECT
    p = PoseCellParams(pc_dim_x=13, pc_dim_y=9, pc_dim_th=10, pc_w_e_dim=3, pc_w_i_dim=3, **extra)
    got, want = _run(p, method, 1, start=(12, 8, 9))
    net = PoseCellNetwork(p, method=method)
    assert net.activity.shape == (1, 10, 9, 13)
    for i, ((act, centre), (ref, ref_c)) in enumerate(zip(got, want, strict=True)):
        np.testing.assert_allclose(act, ref, rtol=0, atol=1e-12, err_msg=f"step {i}")
        for axis, n in enumerate((13, 9, 10)):
            assert ring_gap(centre[axis], ref_c[axis], n) < 1e-9, (i, axis, centre, ref_c)
    # the packet went round every ring's wrap: its cells visited both ends of each axis
    seen = np.zeros((10, 9, 13), bool)
    for act, _ in got:
        seen |= act > 1e-3
    for axis, n in ((0, 10), (1, 9), (2, 13)):
        cells = np.flatnonzero(seen.any(axis=tuple(a for a in range(3) if a != axis)))
        assert 0 in cells and n - 1 in cells, (axis, cells)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
@pytest.mark.parametrize("method", ["crop", "separable", "conv3d"])
def test_the_torch_engines_on_cuda_follow_the_reference(method):
    p = PoseCellParams(pc_dim_x=7, pc_dim_y=5, pc_dim_th=6)
    got, want = _run(p, method, 2, start=(6, 4, 5), device="cuda")
    for i, ((act, _), (ref, _)) in enumerate(zip(got, want, strict=True)):
        np.testing.assert_allclose(act, ref, rtol=0, atol=1e-12, err_msg=f"step {i}")


def test_the_batch_networks_each_follow_their_own_odometry():
    p = PoseCellParams(pc_dim_x=7, pc_dim_y=5, pc_dim_th=6)
    net = PoseCellNetwork(p, 3, method="separable")
    net.place_packet(6, 4, 5)
    refs = [np.zeros((6, 5, 7)) for _ in range(3)]
    for r in refs:
        r[5, 4, 6] = 1.0
    speeds = np.array([0.8, -0.6, 0.3])
    for _ in range(3):
        net.step(speeds, np.zeros(3), np.ones(3))
        refs = [ref_step(r, float(s), 0.0, p) for r, s in zip(refs, speeds, strict=True)]
    for b in range(3):
        np.testing.assert_allclose(net.activity[b].numpy(), refs[b], rtol=0, atol=1e-12)


# ------------------------------------------------------------------ keys, saves
def test_pc_dim_xy_alone_is_square_and_x_y_override():
    assert PoseCellParams(pc_dim_xy=30).dims == (30, 30, 36)
    assert PoseCellParams(pc_dim_xy=30, pc_dim_x=40).dims == (40, 30, 36)
    assert PoseCellParams(pc_dim_x=100, pc_dim_y=40).dims == (100, 40, 36)
    assert PoseCellParams(pc_dim_xy=40, pc_dim_x=100, pc_dim_y=40).dims == (100, 40, 36)
    with pytest.raises(ConfigError, match="pc_dim_xy = 30 contradicts pc_dim_x = 100"):
        PoseCellParams(pc_dim_xy=30, pc_dim_x=100, pc_dim_y=40)
    with pytest.raises(ConfigError, match="pc_dim_x"):
        PoseCellParams(pc_dim_x=-1)
    cfg = RatSLAMConfig.from_flat({"pc_dim_x": 100, "pc_dim_y": 40})
    assert PoseCellNetwork(cfg.pose_cells).activity.shape == (1, 36, 40, 100)


def test_a_square_network_set_either_way_steps_the_same_bits():
    a = PoseCellNetwork(PoseCellParams(pc_dim_xy=9, pc_dim_th=8))
    b = PoseCellNetwork(PoseCellParams(pc_dim_x=9, pc_dim_y=9, pc_dim_th=8, pc_dim_xy=9))
    for vt, vr in ((0.4, 0.3), (0.9, -0.2), (0.5, 0.0)):
        assert a.step(vt, vr, 1.0).tolist() == b.step(vt, vr, 1.0).tolist()
    assert torch.equal(a.activity, b.activity)


def _stage(**kw) -> PoseCells:
    return PoseCells(PoseCellParams(**kw))


def _drive(pc: PoseCells, n: int) -> None:
    for i in range(n):
        pc.on_view_template(ViewMatch(template_id=i % 4, is_new=i < 4, relative_rad=0.0))
        pc.on_odometry(0.3, 0.05, 1.0)


def test_the_stage_state_carries_the_shape_and_round_trips():
    pc = _stage(pc_dim_x=11, pc_dim_y=7, pc_dim_th=12)
    _drive(pc, 12)
    state = pc.get_state()
    assert (state["pc_dim_x"], state["pc_dim_y"]) == (11, 7)
    assert state["activity"].shape == (12, 7, 11)
    record = PoseCellState.from_dict(state)
    assert (record.pc_dim_x, record.pc_dim_y) == (11, 7)
    again = _stage(pc_dim_x=11, pc_dim_y=7, pc_dim_th=12)
    again.set_state(record.to_dict())
    _drive(pc, 5)
    _drive(again, 5)
    assert np.array_equal(pc.get_state()["activity"], again.get_state()["activity"])
    with pytest.raises(MapFormatError, match="pc_dim_y=7, this module has pc_dim_y=11"):
        _stage(pc_dim_xy=11, pc_dim_th=12).set_state(state)


def test_a_square_save_has_no_new_keys_and_an_older_save_loads():
    pc = _stage(pc_dim_xy=9, pc_dim_th=12)
    _drive(pc, 6)
    state = pc.get_state()
    assert "pc_dim_x" not in state and "pc_dim_y" not in state
    # an older save (pc_dim_xy only) loads into the square network it describes ...
    again = _stage(pc_dim_x=9, pc_dim_y=9, pc_dim_th=12)
    again.set_state(state)
    assert np.array_equal(again.get_state()["activity"], state["activity"])
    # ... and is refused by a rectangular one
    with pytest.raises(MapFormatError, match="pc_dim_xy=9, this module has pc_dim_x=13"):
        _stage(pc_dim_x=13, pc_dim_y=9, pc_dim_th=12).set_state(state)


def test_experience_distances_wrap_per_axis():
    """The stage measures an experience's distance on its own torus: one cell across the
    y wrap (5 cells) is one cell; 2 cells in x on a ring of 7 stay 2."""
    pc = _stage(pc_dim_x=7, pc_dim_y=5, pc_dim_th=6)
    assert pc.dims == (7, 5, 6)
    cells = np.array([[3.0, 4.5, 2.0], [6.5, 2.0, 2.0], [4.5, 2.0, 2.0], [3.0, 2.5, 2.0]])
    state = {
        "template_pc": np.zeros((1, 3)),
        "exp_pc": cells,
        "exp_template": np.zeros(4, np.int64),
        "best": np.array([0.5, 0.5, 2.0]),
    }
    pc.set_state(state)
    # brute force: per axis the shorter way round its own ring, then Euclidean
    for cell, d in zip(cells, pc._delta_pc(cells), strict=True):
        gaps = [ring_gap(cell[a], (0.5, 0.5, 2.0)[a], n) for a, n in enumerate((7, 5, 6))]
        assert d == pytest.approx(math.hypot(*gaps))
    assert pc._delta_pc(cells)[0] == pytest.approx(math.hypot(2.5, 1.0))
