"""Merge arithmetic (Eqs. 9-17) on small hand-made maps with a known answer."""

from __future__ import annotations

import math

import numpy as np
import pytest

from torchratslam.errors import GraphError, MapFormatError
from torchratslam.maps.merge import (
    first_experience,
    merge_maps,
    pc_distance,
    pick_experience,
    shift_activity,
)
from torchratslam.maps.state import MapState

DIMS = (9, 9, 12)  # x, y, th rings
CONFIG = {"pc_dim_xy": 9, "pc_dim_th": 12, "template_x_size": 4, "template_y_size": 2}


def wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def links_for(poses, pairs):
    """RatSLAM link geometry (d, heading, facing relative to the source heading)."""
    rows = []
    for a, b in pairs:
        dx, dy = poses[b, :2] - poses[a, :2]
        rows.append(
            (
                a,
                b,
                math.hypot(dx, dy),
                wrap(math.atan2(dy, dx) - poses[a, 2]),
                wrap(poses[b, 2] - poses[a, 2]),
                1.0 + a,
            )
        )
    return np.array(rows, dtype=np.float64).reshape(-1, 6)


def link_residual(state):
    """Max disagreement between each link's prediction and the target pose."""
    p, out = state.exp_pose, 0.0
    for k in range(state.n_links):
        a, b = state.link_from[k], state.link_to[k]
        ang = p[a, 2] + state.link_heading[k]
        pred = p[a, :2] + state.link_d[k] * np.array([math.cos(ang), math.sin(ang)])
        out = max(
            out,
            float(np.abs(pred - p[b, :2]).max()),
            abs(float(wrap(p[a, 2] + state.link_facing[k] - p[b, 2]))),
        )
    return out


def make_map(poses, pcs, tpl_of_exp, templates, tpl_pc, pairs, activity=None, current=None):
    lk = links_for(poses, pairs)
    n, m = len(templates), len(poses)
    return MapState(
        config=dict(CONFIG),
        templates=np.asarray(templates, np.float64).reshape(n, 2, 4),
        template_mean=np.asarray(templates, np.float64).reshape(n, -1).mean(1),
        template_frame=np.arange(n, dtype=np.int64),
        template_pc=np.asarray(tpl_pc, np.float64).reshape(n, 3),
        template_decay=np.linspace(1.0, 2.0, n),
        exp_pose=np.asarray(poses, np.float64).reshape(m, 3),
        exp_pc=np.asarray(pcs, np.float64).reshape(m, 3),
        exp_template=np.asarray(tpl_of_exp, np.int64),
        exp_frame=np.arange(m, dtype=np.int64) * 3,
        exp_t=np.arange(m, dtype=np.float64) * 0.5,
        link_from=lk[:, 0].astype(np.int64),
        link_to=lk[:, 1].astype(np.int64),
        link_d=lk[:, 2],
        link_heading=lk[:, 3],
        link_facing=lk[:, 4],
        link_dt=lk[:, 5],
        activity=np.zeros((12, 9, 9)) if activity is None else activity,
        current_vt=n - 1,
        prev_vt=max(n - 2, -1),
        current_exp=m - 1 if current is None else current,
        prev_exp=max(m - 2, -1),
        frame_index=40,
        extra={"exp:count": np.arange(m, dtype=np.int64) + 100, "pc:flag": np.array([m])},
        scalars={"session": m},
    ).validate()


def world(rng, n):
    """A world trajectory: n poses, pose-cell coordinates, one template per experience."""
    th = np.cumsum(rng.uniform(-0.6, 0.6, n))
    xy = np.cumsum(np.c_[np.cos(th), np.sin(th)] * rng.uniform(0.5, 1.5, (n, 1)), axis=0)
    poses = np.c_[xy, wrap(th)]
    pcs = np.mod(np.c_[xy * 0.8, th / (2 * np.pi) * DIMS[2]] + 3.3, DIMS)
    templates = rng.uniform(0, 1, (n, 8))
    return poses, pcs, templates


