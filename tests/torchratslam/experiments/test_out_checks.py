"""Every command that writes an OUT refuses, before any work, a non-empty OUT holding
something else (a user's files, another command's run) and a finished run of its own
without --overwrite; a single output file is never one of the inputs or another
command's file. Nothing is written or changed by a refused command."""

from __future__ import annotations

from pathlib import Path

import pytest

from torchratslam.cli import main

SMALL = str(Path(__file__).resolve().parents[2] / "data" / "small.yaml")


def _snapshot(d):
    return sorted((p.relative_to(d), p.stat().st_mtime_ns, p.stat().st_size) for p in d.rglob("*"))


@pytest.fixture
def places(small_run, tmp_path):
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    return small_run, foreign


def _refused(argv, capsys, *dirs, says):
    before = [_snapshot(d) for d in dirs]
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert says in err and "Traceback" not in err, err
    assert [_snapshot(d) for d in dirs] == before  # nothing written, nothing changed


@pytest.mark.parametrize(
    "argv",
    [
        ["multisession", "--config", SMALL, "--tour", "sim:loop", "--no-figures", "--quiet"],
        ["mbaram", "--data", "sim:loop?frames=30", "--no-plots", "--no-progress"],
        ["tune", "--config", SMALL, "--data", "sim:loop?frames=20", "--trials", "1"],
    ],
    ids=["multisession", "mbaram", "tune"],
)
def test_an_out_holding_something_else_is_refused(places, argv, capsys):
    run, foreign = places
    for out in (foreign, run.out):
        _refused([*argv, "--out", str(out)], capsys, out, says="is not empty and holds no")


def test_a_finished_mbaram_run_is_replaced_only_with_overwrite(tmp_path, capsys):
    out = tmp_path / "mb"
    argv = ["mbaram", "--data", "sim:loop?frames=30", "--no-plots", "--no-progress"]
    argv += ["--laps", "1", "--loc-laps", "1", "--out", str(out)]
    assert main(argv) == 0
    _refused(argv, capsys, out, says="holds a finished MBARAM run")
    assert main([*argv, "--overwrite"]) == 0


def test_an_output_file_is_never_an_input_or_another_commands_file(places, tmp_path, capsys):
    run, _ = places
    a = str(run.out)
    for flag, target in (("--json", "metrics.json"), ("--figure", "map.png")):
        argv = ["compare-maps", a, a, flag, str(run.out / target)]
        _refused(argv, capsys, run.out, says="a command never rewrites its inputs")
    other = tmp_path / "other"
    assert main(["run", "--config", SMALL, "--data", "sim:loop?frames=20", "--out", str(other),
                 "--no-progress"]) == 0  # fmt: skip
    argv = ["compare-maps", a, a, "--json", str(other / "metrics.json")]
    _refused(argv, capsys, other, says="is a file another torchratslam command wrote")
    argv = ["compare-backends", "--map", str(run.out / "state"), "--backends", "alpha"]
    _refused([*argv, "--json", str(other / "metrics.json")], capsys, other, says="manifest")
    _refused([*argv, "--json", str(run.out / "state" / "x.json")], capsys, run.out, says="input")


def test_a_run_convert_or_merge_never_writes_into_its_inputs(places, tmp_path, capsys):
    from torchratslam.sim import open_sim, write_dataset

    run, _ = places
    ds = write_dataset(open_sim("sim:loop?laps=1&frames=20"), tmp_path / "ds")
    argv = ["run", "--config", SMALL, "--data", str(ds), "--no-progress"]
    for out in (ds, ds / "frames", ds / "frames" / "new"):
        _refused([*argv, "--out", str(out)], capsys, ds, says="a run never rewrites its inputs")
    load = [*argv, "--load", str(run.out / "state"), "--overwrite"]
    for out in (run.out, run.out / "state" / "x"):
        _refused([*load, "--out", str(out)], capsys, run.out, says="given as --load")
    assert main([*argv, "--out", str(ds / "run1")]) == 0  # a new folder beside the data
    _refused(
        ["convert", str(run.out), str(run.out / "state" / "x"), "--to", "reference"],
        capsys,
        run.out,
        says="convert never rewrites its input",
    )
    merge = ["merge", "--config", SMALL, "--loaded", str(run.out), "--partial"]
    _refused([*merge, str(run.out / "state"), "--out", str(tmp_path / "m")], capsys, run.out,
             says="are the same map")  # fmt: skip
    assert not (tmp_path / "m").exists()


def test_reproduce_refuses_a_folder_holding_something_else(places, capsys):
    run, foreign = places
    for out in (foreign, run.out):
        argv = ["reproduce", "multisession/virtual-tour", "--quick", "--out", str(out)]
        _refused(argv, capsys, out, says="holds no report")


