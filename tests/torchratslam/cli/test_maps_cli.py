"""``convert`` end to end on a small simulated run."""

from __future__ import annotations

import json

import numpy as np
import torch

from torchratslam.cli import build_parser, main
from torchratslam.maps.io import load_state

torch.set_num_threads(1)


def test_help_has_examples():
    name = "convert"
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


def test_convert_says_what_it_changed_and_when_a_save_has_no_templates(small_run, capsys):
    root, out = small_run.out.parent, small_run.out
    assert main(["convert", str(out), str(root / "ref"), "--to", "reference"]) == 0
    pvt = root / "ref" / "posecellvisual_templates.txt"
    lines = pvt.read_text().split("\n")
    listed = [int(float(v)) for v in lines[6 + 5].split()]  # template 1's experiences
    lines[6 + 5] = "9.900000000000000000e+01 "  # stale, as the authors' merge leaves one
    pvt.write_text("\n".join(lines))
    capsys.readouterr()
    assert main(["convert", str(root / "ref"), str(root / "nat"), "--to", "native"]) == 0
    text = capsys.readouterr().out
    assert "1 value(s) written differently from the source" in text
    want = f"template 1: experience list [99] -> {listed}"
    assert "changed (a stale list, derived from the map's ids): " in text and want in text
    (root / "ref" / "localviewcells.txt").unlink()
    assert main(["convert", str(root / "ref"), str(root / "nat2"), "--to", "native"]) == 0
    text = capsys.readouterr().out
    n = load_state(out).n_templates
    assert f"no templates (the source has no localviewcells.txt; only {n} template " in text
    assert f": {n} templates" not in text


def _tree(root):
    return {p.relative_to(root): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_merge_never_rewrites_its_inputs_nor_a_finished_runs_state(small_run, capsys):
    """merge --loaded M --partial P --out M, --out RUN/state and a non-empty --out are
    refused in one line naming the flag; nothing in the run changes."""
    root, out = small_run.out.parent, small_run.out
    assert main(["convert", str(out), str(root / "m"), "--to", "native"]) == 0
    assert main(["convert", str(out), str(root / "p"), "--to", "native"]) == 0
    capsys.readouterr()
    before = _tree(root)
    cfg = ["--config", str(small_run.config)]
    cases = [
        (
            ["--loaded", str(root / "m"), "--partial", str(root / "p"), "--out", str(root / "m")],
            "is the map given as --loaded",
        ),
        (
            ["--loaded", str(root / "m"), "--partial", str(root / "p"), "--out", str(root / "p")],
            "is the map given as --partial",
        ),
        (
            ["--loaded", str(out), "--partial", str(root / "p"), "--out", str(out / "state")],
            "is the map given as --loaded",
        ),
        (
            [
                "--loaded",
                str(root / "m"),
                "--partial",
                str(root / "p"),
                "--out",
                str(out / "state"),
            ],
            "not empty",
        ),
    ]
    for argv, message in cases:
        assert main(["merge", *cfg, *argv]) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err, err
        assert sum("error:" in line for line in err.splitlines()) == 1
    assert _tree(root) == before


def test_merging_a_map_with_itself_is_refused(small_run, capsys):
    """merge --loaded M --partial M would double the map (25 -> 49 experiences): refused."""
    root, out = small_run.out.parent, small_run.out
    before = _tree(root)
    argv = ["merge", "--config", str(small_run.config), "--loaded", str(out)]
    assert main([*argv, "--partial", str(out), "--out", str(root / "x")]) == 2
    err = capsys.readouterr().err
    assert "--loaded and --partial are the same map" in err and "Traceback" not in err
    assert _tree(root) == before and not (root / "x").exists()
