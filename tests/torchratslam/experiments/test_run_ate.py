"""A run whose map's ATE is above dead reckoning's says why, with its own figures: the
README's first command (a short session that closes no loop) included."""

from __future__ import annotations

import json

import numpy as np

from torchratslam.cli import main
from torchratslam.experiments.run_ate import ate_note


def test_the_readmes_first_command_says_why_its_ate_is_above_dead_reckoning(tmp_path, capsys):
    out = tmp_path / "s1"
    argv = ["run", "--config", "virtual_tour", "--data", "sim:virtual_tour/session1"]
    assert main([*argv, "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out.splitlines()
    m = json.loads((out / "metrics.json").read_text())
    assert m["ate_rmse_m"] > m["dead_reckoning_ate_m"]  # the case this explains
    # the per-frame pose comes back to dead reckoning: the place offset is the gap
    assert m["ate_frame_pose_m"] <= 1.1 * m["dead_reckoning_ate_m"] < m["ate_rmse_m"]
    exp = np.loadtxt(out / "experiences.csv", delimiter=",", skiprows=1)
    steps = np.hypot(*np.diff(exp[:, 1:3], axis=0).T)  # the links join consecutive ids
    assert m["links"] == m["experiences"] - 1  # no loop closed
    assert f"(here {steps.mean():.2f} m between linked experiences on average)" in m["ate_note"]
    assert f"gives {m['ate_frame_pose_m']:.3f} m" in m["ate_note"]
    assert "no loop was closed" in m["ate_note"]
    assert printed[-1] == f"note: {m['ate_note']}"


def test_the_note_says_what_the_figures_say():
    assert ate_note(0.4, 0.5, 0.4, 1.0, 0) is None  # not above dead reckoning: nothing
    assert ate_note(None, 0.5, None, None, 0) is None
    explained = ate_note(0.9, 0.4, 0.41, 1.5, 0)
    assert explained is not None and " because it compares" in explained
    off = ate_note(0.9, 0.4, 0.8, 1.5, 2)
    assert off is not None and "because" not in off
    assert "moved the poses off the odometry (2 loop-closing links)" in off
    resumed = ate_note(0.9, 0.4, None, 1.5, 1)
    assert resumed is not None and "per-frame" not in resumed and "1 loop-closing link" in resumed
