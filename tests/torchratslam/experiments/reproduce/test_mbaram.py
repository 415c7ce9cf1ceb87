"""The MBARAM paper's experiments, quick versions: real behaviour of each report."""

from __future__ import annotations

import json

import numpy as np
import pytest

from torchratslam.experiments.mbaram_tour import PRESETS, sim_session
from torchratslam.experiments.reproduce.catalogue import get_experiment
from torchratslam.experiments.reproduce.mbaram import (
    _INDOOR,
    _OUTDOOR,
    PAPER_INDOOR,
    PAPER_OUTDOOR,
    QUICK_CORRIDOR_FRAMES,
    RAWSEEDS_HZ,
    set_frames,
    set_spec,
)
from torchratslam.experiments.reproduce.report import ExperimentContext, write_report
from torchratslam.mbaram.params import MBARAMParams


def rows(report):
    return {r.name: r for r in report.rows}


def test_corridor_quick_published_beside_recommended(tmp_path):
    report = get_experiment("mbaram/corridor").run(ExperimentContext(tmp_path, quick=True))
    write_report(report, tmp_path)
    r = rows(report)
    runs = report.details["runs"]
    pub, rec = runs["published"], runs["recommended"]
    # the stand-in is the paper's single 40 x 5 m corridor, three laps in the quick version
    assert report.details["tour"] == "lab_corridor"
    assert report.details["frames"] == 3 * QUICK_CORRIDOR_FRAMES + 1
    assert rec["frames"] + rec["localisation_frames"] == report.details["frames"]
    # Table 3 as printed: the odometry channel's det(Sigma) <= 1 with the robot on a
    # straight line bounds nothing, so a handful of nodes cover the whole corridor
    assert pub["nodes"] <= 8
    assert rec["nodes"] > 2 * pub["nodes"]
    # the map converges: the second traverse adds fewer nodes than the first
    per = rec["nodes_per_lap"]
    assert len(per) == 2 and per[1] < per[0]
    assert sum(per) == rec["nodes"] == r["nodes (recommended)"].ours
    assert r["nodes added, traverse 1 (recommended)"].paper == 24
    assert r["nodes added, traverse 2 (recommended)"].paper == "5-6"  # the text's figure
    # odometry helps: with it at least as often localised as with the lasers alone
    for run in (pub, rec):
        assert run["localisation_rate_with_odometry"] >= run["localisation_rate_without_odometry"]
    assert rec["localisation_rate_with_odometry"] > 0.9
    assert rec["localisation_rate_with_odometry"] > pub["localisation_rate_with_odometry"] + 0.3
    assert r["localisation with odometry (recommended)"].paper == 97.5
    for f in report.figures:
        assert (tmp_path / f).stat().st_size > 0
    saved = json.loads((tmp_path / "report.json").read_text())
    assert saved["details"]["settings"]["published"] == {}


@pytest.mark.parametrize(
    ("name", "table"), [("rawseeds-indoor", PAPER_INDOOR), ("rawseeds-outdoor", PAPER_OUTDOOR)]
)
def test_rawseeds_quick_reports_tables_4_and_5(tmp_path, name, table):
    report = get_experiment(f"mbaram/{name}").run(ExperimentContext(tmp_path, quick=True))
    write_report(report, tmp_path)
    r = rows(report)
    rec = report.details["runs"]["recommended"]
    pub = report.details["runs"]["published"]
    assert len(rec) == 2 and any("Dynamic" in d for d in rec) and any("Static" in d for d in rec)
    papers = {d: (n, qe, cr) for d, n, qe, cr in table}
    for dataset, m in rec.items():
        assert r[f"{dataset}: nodes (recommended)"].paper == papers[dataset][0]
        assert r[f"{dataset}: nodes (recommended)"].ours == m["nodes"]
        # CR is frames per node (Eq. 15); the published parameters give fewer nodes
        assert m["cr"] == pytest.approx(m["frames"] / m["nodes"])
        assert r[f"{dataset}: scans driven (nodes x CR of the table)"].ours == m["frames"]
        assert pub[dataset]["nodes"] < m["nodes"]
        # the map follows the path: QE (Eq. 14) is a small fraction of the world's size
        assert 0 < m["qe"] < 0.05
        # replaying the mapping frames, odometry localises at least as well as lasers alone
    key = (
        "localisation without odometry, mean over sets (recommended; paper: the mean over "
        "its Rawseeds sets, indoor and outdoor together, Fig. 10)"
    )
    assert r[key].paper == 83.9
    assert {"maps.png", "localisation.png"} == set(report.figures)


@pytest.mark.parametrize(("exp", "table"), [(_INDOOR, PAPER_INDOOR), (_OUTDOOR, PAPER_OUTDOOR)])
def test_rawseeds_sets_are_as_long_as_their_table_row(exp, table):
    # Eq. 15 read as Section 3.4 counts it: a set's scans = its nodes x its CR
    for _name, nodes, _qe, cr in table:
        assert abs(set_frames(nodes, cr) - nodes * cr) <= 0.5
    lengths = {set_frames(n, cr) for _d, n, _q, cr in table}
    assert len(lengths) == len(table)  # every set of the table has its own length
    # the stand-in drives that many frames at the assumed rate and the tour's speed,
    # lapping its route (a short count here: the spec is the same for any count)
    session = sim_session(set_spec(exp, 40, quick=True), laps=1, seed=3, moving=0, moved=0)
    assert len(session) == 40
    step = np.linalg.norm(np.diff(np.asarray(session.poses)[:, :2], axis=0), axis=1)
    assert np.allclose(step, exp.speed / RAWSEEDS_HZ, rtol=0.02)
    dt = np.diff(np.asarray(session.times))
    assert np.allclose(dt, 1.0 / RAWSEEDS_HZ)


def test_rawseeds_dynamic_sets_put_pedestrians_in_the_lasers():
    # the same seed with and without pedestrians: the lasers see them within the quick
    # version's frames, and nowhere else do the scans differ
    spec = set_spec(_INDOOR, _INDOOR.quick_frames, quick=True)
    dyn = sim_session(spec, laps=1, seed=5, moving=_INDOOR.pedestrians, moved=0)
    static = sim_session(spec, laps=1, seed=5, moving=0, moved=0)
    diff = np.array(
        [
            max(
                float(np.abs(dyn.scans(k)[c] - static.scans(k)[c]).max())
                for c in ("laser_front", "laser_rear")
            )
            for k in range(0, len(dyn), 10)
        ]
    )
    assert (diff > 0.3).any()  # a pedestrian blocks beams by more than the laser noise
    assert (diff == 0).any()  # where none is in view the scans are the same


def test_table_3_as_printed_is_the_published_preset():
    # Table 3 (and Section 3.4's list): alpha 0.2 / 0.4 / 0.4, S_MAX 1, sigma_init^2 0.01,
    # P_init 1, read with ranges and positions in metres and one S_MAX for every channel
    p = MBARAMParams.from_dict(PRESETS["paper"])
    assert (p.alpha_odometry, p.alpha_laser_front, p.alpha_laser_rear) == (0.2, 0.4, 0.4)
    assert p.s_max == p.s_max_odometry == 1.0
    assert p.sigma_init_sq == 0.01 and p.p_init == 1.0
    assert p.laser_scale == 1.0 and p.odo_scale == 1.0
    assert p.laser_outlier == 0.0 and p.loc_track_hops == 0