def split(rng, n_l=7, n_p=6, frame=(0.7, -4.0, 2.5), pc_off=(5.4, 7.9, 10.5)):
    """Loaded map = world experiences 0..n_l-1; partial map = a stretch of the world
    ending at world experience 2 (the place both maps share), expressed in another frame
    and with other pose-cell coordinates. Returns (loaded, partial, world data)."""
    poses, pcs, templates = world(rng, n_l + n_p)
    lidx = np.arange(n_l)
    pidx = np.r_[np.arange(n_l, n_l + n_p - 1), 2]  # the partial map ends at world exp 2
    loaded = make_map(
        poses[lidx],
        pcs[lidx],
        np.arange(n_l),
        templates[lidx],
        pcs[lidx],
        [(i, i + 1) for i in range(n_l - 1)] + [(n_l - 1, 0)],
    )
    dth, tx, ty = frame
    c, s = math.cos(dth), math.sin(dth)
    pp = poses[pidx].copy()
    pp[:, :2] = pp[:, :2] @ np.array([[c, s], [-s, c]]) + [tx, ty]
    pp[:, 2] = wrap(pp[:, 2] + dth)
    ppc = np.mod(pcs[pidx] - pc_off, DIMS)
    act = np.zeros((12, 9, 9))
    z = np.rint(ppc[-1]).astype(int) % np.array(DIMS)
    act[z[2], z[1], z[0]] = 1.0
    partial = make_map(
        pp,
        ppc,
        np.arange(n_p),
        templates[pidx],
        ppc,
        [(i, i + 1) for i in range(n_p - 1)] + [(0, 2)],
        activity=act,
    )
    return loaded, partial, (poses, pcs, pidx)


@pytest.mark.parametrize("seed", range(6))
def test_known_transform_and_pc_shift_are_recovered(seed):
    rng = np.random.default_rng(seed)
    loaded, partial, (poses, pcs, pidx) = split(rng)
    res = merge_maps(loaded, partial, loaded_template=2)
    m = res.state
    n_l, n_p = loaded.n_experiences, partial.n_experiences
    # every partial experience lands on its world pose (the frame change is undone)
    got = m.exp_pose[n_l:]
    want = poses[pidx[:-1]]
    assert np.allclose(got[:, :2], want[:, :2], atol=1e-9)
    assert np.allclose(wrap(got[:, 2] - want[:, 2]), 0, atol=1e-9)
    # and on its world pose-cell coordinates, with wrap-around
    d = pc_distance(m.exp_pc[n_l:], pcs[pidx[:-1]], DIMS)
    assert d.max() < 1e-9
    assert np.all((m.exp_pc >= 0) & (m.exp_pc < np.array(DIMS)))
    assert pc_distance(m.template_pc[loaded.n_templates :], pcs[pidx[:-1]], DIMS).max() < 1e-9
    # the links are still satisfied by the poses, including the re-pointed ones
    assert link_residual(m) < 1e-9
    assert m.n_experiences == n_l + n_p - 1 and m.n_templates == n_l + n_p - 1
    assert m.n_links == loaded.n_links + partial.n_links
    assert res.info["loaded_exp"] == 2 and res.info["partial_exp"] == n_p - 1
    # the transform maps e_z onto e_u exactly
    assert np.allclose(res.transform_poses(partial.exp_pose[-1])[:2], loaded.exp_pose[2, :2])


def test_pose_cell_shift_wraps_and_activity_moves_to_the_loaded_packet():
    rng = np.random.default_rng(11)
    loaded, partial, _ = split(rng, pc_off=(8.6, 0.4, 11.7))
    u = loaded.template_pc[2]
    res = merge_maps(loaded, partial, 2)
    delta = np.array(res.info["pc_shift"])
    assert np.allclose(delta, u - partial.template_pc[-1])
    # brute-force modular shift, axis by axis
    for i in range(partial.n_templates - 1):
        for ax in range(3):
            want = partial.template_pc[i, ax] + delta[ax]
            while want < 0:
                want += DIMS[ax]
            while want >= DIMS[ax]:
                want -= DIMS[ax]
            assert res.state.template_pc[loaded.n_templates + i, ax] == pytest.approx(want)
    peak = np.unravel_index(np.argmax(res.state.activity), res.state.activity.shape)
    th, y, x = peak
    assert pc_distance(np.array([x, y, th]), u, DIMS) <= math.sqrt(3 * 0.5**2) + 1e-9
    assert res.state.activity.sum() == pytest.approx(partial.activity.sum())


