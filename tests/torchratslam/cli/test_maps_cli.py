"""``compare-maps`` and ``convert`` end to end on a small simulated run."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from torchratslam.cli import build_parser, main
from torchratslam.maps.io import load_state
from torchratslam.maps.native import save_map

torch.set_num_threads(1)


@pytest.mark.parametrize("name", ["compare-maps", "convert"])
def test_help_has_examples(name):
    parser = build_parser()
    sub = next(a for a in parser._subparsers._group_actions if name in a.choices).choices[name]
    assert "examples:" in sub.format_help()


def test_convert_both_ways_keeps_what_each_format_holds(small_run, capsys):
    root, out, cfg = small_run.out.parent, small_run.out, small_run.config
    src = load_state(out)
    assert main(["convert", str(out), str(root / "ref"), "--to", "reference", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["source_format"] == "native" and rep["format"] == "reference"
    dropped = " ".join(rep["dropped"])
    for what in ("activity", "exp_t", "exp_frame", "config", "module extras"):
        assert what in dropped, what
    code = main(["convert", str(root / "ref"), str(root / "back"), "--to", "native"])
    assert code == 0 and "read back unchanged" in capsys.readouterr().out
    assert (
        main(
            [
                "convert",
                str(root / "ref"),
                str(root / "back2"),
                "--to",
                "native",
                "--config",
                str(cfg),
            ]
        )
        == 0
    )
    back = load_state(root / "back2")
    for name in ("templates", "template_pc", "exp_pose", "exp_pc", "link_d", "link_dt"):
        assert np.array_equal(getattr(back, name), getattr(src, name)), name
    assert back.templates.shape == src.templates.shape  # shaped by --config
    assert load_state(root / "back").templates.shape == (src.n_templates, 1, 32 * 8)
    # native -> native keeps everything
    assert main(["convert", str(out), str(root / "nat"), "--to", "native"]) == 0
    assert load_state(root / "nat").equals(src)


def test_convert_refuses_to_overwrite_and_detects_a_loss(small_run, tmp_path, monkeypatch, capsys):
    out = small_run.out
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "mine.txt").write_text("keep")
    assert main(["convert", str(out), str(tmp_path / "full"), "--to", "reference"]) == 2
    assert "not empty" in capsys.readouterr().err
    assert (tmp_path / "full" / "mine.txt").read_text() == "keep"

    import torchratslam.maps.io as mio

    real = mio.write_reference

    def lossy(state, d):  # a writer that rounds the experience poses
        state = state.copy()
        state.exp_pose = np.round(state.exp_pose, 3)
        return real(state, d)

    monkeypatch.setattr(mio, "write_reference", lossy)
    assert main(["convert", str(out), str(tmp_path / "x"), "--to", "reference"]) == 2
    assert "would change exp_pose" in capsys.readouterr().err
    assert not (tmp_path / "x").exists() and not list(tmp_path.glob(".x.*"))


def test_compare_maps_prints_both_icp_conventions(small_run, tmp_path, capsys):
    out, cfg = small_run.out, small_run.config
    src = load_state(out)
    moved = src.copy()  # B = A moved by a known rigid motion
    a, t = 0.03, np.array([0.05, -0.02])
    c, s = math.cos(a), math.sin(a)
    moved.exp_pose[:, :2] = src.exp_pose[:, :2] @ np.array([[c, -s], [s, c]]).T + t
    save_map(moved, tmp_path / "moved")
    code = main(["convert", str(out), str(tmp_path / "ref"), "--to", "reference"])
    assert code == 0
    capsys.readouterr()
    fig = tmp_path / "fig10.png"
    argv = ["compare-maps", str(out), str(tmp_path / "moved"), "--json", "--figure", str(fig)]
    assert main(argv) == 0
    rep = json.loads(capsys.readouterr().out)
    ic = rep["icp"]
    assert ic["libicp_mse_m2"] < 1e-12 and ic["icp_rmse_m"] < 1e-6
    assert ic["units"]["libicp_mse_m2"] == "m^2" and ic["units"]["icp_rmse_m"] == "m"
    # the transform takes B back onto A
    assert ic["transform"]["dth_rad"] == pytest.approx(-a, abs=1e-6)
    assert rep["a"]["ate_rmse_m"] is not None  # the run's dataset has ground truth
    assert rep["groundtruth"] == "sim:loop?laps=1&frames=40"
    assert fig.is_file() and fig.stat().st_size > 0
    # a reference-format map (no creation times) against the run, as text
    argv = ["compare-maps", str(tmp_path / "ref"), str(out), "--config", str(cfg)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "LibICP residual" in text and "m^2" in text and "ICP RMSE" in text
    assert "(reference)" in text and "(native)" in text
    assert main([*argv, "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["a"]["ate_rmse_m"] is None and "creation times" in rep["a"]["ate_note"]
    assert rep["icp"]["libicp_mse_m2"] < 1e-20  # the same positions


def test_compare_maps_errors_are_one_line(tmp_path, capsys):
    assert main(["compare-maps", str(tmp_path / "nope"), str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "not found" in err and err.count("\n") == 2  # the message and the --debug hint
