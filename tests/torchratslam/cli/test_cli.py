"""The CLI: every option's help has an example; ``run`` writes every output; errors end
with exit code 2 and a one-line message; ``compare-backends`` reads graphs and states."""

import csv
import json

import numpy as np
import pytest
import torch

from torchratslam.cli import build_parser, main

torch.set_num_threads(1)

SIM = "sim:loop?laps=1&frames=40"


def _subparser(name):
    parser = build_parser()
    for action in parser._subparsers._group_actions:
        if name in action.choices:
            return action.choices[name]
    raise AssertionError(f"no subcommand {name}")


@pytest.mark.parametrize("name", ["run", "compare-backends"])
def test_every_option_help_has_an_example(name):
    sub = _subparser(name)
    for action in sub._actions:
        if action.dest == "help":
            continue
        assert action.help and "e.g." in action.help, (
            f"{name} {action.option_strings} lacks an example"
        )
    assert "examples:" in sub.format_help()


def test_run_writes_every_output(small_run):
    out = small_run.out
    for name in ("metrics.json", "experiences.csv", "trajectory.csv", "map.png", "pose_cells.png"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    assert (out / "state").is_dir()
    m = json.loads((out / "metrics.json").read_text())
    assert m["frames"] == 40
    for key in ("templates", "experiences", "links", "wall_s", "ate_rmse_m"):
        assert key in m
    for module in ("local_view", "pose_cells", "experience_map"):
        assert (
            m["ms_per_frame"][module]["mean_ms"] > 0 and m["ms_per_frame"][module]["median_ms"] > 0
        )
    exps = list(csv.DictReader((out / "experiences.csv").open()))
    assert list(exps[0]) == ["id", "x", "y", "th", "created_frame"]
    assert len(exps) == m["experiences"] and [int(r["id"]) for r in exps] == list(range(len(exps)))
    traj = list(csv.DictReader((out / "trajectory.csv").open()))
    assert list(traj[0]) == ["frame", "t", "experience_id", "x", "y", "th"]
    assert len(traj) == 40 and [int(r["frame"]) for r in traj] == list(range(40))
    # each trajectory row carries the final pose of its experience
    pose = {int(r["id"]): (float(r["x"]), float(r["y"]), float(r["th"])) for r in exps}
    # frame 0 has no experience yet (OpenRatSLAM's first action comes at frame 1)
    assert int(traj[0]["experience_id"]) == -1 and traj[0]["x"] in ("", "nan")
    for r in traj[1:]:
        assert (float(r["x"]), float(r["y"]), float(r["th"])) == pose[int(r["experience_id"])]
    # the saved state loads back with the same map
    from torchratslam.maps.native import load_state

    st = load_state(out / "state")
    assert st.exp_pose.shape[0] == m["experiences"] and st.templates.shape[0] == m["templates"]
    assert np.allclose(st.exp_pose[:, :2], [[float(r["x"]), float(r["y"])] for r in exps])


def test_compare_backends_on_a_saved_state_and_a_g2o_file(small_run, tmp_path, capsys):
    pytest.importorskip("ratslam_graph.compare")
    out = small_run.out
    js = tmp_path / "cmp.json"
    argv = ["compare-backends", "--json", str(js)]
    assert main([*argv, "--map", str(out / "state"), "--backends", "alpha,gtsam"]) == 0
    rows = json.loads(js.read_text())
    assert [r["name"] for r in rows] == ["alpha", "gtsam"]
    assert all("time_s" in r and "error" in r for r in rows)
    printed = capsys.readouterr().out
    assert "| alpha |" in printed and "| gtsam |" in printed

    from ratslam_graph.io import write_g2o
    from torchratslam.experiments.compare_backends import load_posegraph

    pg = load_posegraph(out / "state")
    g2o = tmp_path / "map.g2o"
    write_g2o(pg, g2o)
    gt = tmp_path / "gt.txt"
    np.savetxt(gt, pg.poses)
    assert main([*argv, "--map", str(g2o), "--groundtruth", str(gt), "--backends", "alpha",
                 "--overwrite"]) == 0  # fmt: skip
    assert json.loads(js.read_text())[0]["ate_rmse_m"] is not None


def _fails(argv, capsys, match):
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert match in err[0] and "Traceback" not in "\n".join(err)
    return err


def test_cli_fails_cleanly_on_bad_input(tmp_path, capsys, small_run):
    cfg = small_run.config
    bad = tmp_path / "bad.yaml"
    bad.write_text("pc_dim_xyz: 3\n")
    (tmp_path / "d" / "frames").mkdir(parents=True)
    run = ["run", "--out", str(tmp_path / "o")]
    cases = [
        (["--config", str(cfg), "--data", str(tmp_path / "missing")], "not found"),
        (["--config", str(tmp_path / "nope.yaml"), "--data", SIM], "not found"),
        (["--config", str(bad), "--data", SIM], "did you mean 'pc_dim_xy'"),
        (["--config", str(cfg), "--data", SIM, "--max-frames", "0"], "--max-frames"),
        (["--config", str(cfg), "--data", "sim:nowhere"], "unknown simulator tour"),
        (["--config", str(cfg), "--data", SIM, "--set", "exp_loops"], "KEY=VALUE"),
        (["--config", str(cfg), "--data", str(tmp_path / "d")], "no images"),
    ]
    for argv, match in cases:
        _fails([*run, *argv], capsys, match)
    _fails(["compare-backends", "--map", str(tmp_path / "none.g2o")], capsys, "not found")
    _fails(["compare-backends", "--map", str(tmp_path / "d")], capsys, "")


def test_run_on_a_written_dataset_directory(tmp_path, small_run, capsys):
    from torchratslam.sim import open_sim, write_dataset

    cfg = small_run.config
    data = write_dataset(open_sim("sim:loop?laps=0.2&frames=12"), tmp_path / "ds")
    out = tmp_path / "out"
    argv = ["run", "--config", str(cfg), "--data", str(data), "--no-progress"]
    assert main([*argv, "--out", str(out), "--max-frames", "10"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["frames"] == 10 and m["odometry"] == "given" and "ate_rmse_m" in m
    from torchratslam.readers.datasets import open_data

    assert open_data(data).mirrored  # meta.json: the simulator's columns turn CCW
    # without odometry.csv the run switches to visual odometry and says so
    (data / "odometry.csv").unlink()
    capsys.readouterr()
    assert main([*argv, "--out", str(tmp_path / "vo")]) == 0
    assert "using visual odometry" in capsys.readouterr().err
    m = json.loads((tmp_path / "vo" / "metrics.json").read_text())
    assert m["frames"] == 12 and m["odometry"] == "visual"


def test_a_gap_in_the_frame_numbering_is_recorded_in_the_metrics(tmp_path, small_run):
    from torchratslam.sim import open_sim, write_dataset

    data = write_dataset(open_sim("sim:loop?laps=0.2&frames=12"), tmp_path / "ds")
    frames = sorted((data / "frames").iterdir())
    last = frames[-1]
    last.rename(
        last.with_name(last.name.replace(last.stem, f"{int(last.stem) + 40:0{len(last.stem)}d}"))
    )
    out = tmp_path / "out"
    argv = ["run", "--config", str(small_run.config), "--data", str(data), "--out", str(out)]
    assert main([*argv, "--no-progress"]) == 0
    warnings = json.loads((out / "metrics.json").read_text())["input_warnings"]
    assert len(warnings) == 1 and "gap" in warnings[0], warnings
    clean = write_dataset(open_sim("sim:loop?laps=0.2&frames=12"), tmp_path / "clean")
    argv = ["run", "--config", str(small_run.config), "--data", str(clean), "--no-progress"]
    assert main([*argv, "--out", str(tmp_path / "out2")]) == 0
    assert "input_warnings" not in json.loads((tmp_path / "out2" / "metrics.json").read_text())


def test_run_with_load_merges_into_the_stored_map(small_run, tmp_path):
    pytest.importorskip("torchratslam.multisession.session")
    out, cfg = small_run.out, small_run.config
    out2 = tmp_path / "second"
    argv = ["run", "--config", str(cfg), "--data", SIM, "--out", str(out2), "--no-progress"]
    assert main([*argv, "--max-frames", "10", "--load", str(out / "state")]) == 0
    m = json.loads((out2 / "metrics.json").read_text())
    first = json.loads((out / "metrics.json").read_text())
    # the same route again: its first view is a stored place, so the session merges at once
    assert m["merges"] and m["merges"][0]["frame"] == 0 and m["merges"][0]["map"] == 0
    assert m["experiences"] >= first["experiences"] and m["loaded"] == [str(out / "state")]


def test_bag_topics_come_from_options_then_topic_root_then_irat_defaults():
    import argparse

    from torchratslam.cli.run import _topics
    from torchratslam.config import load_config

    none = argparse.Namespace(image_topic=None, odom_topic=None)
    assert _topics(none, load_config()) == ("/irat_red/camera/image/compressed", "/irat_red/odom")
    cfg = load_config(None, topic_root="stlucia")
    assert _topics(none, cfg) == ("/stlucia/camera/image/compressed", "/stlucia/odom")
    given = argparse.Namespace(image_topic="/cam", odom_topic=None)
    assert _topics(given, cfg) == ("/cam", "/stlucia/odom")


def test_commands_default_to_one_torch_thread_and_reject_bad_thread_counts(monkeypatch, capsys):
    import torch

    from torchratslam.cli import main

    torch.set_num_threads(2)
    monkeypatch.delenv("TORCHRATSLAM_THREADS", raising=False)
    assert main(["simulate", "no_such_tour", "--out", "/nonexistent/x"]) == 2
    assert torch.get_num_threads() == 1
    monkeypatch.setenv("TORCHRATSLAM_THREADS", "lots")
    assert main(["simulate", "loop", "--out", "/nonexistent/x"]) == 2
    assert "TORCHRATSLAM_THREADS" in capsys.readouterr().err


def test_every_subcommand_help_has_examples_and_no_sphinx_markup():
    import re

    parser = build_parser()
    names = [n for a in parser._subparsers._group_actions for n in a.choices]
    assert {"run", "multisession", "mbaram", "merge", "simulate", "compare-backends"} <= set(names)
    for name in names:
        sub = _subparser(name)
        text = sub.format_help()
        assert re.search(r"^examples?:\n  torchratslam " + name, text, re.M), name
        assert not re.search(r":(class|func|meth|mod|attr|data|exc):`|``", text), name
        for action in sub._actions:
            if action.dest != "help":
                assert action.help and "e.g." in action.help, (name, action.option_strings)


@pytest.mark.parametrize("left", ["report.json", "seeds.json"])
def test_multisession_refuses_an_out_holding_a_finished_run(tmp_path, capsys, left):
    out = tmp_path / "ms"
    out.mkdir()
    (out / left).write_text("{}")
    argv = ["multisession", "--tour", "sim:virtual_tour", "--out", str(out), "--max-frames", "5"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "holds a finished multisession run" in err and "--overwrite" in err
    assert sorted(p.name for p in out.iterdir()) == [left]
    assert (out / left).read_text() == "{}"


def test_multisession_refuses_an_out_holding_a_run_that_did_not_finish(tmp_path, capsys):
    out = tmp_path / "ms"
    out.mkdir()
    (out / "running.json").write_text('{"command": ["torchratslam", "multisession"]}')
    argv = ["multisession", "--tour", "sim:virtual_tour", "--out", str(out), "--max-frames", "5"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "did not finish" in err and "--overwrite" in err
    assert sorted(p.name for p in out.iterdir()) == ["running.json"]


@pytest.mark.parametrize(
    "bad, message",
    [(["--seeds", "9-3"], "runs backwards"), (["--tour", "sim:no_such_tour"], "no_such_tour")],
)
@pytest.mark.parametrize("existing", [False, True])
def test_a_refused_multisession_leaves_out_as_it_was(tmp_path, capsys, bad, message, existing):
    """A multisession refused for a bad argument leaves no running.json (nor an OUT it
    made), so the corrected command is not refused as a run that did not finish."""
    out = tmp_path / "ms"
    if existing:  # an empty OUT the user made (one holding other files is refused)
        out.mkdir()
    argv = ["multisession", "--tour", "sim:virtual_tour", "--out", str(out), "--max-frames", "5"]
    assert main([*argv, *bad]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    if existing:
        assert out.is_dir() and not any(out.iterdir())
    else:
        assert not out.exists()
    # the corrected command is not refused as "a multisession run that did not finish"
    from torchratslam.cli import multisession

    multisession._Running(out, overwrite=False)