def test_shift_activity_matches_a_brute_force_roll():
    rng = np.random.default_rng(3)
    a = rng.random((12, 9, 9))
    out = shift_activity(a, np.array([-3.2, 10.6, 5.0]))  # rounds to (-3, 11, 5)
    for th in range(12):
        for y in range(9):
            for x in range(9):
                assert out[(th + 5) % 12, (y + 11) % 9, (x - 3) % 9] == a[th, y, x]


def reference_merge(loaded, partial, u, e_u, rel=0.0):
    """A plain loop re-implementation of Eqs. 9-17, for comparison."""
    z, e_z = partial.n_templates - 1, partial.n_experiences - 1
    n_vl, n_el = loaded.n_templates, loaded.n_experiences
    tmap = {i: (n_vl + i if i < z else u) for i in range(partial.n_templates)}
    emap = {j: (n_el + j if j < e_z else e_u) for j in range(partial.n_experiences)}
    delta = [loaded.template_pc[u][k] - partial.template_pc[z][k] for k in range(3)]
    dth = loaded.exp_pose[e_u, 2] - partial.exp_pose[e_z, 2] + rel
    exps, links = [], []
    for j in range(partial.n_experiences):
        if j == e_z:
            continue
        x, y, th = partial.exp_pose[j]
        ox, oy = x - partial.exp_pose[e_z, 0], y - partial.exp_pose[e_z, 1]
        nx = math.cos(dth) * ox - math.sin(dth) * oy + loaded.exp_pose[e_u, 0]
        ny = math.sin(dth) * ox + math.cos(dth) * oy + loaded.exp_pose[e_u, 1]
        pc = [(partial.exp_pc[j][k] + delta[k]) % DIMS[k] for k in range(3)]
        exps.append((nx, ny, wrap(th + dth), *pc, tmap[int(partial.exp_template[j])]))
    for k in range(partial.n_links):
        links.append(
            (
                emap[int(partial.link_from[k])],
                emap[int(partial.link_to[k])],
                partial.link_d[k],
                partial.link_heading[k],
                partial.link_facing[k],
            )
        )
    return np.array(exps), np.array(links)


@pytest.mark.parametrize("seed", range(4))
def test_vectorised_merge_equals_a_loop_reference(seed):
    rng = np.random.default_rng(100 + seed)
    loaded, partial, _ = split(rng, n_l=5 + seed, n_p=4 + seed)
    rel = float(rng.uniform(-1, 1))
    res = merge_maps(loaded, partial, 2, relative_rad=rel)
    exps, links = reference_merge(loaded, partial, 2, 2, rel)
    m, n_el = res.state, loaded.n_experiences
    got = np.c_[m.exp_pose[n_el:], m.exp_pc[n_el:], m.exp_template[n_el:]]
    assert np.allclose(got, exps, atol=1e-12)
    gl = np.c_[m.link_from, m.link_to, m.link_d, m.link_heading, m.link_facing][loaded.n_links :]
    assert np.allclose(gl, links)
    # loaded part untouched, partial templates appended in order, the last one dropped
    assert np.array_equal(m.exp_pose[:n_el], loaded.exp_pose)
    assert np.array_equal(m.templates[: loaded.n_templates], loaded.templates)
    assert np.array_equal(m.templates[loaded.n_templates :], partial.templates[:-1])
    assert np.array_equal(m.template_decay[loaded.n_templates :], partial.template_decay[:-1])
    assert np.array_equal(m.exp_frame[n_el:], partial.exp_frame[:-1])
    # per-experience extras concatenated, session extras and scalars from the partial map
    assert np.array_equal(
        m.extra["exp:count"], np.r_[loaded.extra["exp:count"], partial.extra["exp:count"][:-1]]
    )
    assert np.array_equal(m.extra["pc:flag"], partial.extra["pc:flag"])
    assert m.scalars == partial.scalars and m.frame_index == partial.frame_index
    # current ids follow the robot: it stands at the loaded match
    assert m.current_exp == 2 and m.current_vt == 2
    assert m.prev_exp == n_el + partial.n_experiences - 2
    m.validate()


