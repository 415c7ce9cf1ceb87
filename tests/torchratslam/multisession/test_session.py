"""Multisession mapping end to end on the simulated virtual tour, exact save/load
continuation, and the multisession CLI."""

from __future__ import annotations

import json

import networkx as nx
import numpy as np
import pytest
import torch

from torchratslam.config import load_config
from torchratslam.errors import ConfigError
from torchratslam.experiments.multisession_seeds import (
    RECOMMENDED_MERGE_OPTIONS,
    RECOMMENDED_SESSION_OPTIONS,
)
from torchratslam.maps.native import load_state
from torchratslam.maps.running import apply_state, save_state, state_from_slam
from torchratslam.maps.state import MapState
from torchratslam.multisession.session import MultiSessionRatSLAM
from torchratslam.pipeline import RatSLAM
from torchratslam.sim import get_tour

torch.set_num_threads(1)

# the shipped virtual-tour config, unmodified (the paper's Table 1: vt_step_match 2)
CONFIG = load_config("virtual_tour")
# the paper's claims below are checked with the recommended merge (a match confirmed by the
# next new template, the maps joined where the view matches best, the shift turned by the
# heading shift): on this stretch it stays within one experience of the continuous run
# and makes more than 3 new ones without the shift; the paper's merge gives 39 against 37
OWN = CONFIG
MERGE = {"merge_options": RECOMMENDED_MERGE_OPTIONS, **RECOMMENDED_SESSION_OPTIONS}


@pytest.fixture(scope="module")
def tour():
    return get_tour("virtual_tour")


@pytest.fixture(scope="module")
def session1_map(tour):
    slam = RatSLAM(CONFIG)
    slam.run(tour.sessions[0].frames(), progress=False)
    return state_from_slam(slam)


LAP2 = 175  # into the second lap: past session 1's path, the unmapped stretch and the
# start of session 2 (the partial map's region), where unshifted associations show


@pytest.fixture(scope="module")
def session2(tour, session1_map):
    return run_session2(tour, session1_map, LAP2)


@pytest.fixture(scope="module")
def own_session1_map(tour):
    slam = RatSLAM(OWN)
    slam.run(tour.sessions[0].frames(), progress=False)
    return state_from_slam(slam)


@pytest.fixture(scope="module")
def own_session2(tour, own_session1_map):
    return run_session2(tour, own_session1_map, LAP2, config=OWN, **MERGE)


def run_session2(tour, stored, frames, config=CONFIG, **kw):
    ms = MultiSessionRatSLAM(config, [stored], session="session2", **kw)
    counts = []
    ms.run(
        tour.sessions[1].frames(0, frames),
        progress=False,
        callback=lambda r: counts.append((r.frame, r.templates, r.experiences)),
    )
    return ms, np.array(counts)


def test_saved_state_continues_exactly_as_if_never_saved(tour, tmp_path):
    frames = list(tour.sessions[0].frames(0, 50))
    a = RatSLAM(CONFIG)
    a.run(frames[:25], progress=False)
    save_state(a, tmp_path / "run")
    b = RatSLAM(CONFIG)
    apply_state(load_state(tmp_path / "run"), b)
    assert state_from_slam(b).equals(state_from_slam(a))
    a.run(frames[25:], progress=False)
    b.run(frames[25:], progress=False)
    sa, sb = state_from_slam(a), state_from_slam(b)
    assert sa.n_templates > 10 and sa.n_experiences > 10
    assert sb.equals(sa)  # bit for bit: activity, templates, poses, links, ids
    assert np.array_equal(a.trajectory()[25:, 2:], b.trajectory()[:, 2:])


@pytest.mark.slow
def test_session2_merges_with_session1_and_retraverses_without_new_experiences(
    tour, session1_map, session2
):
    ms, counts = session2
    assert len(ms.merges) == 1
    m = ms.merges[0]
    # session 2 reaches session 1's start after about 19 frames
    assert 15 <= m["frame"] <= 22 and m["scenario"] == "ii" and m["map"] == 0
    after = counts[counts[:, 0] > m["frame"] + 2]
    retraverse = after[after[:, 0] < m["frame"] + len(tour.sessions[0]) - 5]
    # on session 1's path: neither new templates nor new experiences
    assert retraverse[:, 2].max() == retraverse[:, 2].min()
    assert retraverse[:, 1].max() == retraverse[:, 1].min()
    at_end_of_retraverse = retraverse[-1, 2]
    assert at_end_of_retraverse == session1_map.n_experiences + m["experiences_added"]
    st = ms.get_map()
    assert nx.is_weakly_connected(ms.experience_map.graph)
    # the loaded map's templates are untouched and come first
    assert np.array_equal(st.templates[: session1_map.n_templates], session1_map.templates)
    # the trajectory is in the merged map's frame: no frame refers to a dropped id
    traj = ms.trajectory()
    # (frame 0 has no experience: OpenRatSLAM's first action comes at frame 1)
    assert traj[0, 2] == -1 and np.isfinite(traj[1:, 3:]).all()
    assert traj[:, 2].max() < st.n_experiences


