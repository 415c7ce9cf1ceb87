"""Merges that hold across seeds (the per-seed check, two seeds), the merge
options (a stricter threshold for stored maps, persistence) and the seed parsing."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchratslam.config import load_config
from torchratslam.errors import ConfigError
from torchratslam.experiments.multisession_seeds import (
    ABLATION_MARGIN,
    RECOMMENDED_MERGE_OPTIONS,
    RECOMMENDED_SESSION_OPTIONS,
    WRONG_PLACE_M,
    merge_distances,
    seed_table,
    seed_table_markdown,
)
from torchratslam.multisession.session import MultiSessionRatSLAM
from torchratslam.pipeline import RatSLAM
from torchratslam.sim import get_tour

torch.set_num_threads(1)

CONFIG = load_config("virtual_tour")


def test_parse_seeds():
    from torchratslam.cli.multisession import parse_seeds

    assert parse_seeds("0-9") == list(range(10))
    assert parse_seeds("1,3,5-6") == [1, 3, 5, 6]
    for bad in ("", "a-b", "1-x"):
        with pytest.raises(ConfigError, match="--seeds"):
            parse_seeds(bad)


def test_merge_distances_by_hand():
    gt = np.array([[0.0, 0, 0, 0], [1.0, 3, 4, 0], [2.0, 3, 5, 0]])
    merges = [
        {"loaded_exp_t": 0.1, "partial_exp_t": 1.2},  # (0,0) vs (3,4): 5 m
        {"loaded_exp_t": 1.6, "partial_exp_t": 2.0},  # (3,5) vs (3,5): 0 m
        {"loaded_exp_t": float("nan"), "partial_exp_t": 2.0},
    ]
    d = merge_distances(merges, gt)
    assert d[0] == pytest.approx(5.0) and d[1] == pytest.approx(0.0) and np.isnan(d[2])


def test_bad_merge_options_are_config_errors():
    with pytest.raises(ConfigError, match="merge_threshold"):
        MultiSessionRatSLAM(CONFIG, merge_threshold=0.0)
    with pytest.raises(ConfigError, match="merge_persist"):
        MultiSessionRatSLAM(CONFIG, merge_persist=0)


@pytest.fixture(scope="module")
def stored():
    tour = get_tour("virtual_tour")
    slam = RatSLAM(CONFIG)
    slam.run(tour.sessions[0].frames(), progress=False)
    from torchratslam.maps.running import state_from_slam

    return tour, state_from_slam(slam)


def _first_merge(tour, state, **kw):
    ms = MultiSessionRatSLAM(CONFIG, [state], session="session2", **kw)
    ms.run(tour.sessions[1].frames(0, 45), progress=False)
    return ms.merges[0] if ms.merges else None


@pytest.mark.slow
def test_stricter_threshold_and_persistence_delay_the_merge(stored):
    """A merge that needs a smaller match error, or several matching new templates in a
    row, cannot come earlier than the paper's first match, and comes with a smaller error
    (threshold) or later (persistence)."""
    tour, state = stored
    paper = _first_merge(tour, state)
    assert paper is not None and paper["error"] <= CONFIG.local_view.vt_match_threshold
    strict = _first_merge(tour, state, merge_threshold=0.8 * paper["error"])
    assert strict is None or (
        strict["frame"] > paper["frame"] and strict["error"] <= 0.8 * paper["error"]
    )
    persist = _first_merge(tour, state, merge_persist=2)
    assert persist is None or persist["frame"] > paper["frame"]


def test_cli_seeds_prints_and_writes_the_table(tmp_path, capsys):
    import json

    from torchratslam.cli import main

    out = tmp_path / "seeds"
    code = main(
        [
            "multisession",
            "--tour",
            "sim:virtual_tour",
            "--out",
            str(out),
            "--seeds",
            "0-1",
            "--max-frames",
            "25",
            "--ablation",
        ]
    )
    assert code == 0
    table = json.loads((out / "seeds.json").read_text())
    assert table["seeds"] == [0, 1]
    for row in table["rows"].values():
        assert {"single", "multi", "ablation", "diff", "merges", "wrong_merges"} <= set(row)
    text = (out / "seeds.md").read_text()
    assert "| multi / single |" in text and "ablation" in text
    captured = capsys.readouterr()
    assert "seed 1 (2/2)" in captured.err  # progress
    assert "| multi / single |" in captured.out


@pytest.mark.slow
def test_absorb_identifies_the_streak_with_the_stored_map(stored):
    """merge_persist=2 merges at the second matching new template; with merge_absorb the
    first one (a stored place seen again) is identified with its stored match: same
    merge frame, one template and one experience fewer per absorbed template."""
    tour, state = stored

    def run(**kw):
        ms = MultiSessionRatSLAM(CONFIG, [state], session="session2", merge_persist=2, **kw)
        ms.run(tour.sessions[1].frames(0, 45), progress=False)
        return ms

    plain, absorbed = run(), run(merge_absorb=True)
    assert plain.merges and absorbed.merges
    a, p = absorbed.merges[0], plain.merges[0]
    assert a["frame"] == p["frame"] and p["absorbed"] == []
    n = len(a["absorbed"])
    assert n >= 1
    assert a["templates_added"] == p["templates_added"] - n
    assert a["experiences_added"] <= p["experiences_added"] - n
    # the partial map is the same at both merges; without absorption the merge keeps
    # every partial experience but the matched e_z
    assert a["partial_experiences"] == p["partial_experiences"] >= 2
    assert p["experiences_added"] == p["partial_experiences"] - 1
    assert absorbed.counts()[0] == plain.counts()[0] - n


@pytest.mark.slow
def test_two_seeds_hold_with_the_recommended_merge():
    """The per-seed check on two seeds of the virtual tour, the paper's parameters, the
    default behaviour (OpenRatSLAM) and the recommended merge options (the rotated
    pose-cell shift, a match confirmed by the next new template, the maps joined where
    the view matches best): the merged map is within one experience of the continuous
    single session (measured 36/35 and 38/37), the ablation without the shift at least
    10% more, and both merges join experiences less than 1 m apart in ground truth.
    (With the paper's merge the same seeds give 39/35 and 40/37: measured,
    docs/multisession.md.)"""
    table = seed_table(
        "sim:virtual_tour",
        [2, 6],
        merge_options=RECOMMENDED_MERGE_OPTIONS,
        **RECOMMENDED_SESSION_OPTIONS,
    )
    for seed, row in table["rows"].items():
        assert abs(row["multi"] - row["single"]) <= 1, (seed, row)
        assert row["ablation_diff"] >= ABLATION_MARGIN, (seed, row)
        assert row["merges"] and all(m["distance_m"] <= WRONG_PLACE_M for m in row["merges"])
        # the ablation re-makes at most the partial map's experiences (the only
        # associations the shift moves): the ceiling the per-seed table reports
        (merge,) = row["merges"]  # one merge: its partial map, e_z excluded
        partial = merge["partial_experiences"] - 1
        assert row["partial_experiences"] == partial >= 3
        assert 0 < row["ablation"] - row["multi"] <= partial
        assert row["ablation_ceiling"] == pytest.approx(
            (row["multi"] + partial - row["single"]) / row["single"]
        )
    assert table["ablation_above"] == 2 and table["wrong_merges"] == 0
    assert table["within_one"] == 2 and table["ablation_reachable"] == 2
    text = seed_table_markdown(table)
    assert "| 2 | 6 |" in text
    assert "| partial experiences merged (ablation ceiling) |" in text
    assert "within one experience: 2/2 seeds" in text


def test_place_counts_by_hand():
    """Experiences 1 m apart along a line, back, and along it again: the way back (the
    opposite heading) repeats nothing, the second pass the same way repeats two places;
    the one place only a bridge frame sees is unseen by the sessions."""
    from torchratslam.experiments.multisession_seeds import place_counts
    from torchratslam.maps.state import MapState

    # ground truth: t = 0..5 along +x at x = 0..5, t = 6..8 back along -x at x = 4, 3, 2,
    # t = 9..10 along +x again at x = 1, 2
    xs = [0, 1, 2, 3, 4, 5, 4, 3, 2, 1, 2]
    th = [0.0] * 6 + [np.pi] * 3 + [0.0] * 2
    gt = np.c_[np.arange(11.0), xs, np.zeros(11), th]
    state = MapState.empty({"pc_dim_xy": 9, "pc_dim_th": 12})
    t = np.array([0.0, 1, 2, 3, 4, 5, 7, 9, 10])  # 9 experiences
    state = dataclasses_replace(state, t)
    sessions = np.array([0, 1, 2, 3, 4, 6, 7, 8, 9, 10])  # frame 5 (x = 5) is a bridge
    out = place_counts(state, gt, sessions)
    assert out["radius_m"] == pytest.approx(0.5)
    # t = 9 (x = 1, +x) repeats t = 1, t = 10 (x = 2, +x) repeats t = 2; t = 7 is the way back
    assert out["repeats"] == 2 and out["places"] == 7
    assert out["unseen"] == 1 and out["places_seen"] == 6


def dataclasses_replace(state, t):
    import dataclasses

    m = len(t)
    return dataclasses.replace(
        state,
        exp_pose=np.zeros((m, 3)),
        exp_pc=np.zeros((m, 3)),
        exp_template=np.zeros(m, np.int64),
        exp_frame=np.arange(m, dtype=np.int64),
        exp_t=np.asarray(t, np.float64),
    )


def test_cli_recommended_merge_passes_the_bundle(tmp_path, monkeypatch):
    """``--recommended-merge`` is ``--pc-shift-rotate --merge-persist 2 --merge-absorb
    --merge-anchor view``, and each flag reaches the seed table on its own."""
    import torchratslam.experiments.multisession_seeds as mt
    from torchratslam.cli import main

    seen: list[dict] = []

    def fake_table(tour, seeds, **kw):
        seen.append(kw)
        return {"tour": tour, "seeds": list(seeds), "rows": {}}

    monkeypatch.setattr(mt, "seed_table", fake_table)
    monkeypatch.setattr(mt, "seed_table_markdown", lambda table: "table")
    argv = ["multisession", "--tour", "sim:virtual_tour", "--seeds", "0-1", "--quiet"]
    assert main([*argv, "--out", str(tmp_path / "a"), "--recommended-merge"]) == 0
    assert main([*argv, "--out", str(tmp_path / "b"), "--merge-absorb"]) == 0
    assert main([*argv, "--out", str(tmp_path / "c"), "--merge-anchor", "view"]) == 0
    rec_t = ["--recommended-merge", "--merge-anchor", "template"]
    assert main([*argv, "--out", str(tmp_path / "d"), *rec_t]) == 0
    rec, absorb, anchor, rec_at_template = seen
    assert rec["merge_options"] == mt.RECOMMENDED_MERGE_OPTIONS
    assert {k: rec[k] for k in mt.RECOMMENDED_SESSION_OPTIONS} == mt.RECOMMENDED_SESSION_OPTIONS
    assert rec["merge_anchor"] == "view"
    assert absorb["merge_absorb"] and absorb["merge_persist"] == 1
    assert absorb["merge_anchor"] == "template"  # the paper's, unless asked
    assert "pc_shift_rotate" not in absorb["merge_options"]
    assert anchor["merge_anchor"] == "view" and not anchor["merge_absorb"]
    # the recommended merge without the view anchor (how the anchor was measured)
    assert rec_at_template["merge_anchor"] == "template" and rec_at_template["merge_absorb"]


def test_cli_merge_anchor_reaches_the_experiment(tmp_path, monkeypatch):
    """``--merge-anchor`` reaches :class:`MultisessionOptions` of the one-report run."""
    import torchratslam.experiments.multisession_tour as mtour
    from torchratslam.cli import main

    seen: list = []

    def fake_run(config, tour, out, options, overwrite=False):
        seen.append(options)
        return {"report": {}}

    monkeypatch.setattr(mtour, "run_experiment", fake_run)
    monkeypatch.setattr(
        "torchratslam.experiments.multisession_report.report_markdown", lambda r: "report"
    )
    argv = ["multisession", "--tour", "sim:virtual_tour", "--quiet", "--no-figures"]
    assert main([*argv, "--out", str(tmp_path / "a"), "--merge-anchor", "view"]) == 0
    assert main([*argv, "--out", str(tmp_path / "b")]) == 0
    assert [o.merge_anchor for o in seen] == ["view", "template"]


def test_tour_spec_options_reach_the_simulator():
    """``--tour sim:NAME?key=value`` passes the simulator's options to every seed's tour
    (and records them); a session, a seed in the spec or an unknown option is refused
    with one line naming it."""
    from torchratslam.errors import InputError
    from torchratslam.experiments.multisession_tour import parse_tour_spec

    assert parse_tour_spec("sim:virtual_tour?session2_start=0.82&fog=20") == (
        "virtual_tour",
        {"session2_start": 0.82, "fog": 20},
    )
    assert parse_tour_spec("virtual_tour") == ("virtual_tour", {})
    with pytest.raises(InputError, match="whole tour"):
        parse_tour_spec("sim:virtual_tour/session2")
    with pytest.raises(InputError, match="--seeds"):
        parse_tour_spec("sim:virtual_tour?seed=3")
    table = seed_table("sim:virtual_tour?session2_start=0.82", [0], ablation=False, max_frames=30)
    assert table["tour_options"] == {"session2_start": 0.82}
    assert "- tour options: {'session2_start': 0.82}" in seed_table_markdown(table)
    # the option changed the tour: session 2 starts 8 frames earlier, so its first 30
    # frames merge later than the default tour's
    plain = seed_table("sim:virtual_tour", [0], ablation=False, max_frames=30)
    early_merge = [m["frame"] for m in table["rows"][0]["merges"]]
    plain_merge = [m["frame"] for m in plain["rows"][0]["merges"]]
    assert early_merge and plain_merge and early_merge[0] > plain_merge[0]
    with pytest.raises(InputError, match="did you mean 'session2_start'"):
        seed_table("sim:virtual_tour?sesion2_start=0.82", [0], ablation=False, max_frames=5)


def test_partial_experiences_counts_each_session_once():
    """Two merges in one session (the running map at the second holds the first's
    partial map) count at the second; another session's merge adds its own; each merge
    drops its matched experience e_z; a merge of a one-experience map brings nothing."""
    from torchratslam.experiments.multisession_seeds import partial_experiences

    merges = [
        {"session": "session5", "partial_experiences": 5},
        {"session": "session5", "partial_experiences": 12},
        {"session": "session2", "partial_experiences": 4},
        {"session": "session3", "partial_experiences": 1},
    ]
    assert partial_experiences(merges) == (12 - 1) + (4 - 1) + 0
    assert partial_experiences([]) == 0