def test_the_ablation_keeps_partial_associations_but_moves_the_activity():
    rng = np.random.default_rng(5)
    loaded, partial, _ = split(rng)
    res = merge_maps(loaded, partial, 2, shift_pose_cells=False)
    m = res.state
    assert np.array_equal(m.template_pc[loaded.n_templates :], partial.template_pc[:-1])
    assert np.array_equal(m.exp_pc[loaded.n_experiences :], partial.exp_pc[:-1])
    shifted = merge_maps(loaded, partial, 2).state
    assert np.array_equal(m.activity, shifted.activity)
    assert np.array_equal(m.exp_pose, shifted.exp_pose)


def test_first_view_match_continues_in_the_loaded_map():
    """Scenario (i): a one-template, one-experience partial map adds nothing."""
    rng = np.random.default_rng(2)
    loaded, _, _ = split(rng)
    partial = make_map(
        np.array([[3.0, 1.0, 0.2]]),
        np.array([[4.0, 4.0, 6.0]]),
        [0],
        rng.random((1, 8)),
        np.array([[4.0, 4.0, 6.0]]),
        [],
    )
    res = merge_maps(loaded, partial, 4)
    m = res.state
    assert m.summary() == loaded.summary()
    assert m.current_exp == 4 and m.current_vt == 4
    assert np.array_equal(m.exp_pose, loaded.exp_pose)


def test_picks_the_experience_nearest_in_pose_cells():
    rng = np.random.default_rng(8)
    loaded, partial, _ = split(rng)
    loaded.exp_template[5] = 2  # template 2 now has experiences 2 and 5
    loaded.exp_pc[5] = loaded.template_pc[2] + [0.2, 0, 0]
    loaded.exp_pc[2] = np.mod(loaded.template_pc[2] + [3, 0, 0], DIMS)
    assert pick_experience(loaded, 2) == 5
    assert merge_maps(loaded, partial, 2, match_exp="nearest").info["loaded_exp"] == 5
    # the authors' code (the default) merges at the template's first experience
    assert first_experience(loaded, 2) == 2
    assert merge_maps(loaded, partial, 2).info["loaded_exp"] == 2
    assert pick_experience(loaded, 99 % loaded.n_templates) in range(loaded.n_experiences)


def test_bad_requests_are_clear_errors():
    rng = np.random.default_rng(9)
    loaded, partial, _ = split(rng)
    with pytest.raises(GraphError, match="loaded template 99"):
        merge_maps(loaded, partial, 99)
    loaded.exp_template[:] = 0
    with pytest.raises(GraphError, match="no experience"):
        merge_maps(loaded, partial, 3)
    other = partial.copy()
    other.config = {**CONFIG, "pc_dim_xy": 21}
    with pytest.raises(MapFormatError, match="pc_dim_xy = 9 in the map but 21"):
        merge_maps(loaded, other, 2)


def _cli_maps(tmp_path, *, match=True):
    from torchratslam.maps.native import save_map

    rng = np.random.default_rng(21)
    loaded, partial, _ = split(rng)
    if not match:
        partial.templates[-1] = 1.0 - loaded.templates[2]
    cfg = tmp_path / "c.yaml"
    cfg.write_text(
        "pc_dim_xy: 9\npc_dim_th: 12\ntemplate_x_size: 4\ntemplate_y_size: 2\n"
        "vt_shift_match: 0\nvt_step_match: 1\nvt_match_threshold: 0.01\n"
    )
    save_map(loaded, tmp_path / "loaded")
    save_map(partial, tmp_path / "partial")
    return loaded, partial, cfg