@pytest.mark.slow
def test_multisession_map_has_as_many_experiences_as_the_continuous_single_session(
    tour, own_session2
):
    """The paper's comparison: the same stretch driven in one continuous session (session
    1, on through the unmapped quarter, then session 2) gives the same number of
    experiences, within one (2% of this map is less than one), and a map of the same
    shape (the recommended merge)."""
    from torchratslam.eval.metrics import icp

    ms, _ = own_session2
    cont = tour.continuous()
    start2 = {p["name"]: p["start"] for p in cont.info["parts"]}["session2"]
    single = RatSLAM(OWN)
    single.run(cont.frames(0, start2 + LAP2), progress=False)
    n_single = state_from_slam(single).n_experiences
    n_multi = ms.get_map().n_experiences
    assert n_single > 20
    assert abs(n_multi - n_single) <= 1
    m = ms.get_map().exp_pose[:, :2]
    s = state_from_slam(single).exp_pose[:, :2]
    lap = tour.routes["ellipse"].length
    assert icp(m, s).rmse < 0.02 * lap


@pytest.mark.slow
def test_without_the_pose_cell_shift_new_experiences_appear(tour, own_session1_map, own_session2):
    _, c1 = own_session2
    plain, c2 = run_session2(
        tour, own_session1_map, LAP2, config=OWN, shift_pose_cells=False, **MERGE
    )
    assert len(plain.merges) == 1 and not plain.merges[0]["pc_shift_applied"]
    assert c2[-1, 2] > c1[-1, 2] + 3


def test_first_view_in_a_stored_map_continues_there(tour, session1_map):
    """Scenario (i): the session starts where session 1 started."""
    ms = MultiSessionRatSLAM(CONFIG, [session1_map], session="again")
    ms.run(tour.sessions[0].frames(0, 30), progress=False)
    assert [m["frame"] for m in ms.merges] == [0] and ms.merges[0]["scenario"] == "i"
    st = ms.get_map()
    assert st.n_experiences == session1_map.n_experiences
    assert st.n_templates == session1_map.n_templates
    assert ms.merges[0]["loaded_exp"] == 0


def test_an_incompatible_stored_map_is_refused(session1_map):
    from torchratslam.errors import MapFormatError

    with pytest.raises(MapFormatError, match="pc_dim_xy = 80 in the map but 40"):
        MultiSessionRatSLAM(CONFIG.replace(pc_dim_xy=40), [session1_map])


@pytest.mark.slow
def test_multisession_cli_writes_the_report(tmp_path, capsys):
    from torchratslam.cli import main

    out = tmp_path / "ms"
    code = main(
        [
            "multisession",
            "--tour",
            "sim:virtual_tour",
            "--out",
            str(out),
            "--max-frames",
            "10",
            "--quiet",
            "--ablation",
        ]
    )
    assert code == 0
    rep = json.loads((out / "report.json").read_text())
    for key in ("single", "single_concatenated", "multi", "ablation_no_pc_shift"):
        assert {"templates", "experiences", "links", "ate_rmse_m"} <= set(rep[key])
    assert rep["single_kind"] == "continuous"
    assert rep["config"]["vt_step_match"] == 2  # the shipped config, unmodified
    assert "icp_rmse" in rep and isinstance(rep["merges"], list)
    assert (out / "multi" / "session1" / "state" / "state.json").exists()
    assert (out / "fig9a_single.png").exists() and (out / "report.md").exists()
    assert "ICP RMSE" in capsys.readouterr().out


@pytest.mark.slow
def test_two_stored_maps_are_merged_one_after_the_other(tour):
    """kappa = 2: session 1 split in two separately mapped halves; session 2 meets the
    first half, then the second, and ends in one connected map."""
    frames = list(tour.sessions[0].frames())
    halves = []
    for part in (frames[:50], frames[56:]):
        slam = RatSLAM(CONFIG)
        slam.run(part, progress=False)
        halves.append(state_from_slam(slam))
    ms = MultiSessionRatSLAM(CONFIG, halves, names=["first", "second"], session="s2")
    ms.run(tour.sessions[1].frames(0, 100), progress=False)
    assert [m["map_name"] for m in ms.merges] == ["first", "second"]
    assert ms.merges[0]["frame"] < 25 < 19 + 56 - 3 <= ms.merges[1]["frame"] <= 19 + 56 + 5
    assert ms.pending == [] and nx.is_weakly_connected(ms.experience_map.graph)
    st = ms.get_map()
    # every template of both halves is kept, in the merged map's order: second, first, new
    assert st.n_templates >= halves[0].n_templates + halves[1].n_templates
    assert np.array_equal(st.templates[: halves[1].n_templates], halves[1].templates)


