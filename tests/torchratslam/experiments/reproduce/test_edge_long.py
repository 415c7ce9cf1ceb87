"""edge/full-length: the loop-closure and memory measures, and the quick run."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from torchratslam.errors import InputError
from torchratslam.experiments.reproduce.edge_long import (
    EXPERIMENTS,
    first_loop_closure,
    memory_per_experience,
)
from torchratslam.experiments.reproduce.report import ExperimentContext, write_report


def _square_loop(side: float, n_side: int, turn_bias: float):
    """A square driven once round and on: true poses, and odometry whose turns are off
    by ``turn_bias`` rad each corner."""
    step = side / n_side
    odo, truth = [], []
    x = y = th = 0.0
    for corner in range(6):
        for i in range(n_side):
            turn = (math.pi / 2 + (turn_bias if corner else 0.0)) if i == 0 and corner else 0.0
            true_turn = math.pi / 2 if i == 0 and corner else 0.0
            th += true_turn
            x, y = x + step * math.cos(th), y + step * math.sin(th)
            truth.append((x, y, th))
            odo.append((step, turn, 1.0))
    return np.array(truth), np.array(odo)


def test_the_first_loop_is_where_an_old_experience_comes_back_and_its_error_is_measured():
    truth, odo = _square_loop(10.0, 20, 0.05)
    f = len(truth)
    # an experience per frame on the first lap; then the map closes onto experience 3
    exp_frames = np.arange(80)
    exp_ids = np.r_[np.arange(80), np.arange(3, 3 + f - 80)] % 80
    got = first_loop_closure(exp_ids, exp_frames, truth, odo, min_loop_m=20.0)
    assert got is not None
    k, j = got["frame"], got["learnt_frame"]
    assert (k, j) == (80, 3)  # frame 80 is back on experience 3
    assert math.isclose(got["loop_m"], 0.5 * (k - j))
    # brute force: integrate the odometry from frame j to k by hand
    x = y = th = 0.0
    for vt, vr, dt in odo[j + 1 : k + 1]:
        th += vr * dt
        x, y = x + vt * dt * math.cos(th), y + vt * dt * math.sin(th)
    tj = truth[j]
    d = truth[k, :2] - tj[:2]
    c, s = math.cos(tj[2]), math.sin(tj[2])
    true_local = (c * d[0] + s * d[1], -s * d[0] + c * d[1])
    # (the dead-reckoned heading at j is the true one plus the bias of the corners before j)
    assert math.isclose(
        got["odometry_error_m"], math.hypot(x - true_local[0], y - true_local[1]), rel_tol=1e-9
    )
    assert got["odometry_error_m"] > 0.5  # four biased corners leave a visible gap
    # no old experience ever comes back: no loop
    assert first_loop_closure(np.arange(f) % 80, np.arange(80), truth, odo, 200.0) is None


def test_memory_counts_experiences_links_and_templates():
    m, links = 4, np.array([0, 0, 1, 2, 0])
    exps = {"pose": np.zeros((m, 3)), "template": np.zeros(m, np.int64)}
    link = {"ends": np.zeros((5, 2), np.int64), "d": np.zeros(5, np.float32)}
    views = {"view": np.zeros((3, 2, 2), np.float32)}
    got = memory_per_experience(exps, link, links, views)
    per_exp, per_link, per_template = 24 + 8, 16 + 4, 16
    assert got["total_bytes"] == m * per_exp + 5 * per_link + 3 * per_template
    assert got["mean_bytes"] == got["total_bytes"] / m
    assert got["max_bytes"] == per_exp + 3 * per_link + per_template  # experience 0: 3 links
    with pytest.raises(InputError, match="different lengths"):
        memory_per_experience({"a": np.zeros(3), "b": np.zeros(4)}, link, links, views)


def test_the_quick_full_length_run_reports_section_seven(tmp_path):
    report = EXPERIMENTS[0].run(ExperimentContext(out=tmp_path, quick=True, seed=0))
    write_report(report, tmp_path)
    d = json.loads((tmp_path / "report.json").read_text())
    rows = {r["name"]: r for r in d["rows"]}
    assert rows["experiences"]["ours"] > 50 and rows["experiences"]["paper"] == 6000
    assert rows["memory per experience, most"]["paper"] == 6.7
    assert (
        rows["memory per experience, most"]["ours"] >= rows["memory per experience, mean"]["ours"]
    )
    assert d["details"]["first_loop"] is not None
    assert d["details"]["first_loop"]["loop_m"] >= 8.0
    for f in d["figures"]:
        assert (tmp_path / f).stat().st_size > 0
