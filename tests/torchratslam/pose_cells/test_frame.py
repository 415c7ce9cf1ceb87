"""The pose-cell stage's compiled frame against the Python it stands for.

References written here: the stage's bookkeeping and action rule as plain Python
(``math.exp``, numpy's in-place decay, ``pc_distance_one``, numpy's argmin of
``pc_distance``, a dictionary of each template's experiences); the arcs (``arc_with``
and the arcs of the activity recomputed); and the two calls ``on_view_template`` +
``on_odometry`` that ``on_frame`` fuses (the pipeline's injection angle applied after).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from ratslam_graph.geometry import pc_distance, pc_distance_one
from ratslam_graph.messages import Action, ActionKind
from torchratslam.config import PoseCellParams
from torchratslam.errors import InputError
from torchratslam.messages import ViewMatch
from torchratslam.pose_cells import _layout as L
from torchratslam.pose_cells import functional as F
from torchratslam.pose_cells._frame import decide, inject_cell, view_update
from torchratslam.pose_cells.stage import PoseCells


def _params(**kw) -> PoseCellParams:
    base = {"pc_dim_xy": 15, "pc_dim_th": 36, "exp_delta_pc_threshold": 2.0}
    base.update(kw)
    return PoseCellParams(**base)


# ------------------------------------------------------------------ references
class OldBook:
    """The stage's templates, experiences and action rule in plain Python."""

    def __init__(self, p: PoseCellParams, best: tuple[float, float, float]):
        self.p = p
        self.dims = p.dims
        self.t_pc: list[tuple[float, float, float]] = []
        self.decay = np.zeros(0)
        self.e_pc: list[tuple[float, float, float]] = []
        self.exps: dict[int, list[int]] = {}
        self.cur_exp = self.cur_vt = self.prev_vt = -1
        self.delta = self.rad = 0.0
        self.best = best

    def view(self, vt: int, rad: float):
        """The injection ``(x, y, th, energy)`` or None."""
        p, n, out = self.p, len(self.t_pc), None
        self.rad = rad
        if vt == n:
            self.t_pc.append(self.best)
            self.decay = np.append(self.decay, p.vt_active_decay)
        elif vt < n - 10 or (p.vt_inject_rule == "openratslam" and n < 10):
            if vt == self.cur_vt:
                self.decay[vt] += p.vt_active_decay
            try:
                ex = math.exp(1.2 * self.decay[vt])
            except OverflowError:
                ex = math.inf
            energy = p.pc_vt_inject_energy / 30.0 * (30.0 - ex)
            if energy > 0:
                n_th = self.dims[2]
                self.delta = rad / (2.0 * math.pi) * n_th
                x, y, th = self.t_pc[vt]
                th = th + self.delta
                th = th + n_th if th < 0 else th
                th = th - n_th if th >= n_th else th
                out = (int(x), int(y), int(th) % n_th, float(energy))
        np.subtract(self.decay, p.pc_vt_restore, out=self.decay)
        np.maximum(self.decay, p.vt_active_decay, out=self.decay)
        self.prev_vt, self.cur_vt = self.cur_vt, vt
        return out

    def corrected(self):
        x, y, th = self.best
        th = th - self.delta
        th = th + self.dims[2] if th < 0 else th
        th = th - self.dims[2] if th >= self.dims[2] else th
        return (x, y, th)

    def create(self):
        src, new = self.cur_exp, len(self.e_pc)
        self.e_pc.append(self.best)
        self.exps.setdefault(self.cur_vt, []).append(new)
        self.cur_exp = new
        return (1, new, src)

    def decide(self):
        if not self.t_pc:
            return (0, -1, -1)
        exps = self.exps.get(self.cur_vt, [])
        if not self.e_pc or not exps:
            return self.create()
        thr, c = self.p.exp_delta_pc_threshold, self.corrected()
        if pc_distance_one(self.e_pc[self.cur_exp], c, self.dims) > thr or (
            self.cur_vt != self.prev_vt
        ):
            ids = [e for e in exps if e != self.cur_exp]
            if ids:
                d = pc_distance(np.array([self.e_pc[e] for e in ids]), np.array(c), self.dims)
                k = int(np.argmin(d))
                if d[k] < thr:
                    src, self.cur_exp = self.cur_exp, ids[k]
                    return (2, ids[k], src)
            return self.create()
        return (0, -1, -1)


