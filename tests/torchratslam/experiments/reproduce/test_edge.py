"""The experience-map paper's experiments, quick versions, through the whole pipeline."""

import json

from torchratslam.experiments.reproduce.edge import EXPERIMENTS
from torchratslam.experiments.reproduce.report import ExperimentContext, write_report


def _run(name, tmp_path):
    exp = next(e for e in EXPERIMENTS if e.id == name)
    report = exp.run(ExperimentContext(out=tmp_path, quick=True, seed=0))
    write_report(report, tmp_path)
    return json.loads((tmp_path / "report.json").read_text())


def test_goal_recall_quick_reaches_goals_on_a_small_floor(tmp_path):
    d = _run("edge/goal-recall", tmp_path)
    trials = d["details"]["trials"]
    assert {t["matrix"] for t in trials} == {"100x40x36", "40x20x36"}
    assert sum(t["reached"] for t in trials) >= len(trials) - 1
    for t in trials:
        if t["reached"]:
            assert t["path_m"] >= 0.5 * t["shortest_m"]
    for f in d["figures"]:
        assert (tmp_path / f).stat().st_size > 0


def test_adaptation_quick_deletes_links_and_reaches_the_goal(tmp_path):
    d = _run("edge/adaptation", tmp_path)
    trials = d["details"]["trials"]
    assert [t["trial"] for t in trials] == [1, 2, 3]
    assert d["details"]["links_deleted_total"] > 0
    assert trials[2]["reached"]
