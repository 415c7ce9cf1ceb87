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