def _stream(n: int, seed: int):
    """Template ids and angles: new places, then revisits (some of the last ten)."""
    rng = np.random.default_rng(seed)
    known = 0
    for _ in range(n):
        if known < 14 or rng.random() < 0.3:
            yield known, float(rng.uniform(-0.5, 0.5))
            known += 1
        else:
            yield int(rng.integers(0, known)), float(rng.uniform(-3.5, 3.5))


# ------------------------------------------------------------------ kernels
@pytest.mark.parametrize("rule", ["openratslam", "last_10"])
def test_view_update_and_decide_are_the_python_bookkeeping(rule):
    p = _params(vt_inject_rule=rule, pc_vt_inject_energy=0.3, exp_delta_pc_threshold=3.0)
    pcs = PoseCells(p)  # its arrays; the network is not used
    rng = np.random.default_rng(3)
    ref = OldBook(p, pcs.centre)
    dims = np.array(p.dims, dtype=float)
    kinds, injected = set(), 0
    for vt, rad in _stream(300, seed=4):
        pcs._make_room()
        status, th, y, x, energy = view_update(pcs._ist, pcs._fst, pcs._t_pc, pcs._t_decay, vt, rad)
        want = ref.view(vt, rad)
        assert status == 0
        assert ((x, y, th, energy) if energy != 0 else None) == want  # energy bit for bit
        injected += want is not None
        np.testing.assert_array_equal(pcs.template_decay, ref.decay)
        # a centre near the template's cells (links and creations), as after a step
        centre = ref.t_pc[vt] if rng.random() < 0.7 else tuple(rng.random(3) * dims)
        centre = tuple(float(v) for v in (np.array(centre) + rng.normal(0, 1.0, 3)) % dims)
        ref.best = centre
        pcs._best = centre
        pcs._odo_update = True
        pcs._make_room()
        kind, dest, src = decide(
            pcs._ist, pcs._fst, pcs._e_pc, pcs._e_template, pcs._e_next, pcs._t_chain
        )
        assert (kind, dest, src) == ref.decide()
        kinds.add(kind)
        assert (pcs.current_exp, pcs.current_vt, pcs.prev_vt) == (
            ref.cur_exp,
            ref.cur_vt,
            ref.prev_vt,
        )
        assert pcs.vt_delta_pc_th == ref.delta and pcs.relative_rad == ref.rad
    assert kinds == {0, 1, 2} and injected > 20
    np.testing.assert_array_equal(pcs.exp_pc, np.array(ref.e_pc))
    for t, exps in ref.exps.items():
        assert pcs.template_experiences(t) == exps


def test_inject_cell_widens_the_arcs_as_arc_with():
    rng = np.random.default_rng(5)
    for _ in range(200):
        shape = tuple(int(v) for v in rng.integers(3, 12, 3))
        act = np.zeros(shape)
        for _ in range(int(rng.integers(1, 4))):
            act[tuple(int(rng.integers(0, n)) for n in shape)] = rng.random()
        nz = act != 0
        arcs = [F.arc(nz.any(axis=(1, 2))), F.arc(nz.any(axis=(0, 2))), F.arc(nz.any(axis=(0, 1)))]
        span = np.zeros(9, np.int64)
        span[:6] = [v for a in arcs for v in a]
        cell = tuple(int(rng.integers(0, n)) for n in shape)
        before = act[cell]
        inject_cell(act, span, *cell, 0.25, True)
        assert act[cell] == before + 0.25
        want = [F.arc_with(a, c, n) for a, c, n in zip(arcs, cell, shape, strict=True)]
        assert span[:6].tolist() == [v for a in want for v in a]
        for ax in range(3):  # every non-zero cell inside the arc
            occ = np.flatnonzero((act != 0).any(axis=tuple(a for a in range(3) if a != ax)))
            s, ln = span[2 * ax], span[2 * ax + 1]
            assert all((o - s) % shape[ax] < ln for o in occ)


