"""The benchmarks' peak-memory runner: a command's peak and log, and why it failed."""

from __future__ import annotations

import sys

import pytest

from benchmarks.bench_scale import run_peak


def test_run_peak_measures_the_command_alone(tmp_path):
    touch = "x = b'1' * (96 * 2**20); print(len(x) // 2**20)"
    wall, peak = run_peak([sys.executable, "-c", touch], tmp_path / "log")
    assert (tmp_path / "log").read_text().strip() == "96"
    assert 96 <= peak < 96 + 200 and wall > 0  # the 96 MiB it wrote, not this process's size


def test_run_peak_says_the_commands_own_reason_when_it_fails(tmp_path):
    fail = "import sys; print('noise', file=sys.stderr); sys.exit('mytool: error: OUT holds a run')"
    with pytest.raises(RuntimeError, match="exited 1: mytool: error: OUT holds a run"):
        run_peak([sys.executable, "-c", fail], tmp_path / "log")
