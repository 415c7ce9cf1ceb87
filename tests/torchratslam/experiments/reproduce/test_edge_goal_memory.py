"""edge/goal-memory, quick: goal memory beside the experience map on the same exploration."""

import json

from torchratslam.experiments.reproduce.edge_goal_memory import EXPERIMENTS
from torchratslam.experiments.reproduce.report import ExperimentContext, write_report


def test_goal_memory_quick_runs_both_systems_on_the_same_goals(tmp_path):
    report = EXPERIMENTS[0].run(ExperimentContext(out=tmp_path, quick=True, seed=0))
    write_report(report, tmp_path)
    d = json.loads((tmp_path / "report.json").read_text())
    per = d["details"]["matrices"]
    assert set(per) == {"100x40x36", "40x20x36"}
    for m in per.values():
        gm, em = m["goal_memory"], m["experience_map"]
        assert [t["goal"] for t in gm["trials"]] == [t["goal"] for t in em["trials"]]
        assert em["reached"] >= em["goals"] - 1
        assert 0 < m["cells_colliding"] <= m["cells_visited"]
        assert m["goal_memory_links"] > 0 and m["cells_reachable_from_start"] > 1
    # the smaller matrix folds the same floor onto fewer cells: more of them collide
    small, large = per["40x20x36"], per["100x40x36"]
    assert small["cells_colliding"] / small["cells_visited"] > (
        large["cells_colliding"] / large["cells_visited"]
    )
    for f in d["figures"]:
        assert (tmp_path / f).stat().st_size > 0


def test_a_trial_starting_at_its_goal_has_no_path_ratio():
    import numpy as np

    from torchratslam.experiments.reproduce.edge_goal_memory import summary
    from torchratslam.navigation.agent import Goal, Trial

    def trial(name, reached, path, shortest):
        empty = np.zeros((0, 2))
        return Trial(Goal(name, (0.0, 0.0), 0), reached, path, shortest, 1.0, (), empty, empty)

    got = summary([trial("A", True, 0.0, 0.0), trial("B", True, 30.0, 20.0),
                   trial("C", False, 9.0, 3.0), trial("D", True, 20.0, 10.0)])  # fmt: skip
    assert got["reached"] == 3 and got["goals"] == 4
    assert got["median_path_ratio"] == np.median([30.0 / 20.0, 20.0 / 10.0])  # not 0/0
    assert summary([trial("A", True, 0.0, 0.0)])["median_path_ratio"] is None