# ------------------------------------------------------------------ on_frame
def _two_calls(pcs: PoseCells, match, odo, injection_angle: bool):
    """The separate calls, and the pipeline's injection angle after them."""
    pcs.on_view_template(match)
    action = pcs.on_odometry(*odo)
    if injection_angle and action.kind != ActionKind.NONE:
        rad = pcs.vt_delta_pc_th * 2.0 * math.pi / pcs.dims[2]
        action = Action(action.kind, action.dest_id, action.src_id, rad)
    return action, pcs.centre


def _same_state(a: PoseCells, b: PoseCells) -> None:
    sa, sb = a.get_state(), b.get_state()
    assert sa.keys() == sb.keys()
    for k in sa:
        np.testing.assert_array_equal(sa[k], sb[k], err_msg=k)
    assert torch.equal(a.network.best, b.network.best)
    assert a.network.last_crop == b.network.last_crop


@pytest.mark.parametrize(
    ("dtype", "kw"),
    [
        (torch.float64, {}),
        (torch.float32, {}),
        (
            torch.float64,
            {"pc_multi_cell": True, "pc_wrap": "preserve_mass", "vt_inject_rule": "last_10"},
        ),
        (torch.float32, {"pc_wrap": "preserve_mass", "pc_dim_xy": 9}),
    ],
)
@pytest.mark.parametrize("injection_angle", [True, False])
def test_on_frame_is_the_two_calls_bit_for_bit(dtype, kw, injection_angle):
    p = _params(pc_vt_inject_energy=0.3, **kw)
    fused, apart = PoseCells(p, dtype=dtype), PoseCells(p, dtype=dtype)
    rng = np.random.default_rng(8)
    kinds = set()
    for vt, rad in _stream(250, seed=6):
        odo = (float(rng.uniform(-0.3, 1.6)), float(rng.uniform(-0.4, 0.4)), 1.0)
        got = fused.on_frame(ViewMatch(vt, rad), *odo, injection_angle=injection_angle)
        want = _two_calls(apart, ViewMatch(vt, rad), odo, injection_angle)
        assert got == want
        assert torch.equal(fused.activity, apart.activity)
        kinds.add(got[0].kind)
    assert kinds == {ActionKind.NONE, ActionKind.CREATE, ActionKind.LINK}
    _same_state(fused, apart)
    # the separate calls go on from the fused frames' state, and the other way round
    for _ in range(40):
        vt, rad = int(rng.integers(0, fused.n_templates + 1)), float(rng.uniform(-1, 1))
        odo = (0.4, -0.1, 1.0)
        assert _two_calls(fused, ViewMatch(vt, rad), odo, True) == apart.on_frame(
            ViewMatch(vt, rad), *odo, injection_angle=True
        )
    _same_state(fused, apart)


def test_on_frame_after_a_restore_and_a_torch_write():
    p = _params(pc_vt_inject_energy=0.3)
    a, b = PoseCells(p), PoseCells(p)
    stream = list(_stream(120, seed=9))
    for vt, rad in stream[:80]:
        a.on_frame(ViewMatch(vt, rad), 0.7, 0.1, 1.0)
    b.set_state(a.get_state())
    for pcs in (a, b):
        with torch.no_grad():
            pcs.activity[0, 0, 0] += 1e-3  # a torch write: the arcs are found again
    for vt, rad in stream[80:]:
        got = b.on_frame(ViewMatch(vt, rad), 0.7, 0.1, 1.0)
        assert got == _two_calls(a, ViewMatch(vt, rad), (0.7, 0.1, 1.0), False)
    _same_state(a, b)
    for t in range(a.n_templates):
        assert b.template_experiences(t) == np.flatnonzero(b.exp_template == t).tolist()