@pytest.mark.parametrize("fmt", ["native", "reference"])
def test_cli_merge_writes_the_merged_map(tmp_path, capsys, fmt):
    from torchratslam.cli import main
    from torchratslam.maps.io import load_state

    loaded, partial, cfg = _cli_maps(tmp_path)
    code = main(
        [
            "merge",
            "--config",
            str(cfg),
            "--loaded",
            str(tmp_path / "loaded"),
            "--partial",
            str(tmp_path / "partial"),
            "--out",
            str(tmp_path / "m"),
            "--format",
            fmt,
        ]
    )
    assert code == 0
    assert '"loaded_template": 2' in capsys.readouterr().out
    from torchratslam.config import load_config

    got = load_state(tmp_path / "m", load_config(cfg))
    want = merge_maps(loaded, partial, 2).state
    assert got.n_experiences == want.n_experiences and got.n_templates == want.n_templates
    assert np.allclose(got.exp_pose, want.exp_pose) and np.allclose(got.exp_pc, want.exp_pc)
    assert np.array_equal(got.link_from, want.link_from)


def test_cli_merge_without_a_match_is_an_error_and_writes_nothing(tmp_path, capsys):
    from torchratslam.cli import main

    _, _, cfg = _cli_maps(tmp_path, match=False)
    code = main(
        [
            "merge",
            "--config",
            str(cfg),
            "--loaded",
            str(tmp_path / "loaded"),
            "--partial",
            str(tmp_path / "partial"),
            "--out",
            str(tmp_path / "m"),
        ]
    )
    assert code == 2
    assert "matches no loaded template" in capsys.readouterr().err
    assert not (tmp_path / "m").exists()


# ------------------------------------------------ two simulated sessions, authors' arithmetic
@pytest.fixture(scope="module")
def two_sessions(tmp_path_factory):
    """Session 1 of the simulated virtual tour mapped alone; session 2 mapped until its
    partial map meets session 1's. Both maps written in the authors' format."""
    import torch

    from torchratslam.config import load_config
    from torchratslam.maps.reference_format import write_reference
    from torchratslam.maps.running import state_from_slam
    from torchratslam.multisession.session import MultiSessionRatSLAM
    from torchratslam.pipeline import RatSLAM
    from torchratslam.sim import get_tour

    torch.set_num_threads(1)
    cfg, tour = load_config("virtual_tour"), get_tour("virtual_tour")
    slam = RatSLAM(cfg)
    slam.run(tour.sessions[0].frames(), progress=False)
    ms = MultiSessionRatSLAM(cfg, [state_from_slam(slam)], session="session2")
    ms.run(tour.sessions[1].frames(0, 25), progress=False)
    assert len(ms.merges) == 1
    d = tmp_path_factory.mktemp("two_sessions")
    write_reference(state_from_slam(slam), d / "loaded")
    write_reference(ms.snapshots[0]["partial_state"], d / "partial")
    return cfg, d, ms.merges[0]


