"""The pose-cell network and module against brute-force references and invariants."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import torchratslam.pipeline.defaults  # noqa: F401  (registers the default stages)
from torchratslam.config import PoseCellParams
from torchratslam.errors import ConfigError, InputError, MapFormatError
from torchratslam.messages import ActionKind, ViewMatch
from torchratslam.pose_cells.network import METHODS, PoseCellNetwork
from torchratslam.pose_cells.stage import PoseCells
from torchratslam.registry import POSE_CELLS

F64 = torch.float64

#: The project's own pose-cell behaviours (the ``torchratslam`` profile): the tests in
#: this file check them; OpenRatSLAM's (the defaults) are checked against its own traces
#: in test_openratslam_traces.py.
PROJECT = {
    "pc_decode": "exact",
    "vt_inject_rule": "last_10",
    "pc_axis": "math",
    "pc_wrap": "preserve_mass",
    "pc_multi_cell": True,
}


def _params(**kw) -> PoseCellParams:
    return PoseCellParams(**{**PROJECT, **kw})


# ----------------------------------------------------------------- references
def brute_kernel(dim: int, var: float) -> np.ndarray:
    """3D weights straight from the definition: exp(-(i^2+j^2+k^2) / (2 var^2)) around
    the centre index dim // 2, normalised; axes (th, y, x)."""
    w = np.zeros((dim, dim, dim))
    c = dim // 2
    for k in range(dim):
        for j in range(dim):
            for i in range(dim):
                w[k, j, i] = math.exp(
                    -((i - c) ** 2 + (j - c) ** 2 + (k - c) ** 2) / (2 * var * var)
                )
    return w / w.sum()