def test_on_frame_raises_as_the_two_calls_and_keeps_the_same_state():
    p = _params()
    fused, apart = PoseCells(p), PoseCells(p)
    for pcs in (fused, apart):
        pcs.on_frame(ViewMatch(0), 0.5, 0.0, 1.0)
    with pytest.raises(InputError, match="template id 5"):
        fused.on_frame(ViewMatch(5), 0.5, 0.0, 1.0)
    with pytest.raises(InputError, match="template id 5"):
        apart.on_view_template(ViewMatch(5))
    _same_state(fused, apart)
    with pytest.raises(InputError, match="odometry must be finite"):
        fused.on_frame(ViewMatch(1), math.nan, 0.0, 1.0)
    apart.on_view_template(ViewMatch(1))
    with pytest.raises(InputError, match="odometry must be finite"):
        apart.on_odometry(math.nan, 0.0, 1.0)
    _same_state(fused, apart)
    assert fused.on_frame(ViewMatch(1), 0.5, 0.0, 1.0) == _two_calls(
        apart, ViewMatch(1), (0.5, 0.0, 1.0), False
    )
    for pcs in (fused, apart):
        with torch.no_grad():
            pcs.network.activity.zero_()
    with pytest.raises(InputError, match="all zero"):
        fused.on_frame(ViewMatch(1), 0.5, 0.0, 1.0)
    apart.on_view_template(ViewMatch(1))
    with pytest.raises(InputError, match="all zero"):
        apart.on_odometry(0.5, 0.0, 1.0)
    _same_state(fused, apart)


def test_on_frame_on_the_torch_engine_is_the_two_calls():
    p = _params(pc_vt_inject_energy=0.3)
    fused = PoseCells(p, method="separable")
    apart = PoseCells(p, method="separable")
    assert not fused.network.uses_numpy
    for vt, rad in _stream(60, seed=10):
        got = fused.on_frame(ViewMatch(vt, rad), 0.6, 0.1, 1.0, injection_angle=True)
        assert got == _two_calls(apart, ViewMatch(vt, rad), (0.6, 0.1, 1.0), True)
    _same_state(fused, apart)


def test_the_state_slots_read_and_write_the_arrays():
    pcs = PoseCells(_params())
    pcs.current_exp, pcs.prev_vt, pcs.relative_rad = 4, 2, -0.25
    assert pcs._ist[L.CUR_EXP] == 4 and pcs._ist[L.PREV_VT] == 2
    assert pcs._fst[L.REL_RAD] == -0.25
    assert type(pcs.current_exp) is int and type(pcs.relative_rad) is float
    assert type(pcs._odo_update) is bool
    assert isinstance(PoseCells.current_exp, L.Slot)


def test_decide_takes_the_first_nan_as_argmin_and_skips_the_current():
    p = _params(exp_delta_pc_threshold=5.0)
    cells = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [np.nan, 1.0, 1.0], [1.5, 2.0, 3.0]])
    for templates in ([0, 0, 0, 0], [0, 0, -1, 0]):  # the NaN row the template's, or not
        pcs = PoseCells(p)
        pcs._store(np.zeros((1, 3)), np.ones(1), cells, np.array(templates))
        pcs.current_exp, pcs.current_vt, pcs.prev_vt = 0, 0, -1  # a new template: search
        pcs._best = (1.4, 2.0, 3.0)
        pcs._odo_update = pcs._vt_update = True
        ids = [i for i in pcs.template_experiences(0) if i != 0]
        kind, dest, src = decide(
            pcs._ist, pcs._fst, pcs._e_pc, pcs._e_template, pcs._e_next, pcs._t_chain
        )
        d = pc_distance(cells[ids], np.array(pcs._best), p.dims)
        k = int(np.argmin(d))  # numpy's choice: the first NaN, else the first nearest
        assert (ids[k] == 2) == (templates[2] == 0)
        if d[k] < 5.0:
            assert (kind, dest, src) == (2, ids[k], 0)
        else:  # a NaN is never within the threshold: a new experience
            assert (kind, dest, src) == (1, 4, 0)


def test_a_copy_and_a_pickle_go_on_as_the_original():
    import copy
    import pickle

    p = _params(pc_vt_inject_energy=0.3)
    pcs = PoseCells(p)
    stream = list(_stream(90, seed=12))
    for vt, rad in stream[:60]:
        pcs.on_frame(ViewMatch(vt, rad), 0.7, 0.1, 1.0)
    copies = [copy.deepcopy(pcs), pickle.loads(pickle.dumps(pcs))]
    for vt, rad in stream[60:]:
        want = pcs.on_frame(ViewMatch(vt, rad), 0.7, 0.1, 1.0)
        for c in copies:
            assert c.on_frame(ViewMatch(vt, rad), 0.7, 0.1, 1.0) == want
    for c in copies:
        _same_state(c, pcs)