def authors_merge(lm, pm, u, rel):
    """The merge as reference-save-format.md describes the authors' code, in plain loops."""
    dims = [lm.config["pc_dim_xy"], lm.config["pc_dim_xy"], lm.config["pc_dim_th"]]
    n_vl, n_vp, n_el, n_ep = lm.n_templates, pm.n_templates, lm.n_experiences, pm.n_experiences
    z, e_z = n_vp - 1, n_ep - 1  # the partial map's last template and last experience
    e_u = next(j for j in range(n_el) if lm.exp_template[j] == u)  # u's first experience
    out = {"e_u": e_u, "templates": [], "t_pc": [], "exps": [], "links": []}
    for i in range(n_vp - 1):  # templates except the last, ids offset by n_vl
        out["templates"].append((n_vl + i, pm.templates[i], pm.template_decay[i]))
        shifted = []
        for k in range(3):  # the templates' packet difference, modulo the network
            v = pm.template_pc[i][k] + (lm.template_pc[u][k] - pm.template_pc[z][k])
            shifted.append(v % dims[k])
        out["t_pc"].append(shifted)
    dth = lm.exp_pose[e_u][2] - pm.exp_pose[e_z][2] + rel
    for j in range(n_ep - 1):
        x = pm.exp_pose[j][0] - pm.exp_pose[e_z][0]
        y = pm.exp_pose[j][1] - pm.exp_pose[e_z][1]
        nx = math.cos(dth) * x - math.sin(dth) * y + lm.exp_pose[e_u][0]
        ny = math.sin(dth) * x + math.cos(dth) * y + lm.exp_pose[e_u][1]
        th = pm.exp_pose[j][2] + dth
        pc = []
        for k in range(3):  # the matched experiences' difference, modulo the network
            v = pm.exp_pc[j][k] + (lm.exp_pc[e_u][k] - pm.exp_pc[e_z][k])
            pc.append(v % dims[k])
        t = int(pm.exp_template[j])
        out["exps"].append((nx, ny, th, pc, n_vl + t if t < z else u))
    for k in range(pm.n_links):
        ends = []
        for e in (int(pm.link_from[k]), int(pm.link_to[k])):
            ends.append(e_u if e == e_z else n_el + e)  # links at e_z re-pointed to e_u
        geo = (pm.link_d[k], pm.link_heading[k], pm.link_facing[k], pm.link_dt[k])
        out["links"].append((*ends, *geo))
    return out


def test_merge_of_two_simulated_sessions_is_the_authors_arithmetic(two_sessions):
    from torchratslam.maps.reference_format import read_reference

    cfg, d, rec = two_sessions
    lm, pm = read_reference(d / "loaded", cfg), read_reference(d / "partial", cfg)
    u, rel = rec["loaded_template"], 0.0  # the virtual tour is not panoramic
    res = merge_maps(lm, pm, u, relative_rad=rel)
    want, m = authors_merge(lm, pm, u, rel), res.state
    n_vl, n_el, n_ll = lm.n_templates, lm.n_experiences, lm.n_links
    assert res.info["loaded_exp"] == want["e_u"]
    assert res.info["partial_exp"] == pm.n_experiences - 1
    # the loaded map is kept as it is
    assert np.array_equal(m.templates[:n_vl], lm.templates)
    assert np.array_equal(m.template_pc[:n_vl], lm.template_pc)
    assert np.array_equal(m.exp_pose[:n_el], lm.exp_pose)
    assert np.array_equal(m.exp_pc[:n_el], lm.exp_pc)
    assert np.array_equal(m.link_from[:n_ll], lm.link_from)
    # templates, field by field
    assert m.n_templates == n_vl + len(want["templates"])
    for i, (tid, data, decay) in enumerate(want["templates"]):
        assert np.array_equal(m.templates[tid], data) and m.template_decay[tid] == decay
        assert m.template_pc[tid].tolist() == pytest.approx(want["t_pc"][i], abs=1e-12)
    # experiences, field by field
    assert m.n_experiences == n_el + len(want["exps"])
    for j, (x, y, th, pc, t) in enumerate(want["exps"]):
        e = n_el + j
        assert m.exp_pose[e, :2].tolist() == pytest.approx([x, y], abs=1e-12)
        assert abs(wrap(m.exp_pose[e, 2] - th)) < 1e-12
        assert m.exp_pc[e].tolist() == pytest.approx(pc, abs=1e-12)
        assert m.exp_template[e] == t
    # links, field by field
    assert m.n_links == n_ll + len(want["links"])
    for k, (a, b, dd, hh, ff, dt) in enumerate(want["links"]):
        got = (m.link_from[n_ll + k], m.link_to[n_ll + k], m.link_d[n_ll + k])
        assert got == (a, b, dd)
        geo = (m.link_heading[n_ll + k], m.link_facing[n_ll + k], m.link_dt[n_ll + k])
        assert geo == (hh, ff, dt)
    # the two shifts really differ here, so the test tells the two readings apart
    e_u, e_z = want["e_u"], pm.n_experiences - 1
    exp_delta = lm.exp_pc[e_u] - pm.exp_pc[e_z]
    tpl_delta = lm.template_pc[u] - pm.template_pc[-1]
    assert np.abs(exp_delta - tpl_delta).max() > 1e-3
    single = merge_maps(lm, pm, u, relative_rad=rel, exp_pc_shift="templates").state
    dims = np.array(pm.pc_dims, np.float64)
    assert np.allclose(single.exp_pc[n_el:], np.mod(pm.exp_pc[:-1] + tpl_delta, dims))
    assert np.array_equal(single.template_pc, m.template_pc)
    assert np.array_equal(single.exp_pose, m.exp_pose)


