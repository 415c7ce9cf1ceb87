"""The recommended merge options on small hand-made maps with a known answer: the rotated
pose-cell shift under both axis conventions, and fusing templates (``merge_absorb``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from torchratslam.maps.merge import _rotate_shift, first_experience, fuse_templates
from torchratslam.maps.state import MapState

DIMS = np.array([40.0, 40.0, 36.0])


def integrate(start, headings_cells, steps, axis):
    """Pose-cell path integration: layer ``th`` moves along ``(cos, sin)`` (math) or
    ``(sin, cos)`` (openratslam) of ``th 2 pi / n_th``, one step per heading."""
    out = [np.asarray(start, np.float64)]
    for th, d in zip(headings_cells, steps):
        a = th * 2 * math.pi / DIMS[2]
        v = (math.cos(a), math.sin(a)) if axis == "math" else (math.sin(a), math.cos(a))
        p = out[-1].copy()
        p[:2] += d * np.array(v)
        p[2] = th
        out.append(np.mod(p, DIMS))
    return np.array(out)


@pytest.mark.parametrize("axis", ["math", "openratslam"])
def test_rotated_shift_maps_one_networks_path_onto_the_other(axis):
    """The same drive laid down by two networks whose heading cells differ by 5 (and
    whose packets start elsewhere): rotating the partial network's cells about the
    matched one by the heading shift, the way the network's axes turn, gives the loaded
    network's cells; the paper's translation does not."""
    rng = np.random.default_rng(0)
    turn = np.cumsum(rng.uniform(-0.8, 0.8, 12))
    steps = rng.uniform(0.5, 1.5, 12)
    loaded = integrate([10.0, 12.0, 20.0], 20.0 + turn, steps, axis)
    partial = integrate([30.0, 25.0, 15.0], 15.0 + turn, steps, axis)
    got = _rotate_shift(partial, partial[-1], loaded[-1], DIMS, axis)
    assert np.allclose(got, loaded, atol=1e-9)
    other = "openratslam" if axis == "math" else "math"
    assert not np.allclose(_rotate_shift(partial, partial[-1], loaded[-1], DIMS, other), loaded)
    assert not np.allclose(np.mod(partial + loaded[-1] - partial[-1], DIMS), loaded)


def small_map():
    """6 templates, 7 experiences (template 1 has two), a chain of links and one loop;
    template 5 (experience 6) is a second view of template 1's place."""
    n_t, tpl = 6, np.array([0, 1, 2, 3, 1, 4, 5])
    m = tpl.size
    pairs = [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (5, 6), (6, 1), (3, 0)]
    lf, lt = (np.array(x, np.int64) for x in zip(*pairs))
    return MapState(
        config={"pc_dim_xy": 40, "pc_dim_th": 36, "template_x_size": 3, "template_y_size": 2},
        templates=np.arange(n_t * 6, dtype=np.float64).reshape(n_t, 2, 3),
        template_mean=np.arange(n_t, dtype=np.float64),
        template_frame=np.arange(n_t, dtype=np.int64),
        template_pc=np.c_[np.arange(n_t), np.arange(n_t), np.zeros(n_t)].astype(np.float64),
        template_decay=np.ones(n_t),
        exp_pose=np.c_[np.arange(m), np.zeros(m), np.zeros(m)].astype(np.float64),
        exp_pc=np.zeros((m, 3)),
        exp_template=tpl,
        exp_frame=np.arange(m, dtype=np.int64),
        exp_t=np.arange(m, dtype=np.float64),
        link_from=lf,
        link_to=lt,
        link_d=np.arange(len(pairs), dtype=np.float64) + 1.0,
        link_heading=np.zeros(len(pairs)),
        link_facing=np.zeros(len(pairs)),
        link_dt=np.ones(len(pairs)),
        activity=np.zeros((0, 0, 0)),
        current_vt=5,
        prev_vt=4,
        current_exp=6,
        prev_exp=5,
        frame_index=7,
        extra={"exp:tag": np.arange(m) + 10, "link:tag": np.arange(len(pairs)) + 20},
    ).validate()


def test_fuse_templates_identifies_a_template_with_its_match():
    state = small_map()
    fused, emap, applied = fuse_templates(state, [(5, 1)])
    assert applied == [(5, 1)]
    assert fused.n_templates == 5 and fused.n_experiences == 6
    assert emap.tolist() == [0, 1, 2, 3, 4, 5, 1]  # experience 6 -> template 1's first
    assert first_experience(state, 1) == 1
    # links: (5, 6) -> (5, 1); (6, 1) would join 1 to itself: dropped
    pairs = list(zip(fused.link_from.tolist(), fused.link_to.tolist()))
    assert pairs == [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (5, 1), (3, 0)]
    assert fused.link_d.tolist() == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0]
    assert fused.extra["link:tag"].tolist() == [20, 21, 22, 23, 24, 25, 27]
    assert fused.extra["exp:tag"].tolist() == [10, 11, 12, 13, 14, 15]
    # the current experience was the dropped one: the robot is at its match now
    assert fused.current_exp == 1 and fused.current_vt == 1 and fused.prev_vt == 4
    assert np.array_equal(fused.templates, state.templates[:5])
    fused.validate()


def test_fuse_templates_keeps_one_link_per_pair_and_skips_bad_pairs():
    state = small_map()
    # template 3 (experience 3) onto template 0 (experience 0): (2, 3) -> (2, 0),
    # (3, 4) -> (0, 4), (3, 0) would be a self-link; (0, 1) exists once
    fused, emap, applied = fuse_templates(state, [(3, 0), (2, 2), (9, 0)])
    assert applied == [(3, 0)]  # (2, 2) is itself, (9, 0) out of range
    pairs = list(zip(fused.link_from.tolist(), fused.link_to.tolist()))
    assert len(pairs) == len(set(pairs)) and all(a != b for a, b in pairs)
    assert fused.n_experiences == state.n_experiences - 1
    assert emap[3] == 0
    # a template both dropped and kept is not dropped (no chains)
    assert fuse_templates(state, [(3, 0), (4, 3)])[2] == [(4, 3)]
    # nothing to do: the same map back
    same, ident, none = fuse_templates(state, [])
    assert same is state and none == [] and ident.tolist() == list(range(7))
