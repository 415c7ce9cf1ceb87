"""Pose cells in OpenRatSLAM's behaviour (the defaults) against OpenRatSLAM itself.

``tests/data/openratslam/*.csv`` are OpenRatSLAM's own ``PosecellNetwork`` (compiled,
unmodified, driven by ``pc_replay``) on (template id, relative angle, odometry)
sequences from the project's simulated tours (see the README there). The module must
give the same action and current experience on every frame, and in float64 the same
packet centre within 1e-9 cells. Each behaviour is also checked on its own against a
brute-force transcription of OpenRatSLAM's loops (``path_integration``, ``find_best``,
``on_view_template``).
"""

from __future__ import annotations

import configparser
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from torchratslam.config import PoseCellParams
from torchratslam.errors import ConfigError
from torchratslam.messages import ViewMatch
from torchratslam.pose_cells.network import PoseCellNetwork
from torchratslam.pose_cells.stage import PoseCells

DATA = Path(__file__).resolve().parents[2] / "data" / "openratslam"
TRACES = ("irat_like", "loop_default", "fast_turns")
F64 = torch.float64


def load_trace(name: str) -> tuple[PoseCellParams, np.ndarray]:
    cp = configparser.ConfigParser()
    cp.read(DATA / f"{name}.txt")
    rows = np.loadtxt(DATA / f"{name}.csv", delimiter=",", skiprows=1)
    return PoseCellParams(**dict(cp["ratslam"])), rows


def replay(p: PoseCellParams, rows: np.ndarray, **kw) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drive PoseCells like pc_replay: template every row, odometry from row 1 on."""
    pc = PoseCells(p, **kw)
    acts, exps, centres = [], [], []
    for frame, vt, rad, v, w, dt in rows[:, :6]:
        pc.on_view_template(ViewMatch(template_id=int(vt), relative_rad=float(rad)))
        act = 0
        if frame > 0 and dt > 0:
            act = int(pc.on_odometry(float(v), float(w), float(dt)).kind)
        acts.append(act)
        exps.append(pc.current_exp)
        centres.append(pc.centre)
    return np.array(acts), np.array(exps), np.array(centres)


@pytest.mark.parametrize("name", TRACES)
def test_float64_reproduces_openratslam_actions_and_centres(name):
    p, rows = load_trace(name)
    acts, exps, centres = replay(p, rows, dtype=F64)
    assert (acts == rows[:, 9]).all(), np.flatnonzero(acts != rows[:, 9])[:5]
    assert (exps[1:] == rows[1:, 10]).all()
    assert (acts > 0).sum() > 100  # the trace does exercise the action rule
    np.testing.assert_allclose(centres[1:], rows[1:, 6:9], rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", TRACES)
def test_float32_gives_openratslam_actions(name):
    p, rows = load_trace(name)
    acts, exps, _ = replay(p, rows, dtype=torch.float32)
    assert (acts == rows[:, 9]).all()
    assert (exps[1:] == rows[1:, 10]).all()


def test_the_torch_methods_reproduce_the_trace_too():
    p, rows = load_trace("fast_turns")
    for method in ("crop", "separable"):
        acts, _, centres = replay(p, rows[:150], dtype=F64, method=method)
        assert (acts == rows[:150, 9]).all()
        np.testing.assert_allclose(centres[1:], rows[1:150, 6:9], rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    ("name", "change"),
    [
        ("irat_like", {"pc_wrap": "preserve_mass"}),
        ("fast_turns", {"vt_inject_rule": "last_10"}),
        ("loop_default", {"pc_decode": "exact"}),
        ("fast_turns", {"pc_axis": "math"}),
    ],
)
def test_each_project_choice_departs_from_the_trace(name, change):
    """The traces can tell each behaviour apart (so the tests above can fail)."""
    p, rows = load_trace(name)
    acts, _, centres = replay(p.replace(**change), rows, dtype=F64)
    assert (acts != rows[:, 9]).any() or np.abs(centres[1:] - rows[1:, 6:9]).max() > 0.1


# ------------------------------------------------------ brute-force transcriptions
def cpp_rot90(layer: np.ndarray, rot: int) -> np.ndarray:
    """OpenRatSLAM's rot90_square, one cell at a time."""
    n = layer.shape[0]
    rot %= 4
    out = layer.copy()
    for _ in range(rot):
        src = out.copy()
        for j in range(n):
            for i in range(n):
                out[i][n - 1 - j] = src[j][i]  # (j, i) -> (jd, id) = (i, n - 1 - j)
    return out