def _joined_distance(tour, merge):
    """Ground-truth distance (m) between the two experiences a merge joined (1 Hz: a
    session's time is its frame index)."""
    s1, s2 = tour.sessions
    a = s1.poses[round(merge["loaded_exp_t"]), :2]
    b = s2.poses[round(merge["partial_exp_t"]), :2]
    return float(np.linalg.norm(a - b))


def _merged_at_template_and_at_view(seed: int):
    """Session 1 of the virtual tour stored, session 2's first 40 frames merged with the
    recommended merge anchored at the template and at the view."""
    tour = get_tour("virtual_tour", seed=seed)
    slam = RatSLAM(CONFIG)
    slam.run(tour.sessions[0].frames(), progress=False)
    stored = state_from_slam(slam)
    kw = {"merge_options": RECOMMENDED_MERGE_OPTIONS, **RECOMMENDED_SESSION_OPTIONS}
    assert kw["merge_anchor"] == "view"  # the recommended merge anchors at the view
    at_template, _ = run_session2(tour, stored, 40, **{**kw, "merge_anchor": "template"})
    at_view, _ = run_session2(tour, stored, 40, **kw)
    return tour, stored, at_template, at_view


def test_the_view_anchor_joins_the_maps_where_the_view_matches_best():
    # seed 26: session 2's second matching template is learnt 3 frames before the stored
    # template it matches (the templates of the two sessions are learnt out of step), so
    # the merge at the template joins places 1.2 m apart; following the view to its best
    # match joins them within one frame (0.4 m)
    tour, stored, at_template, at_view = _merged_at_template_and_at_view(26)
    (mt,), (mv,) = at_template.merges, at_view.merges
    assert _joined_distance(tour, mt) > 1.0
    assert _joined_distance(tour, mv) <= 0.5
    # the merge waited for the view's best match, which is better than the template's
    assert mv["frame"] > mt["frame"] and mv["error"] < mt["error"]
    # the view the maps were joined at became the stored template: no template added
    # for it, and the merged map is one connected map
    partial = at_view.snapshots[0]["partial_state"]
    merged = at_view.snapshots[0]["merged_state"]
    assert merged.n_templates == stored.n_templates + partial.n_templates - 1 - len(mv["absorbed"])
    # the appended place: the last template and experience, linked from the one before
    assert partial.exp_template[-1] == partial.n_templates - 1
    assert partial.link_to[-1] == partial.n_experiences - 1
    assert partial.link_from[-1] == partial.n_experiences - 2
    assert nx.is_weakly_connected(at_view.experience_map.graph)


def test_the_view_anchor_looks_back_to_the_streaks_first_match():
    # seed 3004: session 2's first matching template is learnt 7 frames before session
    # 1's first template, the confirming one 3 frames after it; the best view lies
    # between them, passed before the match was confirmed. Joined at the confirming
    # template the places are 1.2 m apart; the view anchor joins them at the passed
    # frame of the best view (one frame from the stored experience, made at frame 1)
    tour, stored, at_template, at_view = _merged_at_template_and_at_view(3004)
    (mt,), (mv,) = at_template.merges, at_view.merges
    assert _joined_distance(tour, mt) > 1.0
    assert _joined_distance(tour, mv) <= 0.5
    # joined at a frame passed before the confirming template (the template merge's frame)
    assert mv["partial_exp_t"] < mt["frame"] and mv["error"] < mt["error"]
    # the passed place hangs off the experience current then (not the last one), and
    # the robot stays at its current experience
    partial = at_view.snapshots[0]["partial_state"]
    e = partial.n_experiences - 1
    assert partial.exp_t[e] == mv["partial_exp_t"]
    (src,) = partial.link_from[partial.link_to == e]
    assert partial.exp_t[src] < partial.exp_t[e] < partial.exp_t[:e].max()
    assert partial.current_exp != e
    assert nx.is_weakly_connected(at_view.experience_map.graph)
    # the confirming template, learnt 1.2 m past the joined place, is absorbed, and every
    # link between the stored map and the partial one has the merged map's geometry
    # (copied from the dropped experience it would be up to a template spacing off)
    assert mv["absorbed"]
    merged = at_view.snapshots[0]["merged_state"]
    n_loaded = stored.n_experiences
    cross = (merged.link_from < n_loaded) != (merged.link_to < n_loaded)
    assert cross.any()
    p = merged.exp_pose
    gap = np.hypot(*(p[merged.link_to, :2] - p[merged.link_from, :2]).T)
    assert np.allclose(merged.link_d[cross], gap[cross], atol=1e-9)


