"""Error messages speak the caller's language: the command line names flags
(``--overwrite``, ``--set``), Python names arguments (``overwrite=True``,
``overrides``); neither sees the other's spelling."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from torchratslam.cli import main
from torchratslam.errors import InputError, for_cli, for_python, option

SMALL = Path(__file__).resolve().parents[1] / "data" / "small.yaml"
PYTHON_FORMS = re.compile(r"\w+=True|overrides|RunSettings|resume_run|\[\[")
FLAG = re.compile(r"(?<![\w-])--[a-z][a-z-]+")


def test_an_option_is_named_as_each_caller_names_it():
    msg = f"pass {option('--overwrite', 'overwrite=True')} or {option('--set', 'overrides')}"
    assert str(InputError(msg)) == "pass overwrite=True or overrides"
    assert InputError(msg).cli_message() == "pass --overwrite or --set"
    assert for_python(msg) == str(InputError(msg)) and for_cli(msg).count("--") == 2


def _cli_error(argv, capsys):
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err.splitlines()[0]
    assert not PYTHON_FORMS.search(err.split(": error: ", 1)[1]), err
    return err


def _python_error(call):
    with pytest.raises(InputError) as info:
        call()
    text = str(info.value)
    assert not FLAG.search(text), text
    return text


def test_simulate_into_a_full_folder(tmp_path, capsys):
    from torchratslam.sim import open_sim, write_dataset

    out = tmp_path / "d"
    out.mkdir()
    (out / "mine.txt").write_text("x")
    err = _cli_error(["simulate", "loop", "--out", str(out)], capsys)
    assert "--overwrite" in err
    text = _python_error(lambda: write_dataset(open_sim("sim:loop?frames=5"), out))
    assert "overwrite=True" in text and "out_dir" in text


def test_a_bad_override(tmp_path, capsys):
    from torchratslam.config import ConfigError, load_config

    argv = ["run", "--config", str(SMALL), "--data", "sim:loop", "--out", str(tmp_path / "o")]
    err = _cli_error([*argv, "--set", "pc_dim_xy=abc"], capsys)
    assert "--set: parameter 'pc_dim_xy'" in err
    with pytest.raises(ConfigError) as info:
        load_config(str(SMALL), pc_dim_xy="abc")
    assert "overrides: parameter 'pc_dim_xy'" in str(info.value) and "--" not in str(info.value)


def test_a_finished_run_and_the_counts(tmp_path, capsys):
    from torchratslam.experiments.run_dataset import run_dataset
    from torchratslam.experiments.run_options import RunOptions, RunSettings

    out = tmp_path / "o"
    argv = ["run", "--config", str(SMALL), "--data", "sim:loop?frames=10", "--out", str(out)]
    assert main([*argv, "--no-progress"]) == 0
    err = _cli_error([*argv, "--no-progress"], capsys)
    assert "--overwrite" in err and "holds a finished run" in err
    opts = RunOptions(config=str(SMALL), data="sim:loop?frames=10")
    quiet = RunSettings(progress=False)
    text = _python_error(lambda: run_dataset(opts, out, quiet))
    assert "RunSettings(overwrite=True)" in text and "holds a finished run" in text
    err = _cli_error([*argv, "--no-progress", "--threads", "0", "--overwrite"], capsys)
    assert "--threads must be >= 1" in err
    text = _python_error(lambda: run_dataset(opts, out, RunSettings(threads=0)))
    assert "threads must be >= 1" in text


def test_odometry_over_the_limit(tmp_path, capsys):
    from torchratslam.readers.datasets import check_odometry

    text = _python_error(lambda: check_odometry([0.0, 500.0], [0.0, 0.0], source="o.csv"))
    assert "raise the limit (max_speed)" in text
