"""Optuna studies: best config as a ready YAML, history, plots, resume, constraints."""

import csv

import pytest

from torchratslam.config import load_config
from torchratslam.errors import ConfigError, InputError
from torchratslam.sweeps.tune import parse_range

optuna = pytest.importorskip("optuna", reason="optuna (the 'tune' extra) is not installed")
from torchratslam.sweeps import tune  # noqa: E402

DATA = "sim:loop?laps=1&frames=20&lasers=0"
SPACE = {"vt_match_threshold": "0.03:0.1", "pc_vt_inject_energy": "0.05:0.3:log"}
FIXED = {"pc_dim_xy": 21, "exp_loops": 5}


def _history(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_study_writes_best_config_history_and_plots_then_resumes(tmp_path):
    kw = dict(
        config="virtual_tour",
        fixed=FIXED,
        workers=1,
        progress=False,
        out=tmp_path,
        map_penalty=0.001,
    )
    res = tune(DATA, SPACE, trials=3, **kw)
    hist = _history(tmp_path / "history.csv")
    assert len(hist) == res["trials"] == 3
    assert all(h["state"] == "complete" for h in hist)
    for h in hist:  # the objective: ATE plus the map penalty per experience
        assert float(h["value"]) == pytest.approx(
            float(h["ate_m"]) + 0.001 * float(h["experiences"]), rel=1e-12
        )
        assert 0.03 <= float(h["vt_match_threshold"]) <= 0.1
    best = min(hist, key=lambda h: float(h["value"]))
    assert res["best_value"] == pytest.approx(float(best["value"]))
    cfg = load_config(tmp_path / "best.yaml")  # a ready config
    assert cfg.local_view.vt_match_threshold == pytest.approx(float(best["vt_match_threshold"]))
    assert cfg.pose_cells.pc_vt_inject_energy == pytest.approx(float(best["pc_vt_inject_energy"]))
    assert cfg.pose_cells.pc_dim_xy == 21
    assert (tmp_path / "optimization_history.png").stat().st_size > 0
    assert (tmp_path / "param_importances.png").stat().st_size > 0
    with pytest.raises(InputError, match="resume"):
        tune(DATA, SPACE, trials=4, **kw)
    res2 = tune(DATA, SPACE, trials=4, resume=True, **kw)
    hist2 = _history(tmp_path / "history.csv")
    assert len(hist2) == res2["trials"] == 4
    assert hist2[:3] == hist  # finished trials kept, not redone


def test_constraint_on_map_size(tmp_path):
    res = tune(
        DATA,
        {"vt_match_threshold": "0.03:0.12"},
        config="virtual_tour",
        fixed=FIXED,
        trials=4,
        max_experiences=15,
        workers=1,
        progress=False,
        out=tmp_path,
    )
    hist = _history(tmp_path / "history.csv")
    feasible = [h for h in hist if float(h["experiences"]) <= 15]
    if feasible:
        assert res["best_value"] == pytest.approx(min(float(h["value"]) for h in feasible))
    else:
        assert res["best_value"] is None


def test_ranges():
    r = parse_range("k", "0.1:2:log")
    assert (r.low, r.high, r.log, r.integer) == (0.1, 2.0, True, False)
    assert parse_range("k", "1:9:int").integer
    assert parse_range("k", "alpha,gtsam").choices == ("alpha", "gtsam")
    assert parse_range("k", [0.5, 1.5]).high == 1.5
    for bad in ("2:1", "0:1:log", "1:2:cubic", "x"):
        with pytest.raises(ConfigError):
            parse_range("k", bad)
    with pytest.raises(ConfigError, match="vt_match_threshold"):
        tune(DATA, {"vt_match_thresold": "0.1:0.2"}, trials=1, progress=False)


def test_a_trials_ate_says_the_frames_it_is_over(tmp_path):
    from torchratslam.sweeps import sweep

    tune(DATA, SPACE, config="virtual_tour", fixed=FIXED, trials=2, seeds=[0, 1], workers=1,
         progress=False, out=tmp_path)  # fmt: skip
    hist = _history(tmp_path / "history.csv")
    # the same runs as a sweep: each says the frames its ATE is over; a trial sums its runs'
    first = float(hist[0]["vt_match_threshold"])
    grid = {"base": "virtual_tour", "set": FIXED, "datasets": [DATA], "seeds": [0, 1],
            "parameters": {"vt_match_threshold": [first]}}  # fmt: skip
    rows = sweep(grid, workers=1, figures=False)
    rows = rows.to_dict("records") if hasattr(rows, "to_dict") else rows
    assert len(rows) == 2 and all(r["ate_frames"] >= 3 for r in rows)
    assert [int(h["ate_frames"]) for h in hist] == [sum(r["ate_frames"] for r in rows)] * 2