def cpp_path_integration(a: np.ndarray, vtrans: float, vrot: float, cell: float) -> np.ndarray:
    """posecell_network.cpp's path_integration, loop for loop (a: (TH, Y, X))."""
    n_t, n, _ = a.shape
    a = a.copy()
    size_th = 2.0 * math.pi / n_t
    vtrans /= cell
    add = 0.0
    if vtrans < 0:
        vtrans, add = -vtrans, math.pi
    for k in range(n_t):
        d = k * size_th + add
        q = math.floor(d * 2.0 / math.pi)
        r = cpp_rot90(a[k], q)
        d90 = d - math.floor(d * 2 / math.pi) * math.pi / 2
        sw = vtrans * vtrans * math.cos(d90) * math.sin(d90)
        se = vtrans * math.sin(d90) * (1.0 - vtrans * math.cos(d90))
        nw = vtrans * math.cos(d90) * (1.0 - vtrans * math.sin(d90))
        ne = 1.0 - sw - se - nw
        p1 = np.zeros((n + 2, n + 2))
        p1[1 : n + 1, 1 : n + 1] = r
        p2 = np.zeros((n + 2, n + 2))
        for j in range(n + 2):
            for i in range(n + 2):
                p2[j][i] = (
                    p1[j][i] * ne
                    + p1[j][i - 1 if i > 0 else n + 1] * se
                    + p1[j - 1 if j > 0 else n + 1][i] * nw
                    + p1[j - 1 if j > 0 else n + 1][i - 1 if i > 0 else n + 1] * sw
                )
        r = p2[1 : n + 1, 1 : n + 1].copy()
        for i in range(1, n):  # the wrap-back loops start at 1: two cells are dropped
            r[0][i] += p2[n + 1][i + 1]
        for j in range(1, n):
            r[j][0] += p2[j + 1][n + 1]
        r[0][0] += p2[n + 1][n + 1]
        a[k] = cpp_rot90(r, 4 - q)
    if vrot != 0:
        w = abs(vrot) / size_th
        while w > 1:
            w -= 1
        if w == 0:
            w = 1.0
        sign = -1 if vrot < 0 else 1
        s1 = int(sign * math.floor(abs(vrot) / size_th))
        s2 = int(sign * math.ceil(abs(vrot) / size_th))
        while s1 > 0:
            s1 -= n_t
        while s2 > 0:
            s2 -= n_t
        old = a.copy()
        for k in range(n_t):
            a[k] = old[(k - s1) % n_t] * (1.0 - w) + old[(k - s2) % n_t] * w
    return a


def cpp_find_best(a: np.ndarray, avg: int = 3) -> tuple[float, float, float]:
    """posecell_network.cpp's find_best, loop for loop."""
    n_t, n, _ = a.shape
    best, x, y, th = 0.0, 0, 0, 0
    for k in range(n_t):
        for j in range(n):
            for i in range(n):
                if a[k][j][i] > best:
                    best, x, y, th = a[k][j][i], i, j, k
    xs, ys, zs = np.zeros(n), np.zeros(n), np.zeros(n_t)
    for k in range(th, th + 2 * avg + 1):
        for j in range(y, y + 2 * avg + 1):
            for i in range(x, x + 2 * avg + 1):
                kw, jw, iw = (k - avg) % n_t, (j - avg) % n, (i - avg) % n
                zs[kw] += a[kw][jw][iw]
                ys[jw] += a[kw][jw][iw]
                xs[iw] += a[kw][jw][iw]
    out = []
    for sums, m in ((xs, n), (ys, n), (zs, n_t)):
        s1 = s2 = 0.0
        for i in range(m):
            s1 += math.sin((i + 1) * 2.0 * math.pi / m) * sums[i]
            s2 += math.cos((i + 1) * 2.0 * math.pi / m) * sums[i]
        v = math.atan2(s1, s2) * m / (2.0 * math.pi) - 1.0
        while v < 0:
            v += m
        while v > m:
            v -= m
        out.append(v)
    return out[0], out[1], out[2]


def test_path_integration_is_openratslams_loops_including_the_edge_loss():
    """Packets on the x/y edges and corners of a 7 x 7 x 8 network, moved forwards and
    backwards on every layer: the one-cell move with the reference's axes and its
    dropped edge cells, equal to the transcribed loops; the mass really is lost."""
    p = PoseCellParams(pc_dim_xy=7, pc_dim_th=8)
    net = PoseCellNetwork(p, dtype=F64, method="separable")
    rng = np.random.default_rng(5)
    a = rng.random((8, 7, 7)) * (rng.random((8, 7, 7)) < 0.5)
    a[:, 0, 0] = a[:, 0, 6] = a[:, 6, 0] = a[:, 6, 6] = 0.5  # every corner active
    for vtrans, vrot in ((0.4, 0.0), (-0.7, 0.3), (0.9, -1.7), (1.4, 2.2)):
        got = net.path_integrate(torch.from_numpy(a)[None], vtrans, vrot / (2 * math.pi / 8))
        want = cpp_path_integration(a, vtrans, vrot, 1.0)
        np.testing.assert_allclose(got[0].numpy(), want, rtol=0, atol=1e-12)
        if vtrans <= 1:
            assert want.sum() < a.sum() - 1e-3  # OpenRatSLAM loses mass at the edges
    keep = PoseCellNetwork(p.replace(pc_wrap="preserve_mass"), dtype=F64, method="separable")
    moved = keep.path_integrate(torch.from_numpy(a)[None], 0.4, 0.0)
    assert abs(float(moved.sum()) - a.sum()) < 1e-12