def _line_map():
    """5 templates, 6 experiences on the x axis (experience i at x = i, facing +x;
    experience 5 at (2, 1) facing +y is template 4, a second view of template 1's
    place), linked in a chain."""
    tpl = np.array([0, 1, 2, 3, 1, 4])
    m, n_t = tpl.size, 5
    pose = np.c_[np.arange(m), np.zeros(m), np.zeros(m)].astype(np.float64)
    pose[5] = (2.0, 1.0, np.pi / 2)
    lf, lt = np.arange(m - 1), np.arange(1, m)
    return MapState(
        config={"pc_dim_xy": 40, "pc_dim_th": 36, "template_x_size": 3, "template_y_size": 2},
        templates=np.arange(n_t * 6, dtype=np.float64).reshape(n_t, 2, 3),
        template_mean=np.arange(n_t, dtype=np.float64),
        template_frame=np.arange(n_t, dtype=np.int64),
        template_pc=np.zeros((n_t, 3)),
        template_decay=np.ones(n_t),
        exp_pose=pose,
        exp_pc=np.zeros((m, 3)),
        exp_template=tpl,
        exp_frame=np.arange(m, dtype=np.int64),
        exp_t=np.arange(m, dtype=np.float64),
        link_from=lf,
        link_to=lt,
        link_d=np.full(m - 1, 7.0),
        link_heading=np.zeros(m - 1),
        link_facing=np.zeros(m - 1),
        link_dt=np.ones(m - 1),
        activity=np.zeros((0, 0, 0)),
        current_vt=4,
        prev_vt=1,
        current_exp=5,
        prev_exp=4,
        frame_index=6,
    ).validate()


def test_absorbed_links_are_measured_between_the_experiences_they_join():
    from torchratslam.maps.merge import fuse_templates
    from torchratslam.multisession.session import _remeasured

    state = _line_map()
    # template 4 onto template 1: the link 4 -> 5 will join 4 to experience 1
    out = _remeasured(state, [(4, 1)])
    changed = np.flatnonzero(out.link_d != state.link_d)
    assert changed.tolist() == [4]  # the only link that ends at experience 5
    assert out.link_d[4] == pytest.approx(3.0)  # from x = 4 back to x = 1
    assert out.link_heading[4] == pytest.approx(np.pi)  # behind the source
    assert out.link_facing[4] == pytest.approx(0.0)  # experience 1 faces +x, as 4 does
    fused, _, applied = fuse_templates(out, [(4, 1)])
    assert applied == [(4, 1)]
    assert list(zip(fused.link_from.tolist(), fused.link_to.tolist()))[-1] == (4, 1)
    assert fused.link_d[-1] == pytest.approx(3.0)
    # pairs fuse_templates skips change nothing
    assert _remeasured(state, [(2, 2), (9, 1)]) is state


def test_an_unknown_merge_anchor_is_refused(session1_map):
    with pytest.raises(ConfigError, match="merge_anchor"):
        MultiSessionRatSLAM(CONFIG, [session1_map], merge_anchor="nearest")


def test_a_refused_step_leaves_the_multisession_mapper_as_it_was(tour, session1_map):
    """Bad odometry is refused before anything changes: the running map, the pending
    maps, the merges and the image kept for a view-anchored merge."""
    from torchratslam.errors import InputError

    ms = MultiSessionRatSLAM(CONFIG, [session1_map], merge_anchor="view")
    frames = list(tour.sessions[1].frames(0, 3))
    for f in frames[:2]:
        ms.step_frame(f)
    before = (ms.get_map(), list(ms.pending), list(ms.merges), ms._image, ms.frame_index)
    for odo in [(1.0, 2.0), (1e300, 0.0, 0.1), (0.1, float("nan"), 0.1)]:
        with pytest.raises(InputError):
            ms.step(frames[2].image, odo)
    after = (ms.get_map(), list(ms.pending), list(ms.merges), ms._image, ms.frame_index)
    assert after[0].equals(before[0]) and after[1:3] == before[1:3]
    assert after[3] is before[3] and after[4] == before[4]
