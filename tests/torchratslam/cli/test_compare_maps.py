"""``torchratslam compare-maps`` end to end on a small simulated run: which map moves,
the human-readable output and the ``--json FILE`` report."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from torchratslam.cli import build_parser, main
from torchratslam.maps.io import load_state
from torchratslam.maps.native import save_map


def test_help_says_which_map_moves():
    parser = build_parser()
    sub = next(a for a in parser._subparsers._group_actions if "compare-maps" in a.choices)
    text = " ".join(sub.choices["compare-maps"].format_help().split())
    assert "examples:" in text
    assert "A, the single-session map (LibICP's template), is moved onto B" in text
    assert "--json FILE" in text


def test_a_is_moved_onto_b_and_json_goes_to_a_file(small_run, tmp_path, capsys):
    out, cfg = small_run.out, small_run.config
    src = load_state(out)
    moved = src.copy()  # A = B moved by a known rigid motion
    a, t = 0.03, np.array([0.05, -0.02])
    c, s = math.cos(a), math.sin(a)
    moved.exp_pose[:, :2] = src.exp_pose[:, :2] @ np.array([[c, -s], [s, c]]).T + t
    save_map(moved, tmp_path / "moved")
    assert main(["convert", str(out), str(tmp_path / "ref"), "--to", "reference"]) == 0
    capsys.readouterr()
    fig, js = tmp_path / "fig10.png", tmp_path / "cmp" / "report.json"
    argv = ["compare-maps", str(tmp_path / "moved"), str(out), "--json", str(js)]
    assert main([*argv, "--figure", str(fig)]) == 0
    text = capsys.readouterr().out
    assert "A moved onto B" in text and f"json: {js}" in text and not text.startswith("{")
    rep = json.loads(js.read_text())
    ic = rep["icp"]
    assert ic["libicp_mse_m2"] < 1e-12 and ic["icp_rmse_m"] < 1e-6
    assert ic["units"]["libicp_mse_m2"] == "m^2" and ic["units"]["icp_rmse_m"] == "m"
    # the transform takes A (moved) back onto B (fixed)
    assert ic["transform"]["dth_rad"] == pytest.approx(-a, abs=1e-6)
    assert rep["a"]["path"] == str(tmp_path / "moved") and "moved onto B" in rep["roles"]
    assert rep["b"]["ate_rmse_m"] is not None  # the run's dataset has ground truth
    assert rep["groundtruth"] == "sim:loop?laps=1&frames=40"
    assert fig.is_file() and fig.stat().st_size > 0
    # a reference-format map (no creation times) against the run, as text only
    argv = ["compare-maps", str(tmp_path / "ref"), str(out), "--config", str(cfg)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "LibICP residual" in text and "m^2" in text and "ICP RMSE" in text
    assert "(reference)" in text and "(native)" in text and "start rotations" in text
    assert main([*argv, "--json", str(js), "--overwrite"]) == 0  # replaces the first
    rep = json.loads(js.read_text())  # no run of its own: judged against no other's
    assert rep["a"]["ate_rmse_m"] is None and "--groundtruth" in rep["a"]["ate_note"]
    assert main([*argv, "--json", str(js), "--groundtruth", small_run.data,
                 "--overwrite"]) == 0  # fmt: skip
    rep = json.loads(js.read_text())
    assert rep["a"]["ate_rmse_m"] is None and "creation times" in rep["a"]["ate_note"]
    assert rep["icp"]["libicp_mse_m2"] < 1e-20  # the same positions


def test_compare_maps_errors_are_one_line(tmp_path, capsys):
    assert main(["compare-maps", str(tmp_path / "nope"), str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "not found" in err and err.count("\n") == 2  # the message and the --debug hint


def test_ground_truth_of_another_dataset_is_refused(small_run, capsys):
    out = small_run.out  # a map of sim:loop
    argv = ["compare-maps", str(out), str(out), "--groundtruth", "sim:virtual_tour"]
    assert main(argv) == 2
    line = capsys.readouterr().err.splitlines()[0]  # one line (then the --debug hint)
    assert "sim:virtual_tour" in line and "ground truth" in line and "[InputError]" in line
    assert main(["compare-maps", str(out), str(out), "--groundtruth", small_run.data]) == 0


def test_each_run_is_judged_against_its_own_ground_truth(small_run, tmp_path, capsys):
    """compare-maps A B, two runs of different data: B's ATE is taken against B's own
    ground truth (it used to be judged against A's)."""
    from torchratslam.experiments.compare_maps import _try_gt, map_ate

    a = small_run.out
    b = tmp_path / "b"
    data_b = "sim:loop?laps=1&frames=30"
    argv = ["run", "--config", str(small_run.config), "--data", data_b, "--out", str(b)]
    assert main([*argv, "--no-progress"]) == 0
    js = tmp_path / "cmp.json"
    capsys.readouterr()
    assert main(["compare-maps", str(a), str(b), "--json", str(js)]) == 0
    rep = json.loads(js.read_text())
    assert rep["b"]["groundtruth"] == data_b
    want, _, _ = map_ate(load_state(b), _try_gt(data_b))
    assert rep["b"]["ate_rmse_m"] == pytest.approx(want, rel=1e-12)
    wrong, _, _ = map_ate(load_state(b), _try_gt(rep["a"]["groundtruth"]))
    assert abs(rep["b"]["ate_rmse_m"] - wrong) > 1e-6


def _se2_ate(p, q):
    """Least-squares rotation + translation of p onto q (closed form), then the RMSE."""
    pc, qc = p - p.mean(0), q - q.mean(0)
    th = math.atan2(
        float(np.sum(pc[:, 0] * qc[:, 1] - pc[:, 1] * qc[:, 0])),
        float(np.sum(pc[:, 0] * qc[:, 0] + pc[:, 1] * qc[:, 1])),
    )
    c, s = math.cos(th), math.sin(th)
    moved = pc @ np.array([[c, -s], [s, c]]).T + q.mean(0)
    return float(np.sqrt(np.mean(np.sum((moved - q) ** 2, axis=1))))


def test_every_ate_names_its_alignment_and_counts_only_poses_with_ground_truth(
    small_run, tmp_path, capsys
):
    """A ground truth covering part of the map's times: the ATE is taken over the
    experiences inside it (none clamped to its ends), named SE(2)-aligned, with the
    count, in the JSON and on the terminal."""
    from torchratslam.experiments.compare_maps import load_groundtruth

    out = small_run.out
    gt = load_groundtruth("sim:loop?laps=1&frames=40")
    state = load_state(out)
    cut = float(np.quantile(state.exp_t, 0.7))
    part = gt[gt[:, 0] <= cut]
    csv = tmp_path / "gt.csv"
    np.savetxt(csv, part, delimiter=",", header="t,x,y,theta", comments="")
    js = tmp_path / "cmp.json"
    capsys.readouterr()
    assert (
        main(["compare-maps", str(out), str(out), "--groundtruth", str(csv), "--json", str(js)])
        == 0
    )
    text = capsys.readouterr().out
    rep = json.loads(js.read_text())
    inside = state.exp_t <= part[-1, 0] + 1e-9
    n = int(inside.sum())
    assert 3 <= n < state.n_experiences
    truth = np.column_stack(
        [np.interp(state.exp_t[inside], part[:, 0], part[:, k]) for k in (1, 2)]
    )
    want = _se2_ate(state.exp_pose[inside, :2], truth)
    for key in ("a", "b"):
        r = rep[key]
        assert r["ate_alignment"] == "SE(2)" and r["ate_poses"] == n
        assert r["ate_over"] == "experiences at their creation times"
        assert r["ate_rmse_m"] == pytest.approx(want, rel=1e-9, abs=1e-12)
    assert f"SE(2)-aligned, experiences at their creation times: {n} of " in text