@pytest.mark.parametrize("method", ["numpy", "crop", "separable"])
def test_a_step_and_its_centre_are_openratslams_loops(method):
    """A whole on_odo (dynamics with the reference's 3D kernel, path integration,
    find_best) on a packet that straddles the corner of the x/y wrap."""
    p = PoseCellParams(pc_dim_xy=11, pc_dim_th=12)
    net = PoseCellNetwork(p, dtype=F64, method=method)
    a = np.zeros((12, 11, 11))
    a[11, 10, 10] = a[0, 0, 0] = 0.5
    net.set_activity(a)
    kern_e, kern_i = cpp_kernel(7, 1), cpp_kernel(5, 2)
    for vtrans, vrot in ((0.0, 0.0), (0.6, 0.2), (-0.8, -0.5), (0.3, 0.9)):
        e = spread(a, kern_e)
        x = e - spread(e, kern_i)
        x = np.where(x >= p.pc_global_inhib, x - p.pc_global_inhib, 0.0)
        a = cpp_path_integration(x / x.sum(), vtrans, vrot, 1.0)
        c = net.step(vtrans, vrot, 1.0)[0].numpy()
        np.testing.assert_allclose(net.activity[0].numpy(), a, rtol=0, atol=1e-12)
        np.testing.assert_allclose(c, cpp_find_best(a), rtol=0, atol=1e-9)


def cpp_kernel(dim: int, var: int) -> np.ndarray:
    w = np.zeros((dim, dim, dim))
    c = dim // 2
    for k in range(dim):
        for j in range(dim):
            for i in range(dim):
                w[k, j, i] = math.exp(-((i - c) ** 2 + (j - c) ** 2 + (k - c) ** 2) / (2 * var**2))
    return w / w.sum()


def spread(a: np.ndarray, w: np.ndarray) -> np.ndarray:
    out = np.zeros_like(a)
    c = w.shape[0] // 2
    offs = np.arange(w.shape[0]) - c
    for k, j, i in zip(*np.nonzero(a), strict=True):
        tk, tj, ti = (k + offs) % a.shape[0], (j + offs) % a.shape[1], (i + offs) % a.shape[2]
        np.add.at(out, np.ix_(tk, tj, ti), a[k, j, i] * w)
    return out


def test_a_centre_on_a_cell_decodes_just_below_it_and_injects_one_cell_lower():
    p = PoseCellParams(pc_dim_xy=21, pc_dim_th=36)
    net = PoseCellNetwork(p, dtype=F64)
    c = net.step(0.0, 0.0, 1.0)[0].tolist()  # the start packet: symmetric about (10, 10, 18)
    assert c == list(cpp_find_best(net.activity[0].numpy()))
    assert c[0] < 10.0 and int(c[0]) == 9  # 9.999999999999998: truncation gives cell 9
    exact = PoseCellNetwork(p.replace(pc_decode="exact"), dtype=F64)
    assert abs(exact.step(0.0, 0.0, 1.0)[0, 0].item() - 10.0) < 1e-12


@pytest.mark.parametrize(("rule", "injects"), [("openratslam", True), ("last_10", False)])
def test_templates_inject_while_fewer_than_ten_exist_only_in_the_reference(rule, injects):
    p = PoseCellParams(vt_inject_rule=rule, pc_vt_inject_energy=0.5)
    pc = PoseCells(p, dtype=F64)
    for vt in range(3):  # three templates learnt, one step apart
        pc.on_view_template(ViewMatch(template_id=vt))
        pc.on_odometry(1.0, 0.0, 1.0)
    before = pc.activity.clone()
    pc.on_view_template(ViewMatch(template_id=0))  # template 0 seen again
    x, y, th = (int(v) for v in pc.template_pc[0])
    added = float(pc.activity[th, y, x] - before[th, y, x])
    if injects:  # energy 0.5 / 30 * (30 - e^1.2)
        assert added == pytest.approx(0.5 / 30.0 * (30.0 - math.exp(1.2)), abs=1e-12)
    else:
        assert added == 0.0


def test_the_edge_loss_needs_one_cell_steps():
    with pytest.raises(ConfigError, match="pc_multi_cell"):
        PoseCellParams(pc_multi_cell=True)
    PoseCellParams(pc_multi_cell=True, pc_wrap="preserve_mass")