def test_unknown_merge_options_are_errors():
    loaded, partial, _ = split(np.random.default_rng(1))
    with pytest.raises(GraphError, match="exp_pc_shift must be one of"):
        merge_maps(loaded, partial, 2, exp_pc_shift="paper")
    with pytest.raises(GraphError, match="match_exp must be one of"):
        merge_maps(loaded, partial, 2, match_exp="last")


def test_cli_merge_options_select_the_readings(tmp_path, capsys):
    from torchratslam.cli import main
    from torchratslam.config import load_config
    from torchratslam.maps.io import load_state

    loaded, partial, cfg = _cli_maps(tmp_path)
    loaded.exp_template[5] = 2  # template 2 has experiences 2 and 5; 5 is nearer
    loaded.exp_pc[5] = loaded.template_pc[2] + [0.2, 0, 0]
    loaded.exp_pc[2] = np.mod(loaded.template_pc[2] + [3, 0, 0], DIMS)
    from torchratslam.maps.native import save_map

    save_map(loaded, tmp_path / "loaded2")
    args = ["merge", "--config", str(cfg), "--loaded", str(tmp_path / "loaded2")]
    args += ["--partial", str(tmp_path / "partial")]
    for opts, e_u in (([], 2), (["--match-exp", "nearest", "--exp-pc-shift", "templates"], 5)):
        out = tmp_path / f"m{e_u}"
        assert main([*args, "--out", str(out), *opts]) == 0
        assert f'"loaded_exp": {e_u}' in capsys.readouterr().out
        kw = {"match_exp": "nearest", "exp_pc_shift": "templates"} if opts else {}
        want = merge_maps(loaded, partial, 2, **kw).state
        assert np.array_equal(load_state(out, load_config(cfg)).exp_pc, want.exp_pc)


def test_rotated_pose_cell_shift_by_hand():
    """pc_shift_rotate: offsets from the matched cells turn with the heading shift."""
    from torchratslam.maps.merge import _rotate_shift

    dims = np.array([10.0, 10.0, 36.0])
    src, dst = np.array([1.0, 1.0, 0.0]), np.array([5.0, 5.0, 9.0])  # +9 th cells = +90 deg
    pcs = np.array([[2.0, 1.0, 3.0], [1.0, 0.0, 35.0], [9.0, 1.0, 0.0]])  # (+1,0), (0,-1), (-2,0)
    got = _rotate_shift(pcs, src, dst, dims)
    want = np.array([[5.0, 6.0, 12.0], [6.0, 5.0, 8.0], [5.0, 3.0, 9.0]])
    assert np.allclose(got, want, atol=1e-12)
    # no heading shift: the paper's translation
    dst0 = np.array([5.0, 5.0, 0.0])
    assert np.allclose(_rotate_shift(pcs, src, dst0, dims), np.mod(pcs + dst0 - src, dims))


def test_rotated_shift_without_heading_change_equals_the_papers_shift():
    rng = np.random.default_rng(3)
    loaded, partial, _ = split(rng, pc_off=(5.4, 7.9, 0.0))
    a = merge_maps(loaded, partial, loaded_template=2).state
    b = merge_maps(loaded, partial, loaded_template=2, pc_shift_rotate=True).state
    assert np.allclose(a.template_pc, b.template_pc, atol=1e-9)
    assert np.allclose(a.exp_pc, b.exp_pc, atol=1e-9)