def brute_spread(a: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Every non-zero cell spreads its activity through the kernel, with wrap (the
    triple loop over cells of the reference implementation)."""
    out = np.zeros_like(a)
    nt, ny, nx = a.shape
    c = w.shape[0] // 2
    offs = np.arange(w.shape[0]) - c
    for k in range(nt):
        for j in range(ny):
            for i in range(nx):
                if a[k, j, i] != 0:
                    tk = (k + offs) % nt
                    tj = (j + offs) % ny
                    ti = (i + offs) % nx
                    np.add.at(out, np.ix_(tk, tj, ti), a[k, j, i] * w)
    return out


def brute_dynamics(a: np.ndarray, p: PoseCellParams) -> np.ndarray:
    e = brute_spread(a, brute_kernel(p.pc_w_e_dim, p.pc_w_e_var))
    x = e - brute_spread(e, brute_kernel(p.pc_w_i_dim, p.pc_w_i_var))
    x = np.where(x >= p.pc_global_inhib, x - p.pc_global_inhib, 0.0)
    return x / x.sum()


def ring_delta(a, b, n):
    """Signed shortest difference b - a on a ring of n."""
    return (np.asarray(b) - np.asarray(a) + n / 2) % n - n / 2


def packet_net(p: PoseCellParams, cell=None, *, method="crop", dtype=F64, settle=20, batch=1):
    """A network with a settled packet at ``cell`` (x, y, th)."""
    net = PoseCellNetwork(p, batch, dtype=dtype, method=method)
    if cell is not None:
        a = torch.zeros_like(net.activity)
        x, y, th = cell
        a[:, th, y, x] = 1.0
        net.set_activity(a)
    for _ in range(settle):
        net.step(0.0, 0.0, 1.0)
    return net


# ------------------------------------------------------------------- dynamics
@pytest.mark.parametrize("method", ["separable", "conv3d"])
@pytest.mark.parametrize(("e_dim", "i_dim"), [(7, 5), (5, 4)])
def test_excite_and_inhibit_equal_brute_force_triple_loop(method, e_dim, i_dim):
    p = _params(pc_dim_xy=9, pc_dim_th=10, pc_w_e_dim=e_dim, pc_w_i_dim=i_dim, pc_w_i_var=1.7)
    net = PoseCellNetwork(p, dtype=F64, method=method)
    rng = np.random.default_rng(0)
    a = rng.random((10, 9, 9)) * (rng.random((10, 9, 9)) < 0.3)
    e = net.excite(torch.from_numpy(a)[None])[0].numpy()
    ref_e = brute_spread(a, brute_kernel(e_dim, 1.0))
    np.testing.assert_allclose(e, ref_e, rtol=0, atol=1e-12)
    i = net.inhibit(torch.from_numpy(ref_e)[None])[0].numpy()
    ref_i = ref_e - brute_spread(ref_e, brute_kernel(i_dim, 1.7))
    np.testing.assert_allclose(i, ref_i, rtol=0, atol=1e-12)


@pytest.mark.parametrize("method", METHODS)
def test_a_step_without_motion_equals_brute_force_dynamics(method):
    p = _params(pc_dim_xy=13, pc_dim_th=16)
    net = PoseCellNetwork(p, dtype=F64, method=method)
    rng = np.random.default_rng(1)
    a = np.zeros((16, 13, 13))
    a[2:7, 10:13, 0:4] = rng.random((5, 3, 4))  # a packet across the x wrap edge
    a[14, 1, 12] = 0.3  # and a stray cell across the theta/y edges
    a /= a.sum()
    net.set_activity(a)
    for _ in range(3):
        net.step(0.0, 0.0, 1.0)
        a = brute_dynamics(a, p)
        np.testing.assert_allclose(net.activity[0].numpy(), a, rtol=0, atol=1e-12)


def test_crop_equals_full_network_also_when_packets_split_and_rejoin():
    p = _params(pc_dim_xy=31, pc_dim_th=36)
    nets = {m: packet_net(p, (29, 1, 35), method=m, settle=5) for m in ("crop", "separable")}
    rng = np.random.default_rng(2)
    crops = set()
    for t in range(60):
        v, w = rng.uniform(-1.5, 1.5), rng.uniform(-0.4, 0.4)
        if t % 10 == 5:  # now and then a jump of several cells in x/y and in theta
            v, w = 4.7, -1.3
        for net in nets.values():
            if t in (10, 11, 12):
                net.inject(12, 20, 5, 0.4)  # a second packet far away: the crop must grow
            net.step(v, w, 1.0)
        crops.add(nets["crop"].last_crop)
        np.testing.assert_allclose(
            nets["crop"].activity.numpy(), nets["separable"].activity.numpy(), rtol=0, atol=1e-12
        )
        np.testing.assert_allclose(
            nets["crop"].centre().numpy(), nets["separable"].centre().numpy(), atol=1e-9
        )
    assert (36, 31, 31) in crops and min(c[1] for c in crops) < 31  # both paths were used


@pytest.mark.parametrize("method", ["crop", "separable"])
def test_activity_stays_non_negative_and_sums_to_one(method):
    p = _params(pc_dim_xy=15, pc_dim_th=20)
    net = PoseCellNetwork(p, 2, dtype=torch.float32, method=method)
    rng = np.random.default_rng(3)
    for t in range(80):
        if t % 7 == 0:
            net.inject(
                rng.integers(0, 15, 2), rng.integers(0, 15, 2), rng.integers(0, 20, 2), [0.2, 0.0]
            )
        net.step(rng.uniform(-2, 2, 2), rng.uniform(-1, 1, 2), 1.0)
        a = net.activity
        assert bool((a >= 0).all())
        np.testing.assert_allclose(a.sum(dim=(1, 2, 3)).numpy(), 1.0, atol=1e-5)


def test_packet_without_input_stays_put():
    p = _params()  # 21 x 21 x 36
    net = PoseCellNetwork(p, dtype=F64)
    start = net.step(0.0, 0.0, 1.0)[0].numpy()
    for _ in range(200):
        c = net.step(0.0, 0.0, 1.0)[0].numpy()
    d = ring_delta(start, c, np.array([21, 21, 36]))
    assert np.abs(d).max() < 0.05
    assert c == pytest.approx([10, 10, 18], abs=0.05)  # the start cell floor(dim/2)


# ----------------------------------------------------------- path integration
def reference_four_neighbour(layer: np.ndarray, v: float, direction: float) -> np.ndarray:
    """OpenRatSLAM's scheme for one layer: rotate by quarter turns so the heading lies
    in [0, pi/2), spread to the four neighbours with rectangle weights, rotate back."""
    q = math.floor(direction * 2 / math.pi)
    d90 = direction - q * math.pi / 2
    c, s = v * math.cos(d90), v * math.sin(d90)
    weights = {(0, 0): (1 - c) * (1 - s), (1, 0): c * (1 - s), (0, 1): (1 - c) * s, (1, 1): c * s}
    out = np.zeros_like(layer)
    for (dx, dy), w in weights.items():
        for _ in range(q % 4):  # rotate the offset back by q quarter turns
            dx, dy = -dy, dx
        out += w * np.roll(layer, (dy, dx), axis=(0, 1))
    return out


@pytest.mark.parametrize("v", [0.37, 1.0, -0.8])
def test_translation_up_to_one_cell_equals_the_four_neighbour_weighting(v):
    p = _params(pc_dim_xy=11, pc_dim_th=12)
    net = PoseCellNetwork(p, dtype=F64)
    a = np.random.default_rng(4).random((12, 11, 11))
    out = net.path_integrate(torch.from_numpy(a)[None], v, 0.0)[0].numpy()
    for k in range(12):
        direction = k * 2 * math.pi / 12 + (math.pi if v < 0 else 0.0)
        ref = reference_four_neighbour(a[k], abs(v), direction)
        np.testing.assert_allclose(out[k], ref, rtol=0, atol=1e-12)


def test_large_translation_is_a_roll_plus_bilinear_fraction():
    p = _params(pc_dim_xy=11, pc_dim_th=8)
    net = PoseCellNetwork(p, dtype=F64)
    a = np.random.default_rng(5).random((8, 11, 11))
    v = 3.6
    out = net.path_integrate(torch.from_numpy(a)[None], v, 0.0)[0].numpy()
    for k in range(8):
        sx, sy = v * math.cos(k * math.pi / 4), v * math.sin(k * math.pi / 4)
        fx, fy = math.floor(sx), math.floor(sy)
        ax, ay = sx - fx, sy - fy
        ref = sum(
            w * np.roll(a[k], (fy + oy, fx + ox), axis=(0, 1))
            for (ox, oy), w in {
                (0, 0): (1 - ax) * (1 - ay),
                (1, 0): ax * (1 - ay),
                (0, 1): (1 - ax) * ay,
                (1, 1): ax * ay,
            }.items()
        )
        np.testing.assert_allclose(out[k], ref, rtol=0, atol=1e-12)


def test_theta_shift_is_linear_interpolation_between_floor_and_ceil():
    p = _params(pc_dim_xy=5, pc_dim_th=12)
    net = PoseCellNetwork(p, dtype=F64)
    a = np.random.default_rng(6).random((12, 5, 5))
    for s in (0.3, 2.75, -1.4, 13.5):
        out = net.path_integrate(torch.from_numpy(a)[None], 0.0, s)[0].numpy()
        f = math.floor(s)
        ref = (1 - (s - f)) * np.roll(a, f, axis=0) + (s - f) * np.roll(a, f + 1, axis=0)
        np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12)


@pytest.mark.parametrize("layer", [0, 4, 9, 13, 18, 22, 27, 31])  # 8+ headings of 36 layers
@pytest.mark.parametrize("speed", [0.4, 1.6])  # cells per step, below and above one
def test_constant_odometry_moves_the_centre_along_the_layer_heading(layer, speed):
    p = _params(pc_dim_xy=21, pc_dim_th=36)
    net = packet_net(p, (18, 2, layer), settle=15)  # near the x/y edges: it crosses the wrap
    c = net.centre()[0].numpy()
    steps = 12
    d = np.zeros(3)
    for _ in range(steps):  # sum the per-step moves: the total exceeds half the ring
        c, c_prev = net.step(speed, 0.0, 1.0)[0].numpy(), c
        d += ring_delta(c_prev, c, np.array([21, 21, 36]))
    heading = layer * 2 * math.pi / 36
    expected = speed * steps * np.array([math.cos(heading), math.sin(heading)])
    # the packet spans a few theta layers, so it moves slightly slower than one layer
    assert np.linalg.norm(d[:2] - expected) < 0.08 * speed * steps
    # layers either side of the packet's heading get different bilinear blur at
    # fractional shifts, so theta creeps a little (about 0.01 cell per step at 1.6)
    assert abs(d[2]) < 0.02 * steps
    assert np.hypot(*d[:2]) > 0.9 * speed * steps


def test_negative_speed_moves_backwards():
    p = _params(pc_dim_xy=21, pc_dim_th=36)
    net = packet_net(p, (10, 10, 9), settle=15)  # heading 90 degrees: +y
    c0 = net.centre()[0].numpy()
    for _ in range(10):
        c = net.step(-0.5, 0.0, 1.0)[0].numpy()
    d = ring_delta(c0, c, np.array([21, 21, 36]))
    assert d[1] == pytest.approx(-5.0, abs=0.4) and abs(d[0]) < 0.2


def test_rotation_moves_theta_by_vrot_dt_and_full_turns_return():
    p = _params(pc_dim_xy=11, pc_dim_th=36)
    net = packet_net(p, settle=10)
    c0 = net.centre()[0].numpy()
    vrot = 2 * math.pi / 36 * 0.75  # 0.75 theta cells per second
    c = net.step(0.0, vrot, 2.0)[0].numpy()  # dt = 2 s: 1.5 cells
    assert ring_delta(c0[2], c[2], 36) == pytest.approx(1.5, abs=0.03)
    for _ in range(23):  # 24 steps of 1.5 cells: one full turn
        c = net.step(0.0, vrot, 2.0)[0].numpy()
    assert abs(ring_delta(c0[2], c[2], 36)) < 0.1
    for _ in range(16):  # two more turns backwards, 4.5 cells per step
        c = net.step(0.0, -vrot * 3, 2.0)[0].numpy()
    assert abs(ring_delta(c0[2], c[2], 36)) < 0.1
    assert np.abs(ring_delta(c0[:2], c[:2], 11)).max() < 0.05


def test_repeated_injection_relocalises_the_packet():
    p = _params()
    net = packet_net(p, settle=5)
    target = (3, 17, 30)
    for _ in range(40):
        net.inject(*target, 0.15)
        c = net.step(0.0, 0.0, 1.0)[0].numpy()
    d = ring_delta(np.array(target, dtype=float), c, np.array([21, 21, 36]))
    assert np.abs(d).max() < 0.5


# ---------------------------------------------------------- batch and dtypes
@pytest.mark.parametrize("method", ["crop", "separable"])
def test_batched_equals_looped(method):
    p = _params(pc_dim_xy=17, pc_dim_th=24)
    b = 4
    rng = np.random.default_rng(7)
    vt, vr, dt = (
        rng.uniform(-2, 2, (30, b)),
        rng.uniform(-0.5, 0.5, (30, b)),
        rng.uniform(0.5, 1.5, (30, b)),
    )
    batched = PoseCellNetwork(p, b, dtype=F64, method=method)
    singles = [PoseCellNetwork(p, 1, dtype=F64, method=method) for _ in range(b)]
    for t in range(30):
        if t % 5 == 2:
            cell = rng.integers(0, [17, 17, 24], (b, 3))
            energy = rng.uniform(0, 0.3, b) * (rng.random(b) < 0.6)
            batched.inject(cell[:, 0], cell[:, 1], cell[:, 2], energy)
            for i, net in enumerate(singles):
                net.inject(int(cell[i, 0]), int(cell[i, 1]), int(cell[i, 2]), float(energy[i]))
        cb = batched.step(torch.from_numpy(vt[t]), vr[t], dt[t])
        for i, net in enumerate(singles):
            ci = net.step(vt[t, i], vr[t, i], dt[t, i])
            np.testing.assert_allclose(cb[i].numpy(), ci[0].numpy(), atol=1e-9)
            np.testing.assert_allclose(
                batched.activity[i].numpy(), net.activity[0].numpy(), atol=1e-12
            )


def test_float32_agrees_with_float64():
    p = _params()
    nets = [PoseCellNetwork(p, dtype=d) for d in (torch.float32, F64)]
    rng = np.random.default_rng(8)
    for _ in range(100):
        v, w = rng.uniform(0, 1.2), rng.uniform(-0.3, 0.3)
        c32, c64 = (n.step(v, w, 1.0)[0].numpy() for n in nets)
        # stated tolerance: 1e-3 cells on the centre, 1e-5 on any cell's activity
        assert np.abs(ring_delta(c64, c32, np.array([21, 21, 36]))).max() < 1e-3
    diff = (nets[0].activity.double() - nets[1].activity).abs().max().item()
    assert diff < 1e-5


def test_bad_arguments_are_clear_errors():
    p = _params(pc_dim_xy=7, pc_dim_th=8)
    with pytest.raises(ConfigError, match="method"):
        PoseCellNetwork(p, method="fft")
    with pytest.raises(ConfigError, match="batch_size"):
        PoseCellNetwork(p, 0)
    net = PoseCellNetwork(p, 2)
    with pytest.raises(InputError, match=r"vtrans.*\(2,\)"):
        net.step([1.0, 2.0, 3.0], 0.0, 1.0)
    with pytest.raises(InputError, match="finite"):
        net.step(float("nan"), 0.0, 1.0)
    with pytest.raises(MapFormatError, match="shape"):
        net.set_activity(np.zeros((8, 7, 6)))
    dead = PoseCellNetwork(p.replace(pc_global_inhib=1.0))
    with pytest.raises(InputError, match="died out"):
        dead.step(0.0, 0.0, 1.0)


# ------------------------------------------------------------ PoseCells module
class ReferenceRule:
    """The pose-cell bookkeeping and action rule, written from the algorithm notes,
    fed with the centres of the module under test."""

    def __init__(self, p: PoseCellParams):
        self.p = p
        self.dims = np.array([p.pc_dim_xy, p.pc_dim_xy, p.pc_dim_th], dtype=float)
        self.tpl_pc, self.decay, self.exp_pc, self.exp_vt = [], [], [], []
        self.cur_exp, self.cur_vt, self.prev_vt, self.delta_th, self.rad = -1, -1, -1, 0.0, 0.0
        self.injections = []

    def view(self, vt, rad, centre):
        p = self.p
        self.rad = rad
        if vt == len(self.tpl_pc):
            self.tpl_pc.append(list(centre))
            self.decay.append(p.vt_active_decay)
        elif vt < len(self.tpl_pc) - 10:
            if vt == self.cur_vt:
                self.decay[vt] += p.vt_active_decay
            energy = p.pc_vt_inject_energy / 30 * (30 - math.exp(1.2 * self.decay[vt]))
            if energy > 0:
                self.delta_th = rad / (2 * math.pi) * p.pc_dim_th
                th = (self.tpl_pc[vt][2] + self.delta_th) % p.pc_dim_th
                self.injections.append(
                    (int(self.tpl_pc[vt][0]), int(self.tpl_pc[vt][1]), int(th), energy)
                )
        self.decay = [max(d - p.pc_vt_restore, p.vt_active_decay) for d in self.decay]
        self.prev_vt, self.cur_vt = self.cur_vt, vt

    def dist(self, e, centre):
        c = np.array(centre, dtype=float)
        c[2] = (c[2] - self.delta_th) % self.dims[2]
        d = np.abs(np.array(self.exp_pc[e]) - c)
        d = np.minimum(d, self.dims - d)
        return float(np.sqrt((d * d).sum()))

    def create(self, centre):
        src = self.cur_exp
        self.exp_pc.append(list(centre))
        self.exp_vt.append(self.cur_vt)
        self.cur_exp = len(self.exp_pc) - 1
        return ("CREATE", self.cur_exp, src)

    def action(self, centre):
        if not self.tpl_pc:
            return ("NONE", -1, -1)
        if not self.exp_pc:
            return self.create(centre)
        mine = [e for e in range(len(self.exp_pc)) if self.exp_vt[e] == self.cur_vt]
        if not mine:
            return self.create(centre)
        if (
            self.dist(self.cur_exp, centre) > self.p.exp_delta_pc_threshold
            or self.cur_vt != self.prev_vt
        ):
            best, best_d = -1, math.inf
            for e in mine:
                if e != self.cur_exp and self.dist(e, centre) < best_d:
                    best, best_d = e, self.dist(e, centre)
            if best >= 0 and best_d < self.p.exp_delta_pc_threshold:
                src, self.cur_exp = self.cur_exp, best
                return ("LINK", best, src)
            return self.create(centre)
        return ("NONE", -1, -1)


def scripted_views(n: int, seed: int):
    """A loop-like template stream: new places, then revisits (with relative angles)."""
    rng = np.random.default_rng(seed)
    known = 0
    for t in range(n):
        if known < 14 or rng.random() < 0.3:
            yield t, ViewMatch(known, is_new=True), (0.6, 0.15)
            known += 1
        else:
            vt = int(rng.integers(0, max(known - 8, 1)))
            yield t, ViewMatch(vt, relative_rad=float(rng.uniform(-0.5, 0.5))), (0.6, 0.15)


def test_module_follows_the_reference_bookkeeping_and_action_rule():
    p = _params(pc_dim_xy=15, pc_dim_th=36, exp_delta_pc_threshold=2.0, pc_vt_inject_energy=0.3)
    pc = PoseCells(p, dtype=F64)
    ref = ReferenceRule(p)
    got_inj = []
    original = pc.network.inject
    pc.network.inject = lambda x, y, th, e: (got_inj.append((x, y, th, e)), original(x, y, th, e))
    kinds = set()
    for _t, match, (v, w) in scripted_views(160, seed=9):
        ref.view(match.template_id, match.relative_rad, pc.centre)
        pc.on_view_template(match)
        action = pc.on_odometry(v, w, 1.0)
        want = ref.action(pc.centre)
        assert (action.kind.name, action.dest_id, action.src_id) == want
        if action.kind != ActionKind.NONE:
            assert action.relative_rad == pytest.approx(match.relative_rad)
        kinds.add(action.kind)
    assert kinds >= {ActionKind.CREATE, ActionKind.LINK, ActionKind.NONE}
    assert [(x, y, th) for x, y, th, _ in got_inj] == [i[:3] for i in ref.injections]
    np.testing.assert_allclose([e for *_, e in got_inj], [i[3] for i in ref.injections])
    assert len(ref.injections) > 10
    np.testing.assert_allclose(pc.template_decay, ref.decay)
    assert pc.current_exp == ref.cur_exp and pc.n_experiences == len(ref.exp_pc)


def test_first_steps_and_recent_templates():
    p = _params(pc_dim_xy=11)
    pc = PoseCells(p, dtype=F64)
    assert pc.on_odometry(0.1, 0.0, 1.0).kind == ActionKind.NONE  # no template yet
    pc.on_view_template(ViewMatch(0, is_new=True))
    assert pc.template_pc[0] == pytest.approx(pc.centre)
    a = pc.on_odometry(0.1, 0.0, 1.0)
    assert (a.kind, a.dest_id, a.src_id) == (ActionKind.CREATE, 0, -1)
    assert pc.on_odometry(0.1, 0.0, 1.0).kind == ActionKind.NONE  # no new view since
    before = pc.activity.clone()
    pc.on_view_template(ViewMatch(0))  # one of the last 10 learnt: no injection
    assert torch.equal(pc.activity, before)
    with pytest.raises(InputError, match="template id 5"):
        pc.on_view_template(ViewMatch(5))


@pytest.mark.parametrize(("xy", "method"), [(15, "auto"), (41, "crop")])
def test_state_round_trip_continues_bit_identically(xy, method):
    p = _params(pc_dim_xy=xy, pc_dim_th=36, pc_vt_inject_energy=0.3)
    stream = list(scripted_views(120, seed=10))
    a = PoseCells(p, method=method)
    for _t, m, (v, w) in stream[:70]:
        a.on_view_template(m)
        a.on_odometry(v, w, 1.0)
    state = a.get_state()
    for key, value in state.items():
        assert isinstance(value, (np.ndarray, int, float, bool)), key
    b = PoseCells(p, method=method)
    b.set_state({k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in state.items()})
    for _t, m, (v, w) in stream[70:]:
        for pc in (a, b):
            pc.on_view_template(m)
        acts = [pc.on_odometry(v, w, 1.0) for pc in (a, b)]
        assert acts[0] == acts[1]
        assert a.centre == b.centre
        assert torch.equal(a.activity, b.activity)
    with pytest.raises(MapFormatError, match="pc_dim_xy"):
        PoseCells(p.replace(pc_dim_xy=xy + 2)).set_state(state)
    with pytest.raises(MapFormatError, match="lacks 'exp_pc'"):
        PoseCells(p).set_state({"template_pc": np.zeros((0, 3))})


def test_state_without_activity_restarts_the_packet_at_the_current_experience():
    p = _params(pc_dim_xy=11)
    pc = PoseCells(p)
    state = {
        "template_pc": np.array([[1.0, 2.0, 3.0], [7.2, 8.9, 30.5]]),
        "exp_pc": np.array([[1.0, 2.0, 3.0], [7.2, 8.9, 30.5]]),
        "exp_template": np.array([0, 1]),
        "current_exp": 1,
        "activity": np.zeros((0, 0, 0)),
    }
    pc.set_state(state)
    assert pc.activity[30, 8, 7] == 1.0 and float(pc.activity.sum()) == 1.0
    assert pc.centre == pytest.approx((7.2, 8.9, 30.5))
    assert pc.template_experiences(1) == [1]


def test_auto_method_crops_only_large_networks():
    assert PoseCellNetwork(_params(pc_dim_xy=11)).method == "separable"
    assert PoseCellNetwork(_params(pc_dim_xy=21)).method == "separable"
    assert PoseCellNetwork(_params(pc_dim_xy=80)).method == "crop"
    assert PoseCellNetwork(_params(pc_dim_xy=21), 32).method == "crop"


def test_crop_notices_activity_written_from_outside():
    p = _params(pc_dim_xy=41, pc_dim_th=36)
    nets = [packet_net(p, (20, 20, 18), method=m, settle=6) for m in ("crop", "separable")]
    for net in nets:
        with torch.no_grad():
            net.activity[0, 2, 37, 3] += 0.4  # e.g. a map merge editing the buffer
        net.step(0.5, 0.1, 1.0)
    assert nets[0].activity[0, 2, 37, 3] > 0  # the far cell was processed, not dropped
    np.testing.assert_allclose(nets[0].activity.numpy(), nets[1].activity.numpy(), atol=1e-12)


def test_registered_as_ratslam():
    assert POSE_CELLS.get("ratslam") is PoseCells


def _brute_centre(act: np.ndarray, c: int) -> tuple[float, float, float]:
    """Population vector of the (2c+1)^3 cube around the first maximum, plain loops."""
    n_t, n_y, n_x = act.shape
    flat = int(np.argmax(act))
    pt, py, px = flat // (n_y * n_x), (flat // n_x) % n_y, flat % n_x
    sums = {"x": [0.0] * n_x, "y": [0.0] * n_y, "t": [0.0] * n_t}
    for dt in range(-c, c + 1):
        for dy in range(-c, c + 1):
            for dx in range(-c, c + 1):
                t, y, x = (pt + dt) % n_t, (py + dy) % n_y, (px + dx) % n_x
                v = float(act[t, y, x])
                sums["x"][x] += v
                sums["y"][y] += v
                sums["t"][t] += v
    out = []
    for key, n in (("x", n_x), ("y", n_y), ("t", n_t)):
        s = sum(w * math.sin(2 * math.pi * i / n) for i, w in enumerate(sums[key]))
        co = sum(w * math.cos(2 * math.pi * i / n) for i, w in enumerate(sums[key]))
        out.append((math.atan2(s, co) * n / (2 * math.pi)) % n)
    return tuple(out)


@pytest.mark.parametrize("seed", range(3))
def test_decoded_centre_equals_brute_force_population_vector_across_the_wrap(seed):
    rng = np.random.default_rng(seed)
    params = _params(pc_dim_xy=11, pc_dim_th=12)
    net = PoseCellNetwork(params, 2, dtype=torch.float64)
    acts = rng.random((2, 12, 11, 11)) * 0.1
    acts[0, 0, 10, 0] = 5.0  # peak on the corner: the cube wraps on every axis
    acts[1, 11, 0, 10] = 5.0
    net.set_activity(acts)
    got = net.centre(recompute=True).numpy()
    for b in range(2):
        want = _brute_centre(acts[b], params.pc_cells_to_avg)
        diff = (got[b] - np.array(want) + np.array([5.5, 5.5, 6.0])) % np.array(
            [11.0, 11.0, 12.0]
        ) - np.array([5.5, 5.5, 6.0])
        assert np.abs(diff).max() < 1e-9


# ------------------------------------------------------- torch module behaviour
@pytest.mark.parametrize("method", ["numpy", "crop", "separable"])
@pytest.mark.parametrize("profile", ["openratslam", "project"])
def test_double_float_and_to_move_the_caches_with_the_activity(method, profile):
    p = PoseCellParams() if profile == "openratslam" else _params()
    net = PoseCellNetwork(p, dtype=torch.float32, method=method)
    ref = PoseCellNetwork(p, dtype=F64, method=method)
    for n in (net, ref):
        n.step(0.4, 0.1, 1.0)  # builds the float32 matrices and scratch buffers
    net.double()
    ref_c = ref.step(0.3, -0.2, 1.0)
    c = net.step(0.3, -0.2, 1.0)
    assert net.activity.dtype == F64 and net.best.dtype == F64
    np.testing.assert_allclose(c.numpy(), ref_c.numpy(), atol=1e-5)
    net.float()
    assert net.activity.dtype == torch.float32 and net.best.dtype == F64
    net.step(0.2, 0.0, 1.0)
    net.to(torch.float64)
    net.inject(3, 4, 5, 0.1)
    net.step(0.2, 0.3, 1.0)
    assert net.activity.dtype == F64
    assert torch.isfinite(net.activity).all() and float(net.activity.sum()) > 0.9


@pytest.mark.parametrize("method", ["numpy", "crop"])
def test_state_dict_round_trips_activity_and_centre(method):
    p = PoseCellParams()
    a = PoseCellNetwork(p, dtype=F64, method=method)
    for t in range(12):
        if t == 5:
            a.inject(2, 3, 30, 0.2)
        a.step(0.7, 0.15, 1.0)
    state = a.state_dict()
    assert set(state) == {"activity", "best"}
    b = PoseCellNetwork(p, dtype=F64, method=method)
    b.load_state_dict(state)
    assert torch.equal(b.centre(), a.centre())  # before any step: the saved centre
    for _ in range(5):
        ca, cb = a.step(-0.5, 0.3, 1.0), b.step(-0.5, 0.3, 1.0)
        assert torch.equal(ca, cb)
        assert torch.equal(a.activity, b.activity)


@pytest.mark.parametrize("profile", ["openratslam", "project"])
def test_numpy_step_equals_the_batched_torch_step(profile):
    """One network in numpy and the same inputs as rows of a torch batch: the same
    activity (rounding) and centres, with injections and moves across the wraps."""
    p = PoseCellParams(pc_dim_xy=15) if profile == "openratslam" else _params(pc_dim_xy=15)
    rng = np.random.default_rng(11)
    b = 3
    batch = PoseCellNetwork(p, b, dtype=F64)
    singles = [PoseCellNetwork(p, dtype=F64, method="numpy") for _ in range(b)]
    for t in range(60):
        v = rng.uniform(-1.0, 1.0, b) * (2.5 if profile == "project" else 1.0)
        w = rng.uniform(-1.2, 1.2, b)
        if t % 9 == 4:
            cells = rng.integers(0, 15, (3, b))
            batch.inject(cells[0], cells[1], cells[2] % 36, 0.3)
            for i, n in enumerate(singles):
                n.inject(int(cells[0, i]), int(cells[1, i]), int(cells[2, i] % 36), 0.3)
        cb = batch.step(v, w, 1.0)
        for i, n in enumerate(singles):
            ci = n.step(float(v[i]), float(w[i]), 1.0)
            np.testing.assert_allclose(ci[0].numpy(), cb[i].numpy(), rtol=0, atol=1e-9)
            np.testing.assert_allclose(
                n.activity[0].numpy(), batch.activity[i].numpy(), rtol=0, atol=1e-12
            )


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
@pytest.mark.parametrize("profile", ["openratslam", "project"])
def test_to_cuda_steps_like_the_cpu_and_loads_back(profile):
    p = PoseCellParams() if profile == "openratslam" else _params()
    cpu = PoseCellNetwork(p, dtype=F64)
    gpu = PoseCellNetwork(p, dtype=F64)
    for n in (cpu, gpu):
        n.step(0.5, 0.1, 1.0)
    gpu.to("cuda")
    assert gpu.activity.is_cuda and gpu.best.is_cuda and gpu.best.dtype == F64
    for t in range(30):
        for n in (cpu, gpu):
            if t == 10:
                n.inject(3, 17, 4, 0.3)
            c = n.step(0.8, -0.3, 1.0)
        np.testing.assert_allclose(c.cpu().numpy(), cpu.centre().numpy(), rtol=0, atol=1e-9)
    back = PoseCellNetwork(p, dtype=F64)
    back.load_state_dict({k: v.cpu() for k, v in gpu.state_dict().items()})
    np.testing.assert_allclose(back.centre().numpy(), cpu.centre().numpy(), atol=1e-9)


@pytest.mark.parametrize("method", ["numpy", "crop", "separable"])
def test_place_packet_and_set_centre(method):
    p = _params(pc_dim_xy=21)
    net = PoseCellNetwork(p, 1 if method == "numpy" else 2, dtype=F64, method=method)
    net.step(0.7, 0.2, 1.0)
    net.place_packet(24, -1, 5)  # indices wrap
    act = net.activity.numpy()
    assert (act[:, 5, 20, 3] == 1.0).all() and (act.sum(axis=(1, 2, 3)) == 1.0).all()
    assert net.centre().tolist() == [[3.0, 20.0, 5.0]] * net.batch_size
    # the next step starts from the placed packet, like a fresh network placed there
    fresh = PoseCellNetwork(p, net.batch_size, dtype=F64, method=method)
    with torch.no_grad():
        fresh.activity.zero_()
        fresh.activity[:, 5, 20, 3] = 1.0
    assert torch.equal(net.step(0.3, 0.1, 1.0), fresh.step(0.3, 0.1, 1.0))
    net.set_centre([1.5, 2.5, 3.5])
    assert net.centre().tolist() == [[1.5, 2.5, 3.5]] * net.batch_size
    assert net.best.dtype == F64
    with pytest.raises(InputError, match="centre"):
        net.set_centre([1.0, 2.0])


def test_a_template_seen_for_ever_stops_injecting_without_overflowing():
    # the decay of a template seen again and again grows by vt_active_decay each time;
    # past exp's range C's exp gives inf, OpenRatSLAM's energy -inf: nothing is injected
    p = _params(pc_dim_xy=11, vt_active_decay=10.0, pc_vt_restore=0.0)
    pc = PoseCells(p, dtype=F64)
    for t in range(12):  # 12 templates: template 0 is no longer among the last 10
        pc.on_view_template(ViewMatch(t, is_new=True))
        pc.on_odometry(0.0, 0.0, 1.0)
    seen = 0
    while 1.2 * pc.template_decay[0] <= 800.0:  # past exp's largest argument, 709.78
        before = pc.activity.clone()
        pc.on_view_template(ViewMatch(0))
        seen += 1
        energy = (
            p.pc_vt_inject_energy / 30.0 * (30.0 - np.exp(min(1.2 * pc.template_decay[0], 700.0)))
        )
        if energy <= 0:
            assert torch.equal(pc.activity, before)  # no injection once the energy is <= 0
    assert seen > 60 and 1.2 * pc.template_decay[0] > 709.79
    before = pc.activity.clone()
    pc.on_view_template(ViewMatch(0))  # overflows in Python's math.exp, not here
    assert torch.equal(pc.activity, before)


@pytest.mark.parametrize("dtype", [torch.float32, F64])
def test_inject_with_python_numbers_adds_as_the_arrays_path(dtype):
    # PoseCells passes Python ints and a float (no arrays); the cell must get the same
    # bits as through one-element arrays: the sum rounded as float64, then to the dtype
    p = PoseCellParams()
    nets = [PoseCellNetwork(p, dtype=dtype, method="numpy") for _ in range(3)]
    for n in nets:  # float32 rounds 1 + 2**-24 + 2**-50 up; 1 + float32(that energy) ties to 1
        with torch.no_grad():
            n.activity[0, 1, 2, 3] = 1.0
    nets[0].inject(3, 2, 1, 2.0**-24 + 2.0**-50)
    nets[1].inject(np.array([3]), np.array([2]), np.array([1]), np.array([2.0**-24 + 2.0**-50]))
    with torch.no_grad():
        nets[2].activity[0, 1, 2, 3] = 1.0 + 2.0**-24 + 2.0**-50
    assert nets[0].activity[0, 1, 2, 3] == nets[2].activity[0, 1, 2, 3] > 1.0
    rng = np.random.default_rng(7)
    for _ in range(40):
        x, y, th = (int(v) for v in rng.integers(-50, 80, 3))
        e = float(rng.random() * 1e-3)
        nets[0].inject(x, y, th, e)
        nets[1].inject(np.array([x]), np.array([y]), np.array([th]), np.array([e]))
        cell = (0, th % p.pc_dim_th, y % p.pc_dim_xy, x % p.pc_dim_xy)  # the rule, here
        a = nets[2].activity
        with torch.no_grad():  # (through torch: the crop's cache sees the write)
            a[cell] = float(np.float64(a[cell].item()) + np.float64(e))
        nets[0].step(0.3, 0.1, 1.0)  # the crop's cache must know the new cells
        nets[1].step(0.3, 0.1, 1.0)
        nets[2].step(0.3, 0.1, 1.0)
    for n in nets[1:]:
        assert torch.equal(nets[0].activity, n.activity)
        assert torch.equal(nets[0].best, n.best)
    for bad in (math.nan, math.inf):
        for args in ((1, 2, 3, bad), (np.array([1]), np.array([2]), np.array([3]), bad)):
            with pytest.raises(InputError, match="finite"):
                nets[0].inject(*args)


def test_a_step_reads_the_buffer_it_is_given_after_data_is_replaced():
    # the numpy path keeps a view of the buffer's memory: new memory, a new view
    p = PoseCellParams()
    net, ref = (PoseCellNetwork(p, dtype=F64, method="numpy") for _ in range(2))
    net.step(0.3, 0.1, 1.0)
    other = torch.zeros_like(net.activity)
    other[0, 5, 6, 7] = 1.0
    net.activity.data = other.clone()  # the same tensor object, other memory
    ref.set_activity(other)
    assert torch.equal(net.step(0.2, -0.1, 1.0), ref.step(0.2, -0.1, 1.0))
    assert torch.equal(net.activity, ref.activity)
