"""The compiled frame (odometry, action, relaxation in one call) against the Python path.

Every test drives two maps with the same random frames: one through
:meth:`ExperienceMap.step_frame` (the compiled call), one through ``on_odometry``,
``apply`` and ``iterate`` (the Python path), and asks for the same map to the bit.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from ratslam_graph import frame_step
from ratslam_graph.errors import GraphError, InputError
from ratslam_graph.experience_graph import ExperienceGraph, out_lists
from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.geometry import wrap_angle
from ratslam_graph.messages import Action, ActionKind
from ratslam_graph.params import ExperienceMapParams


def frames(seed: int, steps: int):
    """Random frames: odometry (None on some), an action, pose-cell coordinates, a
    behaviour label and whether to relax."""
    rng = np.random.default_rng(seed)
    n = 0
    for step in range(steps):
        odo = None
        if rng.uniform() > 0.05:
            odo = (rng.uniform(0, 2), rng.uniform(-0.8, 0.8), rng.uniform(0.02, 0.3))
        u = rng.uniform()
        rel = float(rng.uniform(-0.4, 0.4))
        if n == 0 or u < 0.3:
            act = Action(ActionKind.CREATE, dest_id=n)
            n += 1
        elif u < 0.6:
            act = Action(ActionKind.LINK, dest_id=int(rng.integers(n)), relative_rad=rel)
        elif u < 0.7:
            act = Action(ActionKind.SET, dest_id=int(rng.integers(n)), relative_rad=rel)
        else:
            act = Action.none()
        pc = tuple(float(v) for v in rng.uniform(0, 30, 3))
        yield step, odo, act, pc, int(rng.integers(3)), bool(rng.uniform() < 0.8)


def python_path(em: ExperienceMap, step, odo, act, pc, beh, relax) -> None:
    if odo is not None:
        em.on_odometry(*odo)
    em.apply(act, frame=step, t=0.1 * step, pc=pc, template_id=step % 7, behaviour=beh)
    if relax:
        em.iterate()


def compiled(em: ExperienceMap, step, odo, act, pc, beh, relax) -> None:
    em.step_frame(
        odo, act, frame=step, t=0.1 * step, pc=pc, template_id=step % 7, behaviour=beh, relax=relax
    )


def assert_bit_equal(a: ExperienceMap, b: ExperienceMap) -> None:
    sa, sb = a.get_state(), b.get_state()
    assert sa.keys() == sb.keys()
    for key, va in sa.items():
        va, vb = np.asarray(va), np.asarray(sb[key])
        assert va.dtype == vb.dtype and va.shape == vb.shape, key
        assert va.tobytes() == vb.tobytes(), key
    e = a.store.e
    np.testing.assert_array_equal(a.store.meas[:e], b.store.meas[:e])
    ga, gb = a.graph, b.graph
    assert dict(ga.nodes(data=True)) == dict(gb.nodes(data=True))
    assert list(ga.edges(data=True)) == list(gb.edges(data=True))


PARAMS = [
    {},
    {"exp_first_at_origin": True, "exp_link_time": "per_link"},
    {"exp_loops": 3, "exp_correction": 0.7},
    {"exp_loops": 0},
]


@pytest.mark.parametrize("kw", PARAMS)
@pytest.mark.parametrize("seed", [3, 4])
def test_compiled_frame_is_the_python_path_bit_for_bit(seed, kw):
    params = ExperienceMapParams(**kw)
    fast, slow = ExperienceMap(params), ExperienceMap(params)
    assert frame_step.compiled_frame(fast)
    for k, f in enumerate(frames(seed, 160)):
        compiled(fast, *f)
        python_path(slow, *f)
        if k % 40 == 0:  # the graph read mid-run too
            assert_bit_equal(fast, slow)
    assert fast.num_links > 20 and len(fast) > 20
    assert_bit_equal(fast, slow)


def test_the_kept_arguments_follow_the_maps_arrays():
    """The compiled frame's arguments, kept on the map, are made again whenever its
    arrays are replaced or its links change other than by the compiled frame: a copy
    (each map writes its own arrays), a link removed or added by hand, a state loaded,
    new settings."""
    fast, slow = ExperienceMap(), ExperienceMap()
    copies: list[ExperienceMap] = []
    for k, f in enumerate(frames(11, 240)):
        if k == 60:
            copies.append(copy.deepcopy(fast))
        maps = [fast, slow, *copies]
        if k == 100:
            src, dst = int(slow.store.src[3]), int(slow.store.dst[3])
            for em in maps:
                em.store.remove_link(src, dst)
        if k == 140:
            for em in maps:
                em.set_state(em.get_state())
        if k == 180:
            a, b = next(
                (a, b)
                for a in range(len(slow))
                for b in range(a + 1, len(slow))
                if slow.store.link_index(a, b) < 0
            )
            for em in maps:
                assert em.store.add_link(a, b, 1.0, 0.1, 0.2, 3.0)
        if k == 200:
            params = ExperienceMapParams(exp_loops=3, exp_correction=0.7)
            for em in maps:
                em.params = params
        compiled(fast, *f)
        python_path(slow, *f)
        for em in copies:
            compiled(em, *f)
    assert fast.num_links > 20 and len(fast) > 20
    assert_bit_equal(fast, slow)
    assert_bit_equal(copies[0], slow)


def test_other_settings_take_the_python_path_and_give_its_map():
    for kw in (
        {"exp_link_averaging": True},
        {"exp_link_directed": True},
        {"exp_link_confidence_threshold": 0.3},
        {"exp_relax_budget": 50},
        {"exp_backend": "alpha", "exp_relax_order": "colour"},
    ):
        params = ExperienceMapParams(**kw)
        fast, slow = ExperienceMap(params), ExperienceMap(params)
        assert not frame_step.compiled_frame(fast)
        for f in frames(5, 60):
            compiled(fast, *f)
            python_path(slow, *f)
        assert_bit_equal(fast, slow)


def test_refused_actions_raise_as_the_python_path_does():
    fast, slow = ExperienceMap(), ExperienceMap()
    for f in frames(6, 20):
        compiled(fast, *f)
        python_path(slow, *f)
    n = len(fast)
    bad = [
        (Action(ActionKind.LINK, dest_id=n + 3), GraphError),
        (Action(ActionKind.CREATE, dest_id=n + 1), GraphError),
    ]
    for act, err in bad:
        with pytest.raises(err):
            compiled(fast, 99, (1.0, 0.1, 0.1), act, (1.0, 2.0, 3.0), 0, True)
        with pytest.raises(err):
            python_path(slow, 99, (1.0, 0.1, 0.1), act, (1.0, 2.0, 3.0), 0, True)
        assert_bit_equal(fast, slow)
    # a non-finite odometry: the experience refused, the odometry kept, as before
    for em, run in ((fast, compiled), (slow, python_path)):
        with pytest.raises(InputError):
            run(
                em,
                100,
                (math.inf, 0.0, 0.1),
                Action(ActionKind.CREATE, dest_id=n),
                (0.0,) * 3,
                0,
                True,
            )
    assert_bit_equal(fast, slow)


def test_compiled_hypot_is_pythons():
    from ratslam_graph._frame_step import py_hypot

    rng = np.random.default_rng(7)
    x = rng.normal(size=200_000) * 10.0 ** rng.integers(-8, 8, size=200_000)
    y = rng.normal(size=200_000) * 10.0 ** rng.integers(-8, 8, size=200_000)
    special = [0.0, -0.0, 5e-324, -2.5e-310, 1e-300, 1e300, 1.7e308, 3.0, -4.0]
    pairs = list(zip(x.tolist(), y.tolist())) + [(a, b) for a in special for b in special]
    for a, b in pairs:
        assert py_hypot(a, b) == math.hypot(a, b), (a, b)


def test_compiled_wrap_is_wrap_angle():
    from ratslam_graph._frame_step import wrap_pi

    rng = np.random.default_rng(8)
    vals = [*rng.uniform(-40, 40, 100_000).tolist(), math.pi, -math.pi, 0.0, -0.0, 2 * math.pi]
    for a in vals:
        w = wrap_pi(a)
        assert w == wrap_angle(a, include_pi=True) and math.copysign(1, w) == math.copysign(
            1, wrap_angle(a, include_pi=True)
        )


def test_compiled_odometry_is_on_odometry():
    from ratslam_graph._frame_step import odometry

    rng = np.random.default_rng(10)
    fast, slow = ExperienceMap(), ExperienceMap()
    for _ in range(20_000):
        odo = tuple(rng.uniform([-1.0, -4.0, 0.0], [3.0, 4.0, 0.5]).tolist())
        odometry(fast._fs, *odo)
        slow.on_odometry(*odo)
        assert fast._fs.tobytes() == slow._fs.tobytes()
    assert abs(fast.accum_x) + abs(fast.accum_y) > 1.0


def test_out_lists_are_each_sources_links_in_creation_order():
    rng = np.random.default_rng(9)
    src = rng.integers(0, 12, 80)
    ends, nxt = out_lists(src, 15)
    for s in range(15):
        walk, k = [], int(ends[s, 0])
        while k >= 0:
            walk.append(k)
            k = int(nxt[k])
        expect = [k for k in range(80) if src[k] == s]
        assert walk == expect
        assert int(ends[s, 1]) == (expect[-1] if expect else -1)


def test_removing_links_keeps_the_out_lists():
    g = ExperienceGraph()
    for i in range(6):
        g.add_experience(float(i), 0.0, 0.0)
    pairs = [(0, 1), (0, 2), (1, 2), (0, 3), (3, 4), (0, 5)]
    for a, b in pairs:
        assert g.add_link(a, b, 1.0, 0.0, 0.0, 1.0)
    g.remove_link(0, 2)
    pairs.remove((0, 2))
    assert [g.link_index(a, b) for a, b in pairs] == list(range(5))
    assert g.link_index(2, 0) == -1 and g.link_index(4, 3) == 3
    assert [int(g.dst[k]) for k in g.out_links(0)] == [1, 3, 5]
    assert not g.add_link(2, 1, 1.0, 0.0, 0.0, 1.0)  # one link per pair, either direction