def test_sweep_refuses_a_folder_holding_something_else(places, tmp_path, capsys):
    run, foreign = places
    spec = tmp_path / "sw.yaml"
    spec.write_text(
        f"base: {SMALL}\ndatasets: ['sim:loop?frames=20']\n"
        "parameters:\n  vt_match_threshold: [0.03, 0.05]\n"
    )
    for out in (foreign, run.out):
        argv = ["sweep", str(spec), "--out", str(out), "--no-progress"]
        _refused(argv, capsys, out, says="holds no sweep")


@pytest.mark.parametrize("other", ["report.json", "results.csv", "state.npz", "frames"])
def test_a_run_refuses_an_out_holding_another_commands_outputs(tmp_path, capsys, other):
    out = tmp_path / "o"
    out.mkdir()
    (out / other).mkdir() if other == "frames" else (out / other).write_text("x")
    argv = ["run", "--config", SMALL, "--data", "sim:loop?frames=10", "--no-progress"]
    _refused([*argv, "--out", str(out)], capsys, out, says=f"({other}); a run does not write")


def _py_refused(call, *dirs, says):
    from torchratslam.errors import InputError

    before = [_snapshot(d) for d in dirs]
    with pytest.raises(InputError) as info:
        call()
    text = str(info.value)
    assert says in text and "--out" not in text and "--overwrite" not in text, text
    assert [_snapshot(d) for d in dirs] == before  # nothing written, nothing changed
    return text


def test_the_python_functions_check_their_out_as_the_commands_do(places, tmp_path):
    from torchratslam.experiments.mbaram_tour import MBARAMTourOptions
    from torchratslam.experiments.mbaram_tour import run_experiment as mbaram
    from torchratslam.experiments.multisession_tour import MultisessionOptions
    from torchratslam.experiments.multisession_tour import run_experiment as multisession
    from torchratslam.sweeps import sweep, tune

    run, foreign = places
    grid = {"base": SMALL, "datasets": ["sim:loop?frames=20"],
            "parameters": {"vt_match_threshold": [0.03]}}  # fmt: skip
    calls = {
        "sweep": lambda out: sweep(grid, out),
        "tune": lambda out: tune("sim:loop?frames=20", config=SMALL, trials=1, out=out),
        "mbaram": lambda out: mbaram("sim:loop?frames=30", out, MBARAMTourOptions(plots=False)),
        "multisession": lambda out: multisession(
            SMALL, "sim:loop", out, MultisessionOptions(figures=False)
        ),
    }
    for name, call in calls.items():
        for out in (foreign, run.out):
            text = _py_refused(lambda c=call, o=out: c(o), out, says="is not empty and holds no")
            assert f"out={str(out)!r}" in text, (name, text)
    # a finished run of their own is replaced only with overwrite=True
    mb = tmp_path / "mb"
    options = MBARAMTourOptions(laps=1, loc_laps=1, plots=False)
    mbaram("sim:loop?frames=30", mb, options)
    text = _py_refused(lambda: mbaram("sim:loop?frames=30", mb, options), mb, says="finished")
    assert "overwrite=True" in text
    mbaram("sim:loop?frames=30", mb, options, overwrite=True)
    ms = tmp_path / "ms"
    (ms).mkdir()
    (ms / "report.json").write_text("{}")
    text = _py_refused(lambda: calls["multisession"](ms), ms, says="finished multisession run")
    assert "overwrite=True" in text


def test_an_existing_output_file_is_replaced_only_with_overwrite(places, tmp_path, capsys):
    from torchratslam.experiments.compare_maps import compare_maps, write_json

    run, _ = places
    a = str(run.out)
    mine = tmp_path / "mine"
    mine.mkdir()
    for flag in ("--json", "--figure"):
        target = mine / f"notes{flag[2:]}"
        target.write_bytes(b"my notes")
        argv = ["compare-maps", a, a, flag, str(target)]
        _refused(argv, capsys, mine, says="exists; choose another path, or replace it with "
                 "--overwrite")  # fmt: skip
        assert target.read_bytes() == b"my notes"
        assert main([*argv, "--overwrite"]) == 0
        assert target.read_bytes() != b"my notes"
    notes = mine / "cmp.json"
    notes.write_text("mine")
    argv = ["compare-backends", "--map", str(run.out / "state"), "--backends", "alpha"]
    _refused([*argv, "--json", str(notes)], capsys, mine, says="--overwrite")
    assert main([*argv, "--json", str(notes), "--overwrite"]) == 0
    assert notes.read_text().startswith("[")
    # from Python: the same checks, in Python's words
    fig = mine / "fig.png"
    fig.write_text("mine")
    text = _py_refused(lambda: compare_maps(a, a, figure=fig), mine, says="exists")
    assert "overwrite=True" in text
    report = compare_maps(a, a)
    text = _py_refused(lambda: write_json(report, notes), mine, says="exists")
    _py_refused(lambda: write_json(report, run.out / "metrics.json"), run.out, says="input")
    write_json(report, notes, overwrite=True)
    assert notes.read_text().startswith("{")
