"""``torchratslam sweep`` and ``tune``: help conventions and one-line errors."""

import pytest

from torchratslam.cli import build_parser, main


def _subparser(name):
    for action in build_parser()._subparsers._group_actions:
        if name in action.choices:
            return action.choices[name]
    raise AssertionError(f"no subcommand {name}")


@pytest.mark.parametrize("name", ["sweep", "tune"])
def test_every_option_help_has_an_example(name):
    sub = _subparser(name)
    for action in sub._actions:
        if action.dest != "help":
            assert action.help and "e.g." in action.help, (name, action.option_strings)
    assert "examples:" in sub.format_help()


@pytest.mark.parametrize(
    "argv, message",
    [
        (["sweep", "missing.yaml", "--out", "{tmp}/o"], "not found"),
        (["sweep", "{tmp}/bad.yaml", "--out", "{tmp}/o"], "vt_match_threshold"),
        (["sweep", "{tmp}/good.yaml", "--out", "{tmp}/o", "--workers", "0"], "--workers"),
        (["tune", "--out", "{tmp}/t", "--param", "vt_match_threshold=0.2:0.1"], "below high"),
        (["tune", "--out", "{tmp}/t", "--param", "nope=1:2"], "nope"),
        (["tune", "--out", "{tmp}/t", "--metric", "speed"], "unknown metric"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(argv, message, tmp_path, capsys):
    (tmp_path / "bad.yaml").write_text("parameters: {vt_match_threshhold: [0.1]}\n")
    (tmp_path / "good.yaml").write_text("parameters: {exp_loops: [1]}\n")
    code = main([a.replace("{tmp}", str(tmp_path)) for a in argv])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and "Traceback" not in err


def test_sweep_command_writes_the_table(tmp_path, capsys):
    f = tmp_path / "s.yaml"
    f.write_text(
        "base: virtual_tour\nset: {pc_dim_xy: 21}\nparameters: {exp_loops: [1, 3]}\n"
        "datasets: ['sim:loop?frames=15&lasers=0']\n"
    )
    code = main(
        [
            "sweep",
            str(f),
            "--out",
            str(tmp_path / "o"),
            "--workers",
            "1",
            "--no-progress",
            "--no-figures",
        ]
    )
    assert code == 0
    out = capsys.readouterr().out
    assert "2 runs (0 failed)" in out and "best ATE" in out
    assert (tmp_path / "o" / "results.csv").read_text().count("\n") == 3


def test_resume_with_another_grid_keeps_the_first_sweeps_rows(tmp_path, capsys):
    """sweep A --out D, then sweep B --out D --resume (B another grid) refuses in one line
    and leaves A's finished rows in results.csv byte for byte."""
    head = "base: virtual_tour\nset: {pc_dim_xy: 21}\ndatasets: ['sim:loop?frames=8&lasers=0']\n"
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    a.write_text(head + "parameters: {exp_loops: [1, 3]}\n")
    b.write_text(head + "parameters: {exp_loops: [2, 4]}\n")
    out = tmp_path / "d"
    common = ["--out", str(out), "--workers", "1", "--no-progress", "--no-figures"]
    assert main(["sweep", str(a), *common]) == 0
    table = (out / "results.csv").read_bytes()
    capsys.readouterr()
    code = main(["sweep", str(b), *common, "--resume"])
    err = capsys.readouterr().err
    assert code == 2
    assert "2 runs of another sweep" in err and "Traceback" not in err
    assert sum("error:" in line for line in err.splitlines()) == 1
    assert (out / "results.csv").read_bytes() == table


def test_a_huge_grid_is_refused_at_once_on_its_run_count(tmp_path, capsys):
    """1e6 x 1e6 values used to spin silently (every run's config read before anything
    was shown): refused at once, naming the run count, leaving no OUT."""
    import time

    f = tmp_path / "huge.yaml"
    f.write_text(
        "parameters:\n"
        "  vt_match_threshold: {start: 0.01, stop: 0.2, num: 1000000}\n"
        "  pc_vt_inject_energy: {start: 0.05, stop: 0.2, num: 1000000}\n"
    )
    out = tmp_path / "o"
    t0 = time.perf_counter()
    assert main(["sweep", str(f), "--out", str(out), "--no-progress"]) == 2
    assert time.perf_counter() - t0 < 20
    err = capsys.readouterr().err
    assert "num = 1000000 values is more than a sweep runs (100000)" in err
    assert "Traceback" not in err and not out.exists()
    f.write_text(  # each list small enough, the grid not
        "parameters:\n"
        "  vt_match_threshold: {start: 0.01, stop: 0.2, num: 1000}\n"
        "  pc_vt_inject_energy: {start: 0.05, stop: 0.2, num: 1000}\n"
    )
    assert main(["sweep", str(f), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "1e+06 runs (1000 x 1000 values)" in err and "at most 100000" in err
    assert not out.exists()
    f.write_text(
        "parameters:\n  vt_match_threshold: {start: 0.01, stop: 0.2, num: 1000000000000}\n"
    )
    assert main(["sweep", str(f), "--out", str(out), "--no-progress"]) == 2
    assert "num = 1000000000000 values" in capsys.readouterr().err
