"""The start-up is said and kept apart: numba's first compilation of torchratslam's
kernels is announced once, before the pause; a run's frames/s leaves the first frame's
one-off cost out and records it on its own."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import time
from pathlib import Path

from torchratslam.pipeline.results import RunResult

NOTICE = "compiling torchratslam's numba kernels"

SCRIPT = textwrap.dedent(
    """
    import logging, sys
    import numpy as np
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    from torchratslam.timing import watch_compiles
    watch_compiles()
    watch_compiles()  # idempotent: one listener
    from torchratslam.local_view._blocks import block_means
    img = np.zeros((4, 4, 1), np.uint8)
    block_means(img, 0, 0, 2, 2, 2, 2, 255.0 * 4)
    block_means(img.astype(np.uint8), 0, 0, 1, 4, 1, 4, 255.0 * 16)
    """
)


def test_the_first_compilation_is_said_once_and_a_cached_start_says_nothing(tmp_path):
    env_cache = {"NUMBA_CACHE_DIR": str(tmp_path / "numba")}  # a fresh install's empty cache
    root = Path(__file__).resolve().parents[2]
    import os

    env = {**os.environ, **env_cache, "PYTHONPATH": f"{root}:{root / 'graph'}"}
    first = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=300
    )
    assert first.returncode == 0, first.stderr[-2000:]
    assert first.stderr.count(NOTICE) == 1, first.stderr  # once, though it compiled
    assert any((tmp_path / "numba").rglob("*.nbi"))  # cached on disk now
    again = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=300
    )
    assert again.returncode == 0, again.stderr[-2000:]
    assert NOTICE not in again.stderr  # loaded from the cache: nothing to say


def test_frames_per_second_leave_the_start_up_out():
    r = RunResult(frames=11, wall_s=12.0, templates=0, experiences=0, links=0, startup_s=10.0)
    assert r.fps == 10 / 2.0  # the ten frames after the first, over the 2 s after it
    assert RunResult(11, 12.0, 0, 0, 0).fps == 11 / 12.0  # no start-up measured: all of it
    assert RunResult(1, 3.0, 0, 0, 0, startup_s=3.0).fps == 1 / 3.0  # one frame: all of it


def test_a_run_records_its_start_up_apart_from_its_frames_per_second(tmp_path, monkeypatch):
    from torchratslam.cli import main
    from torchratslam.pipeline.ratslam import RatSLAM

    small = Path(__file__).resolve().parents[1] / "data" / "small.yaml"
    real = RatSLAM.step_frame
    calls = {"n": 0}

    def slow_first(self, frame, **kw):
        calls["n"] += 1
        if calls["n"] == 1:
            time.sleep(1.5)  # a start-up as numba's compilation makes it
        return real(self, frame, **kw)

    monkeypatch.setattr(RatSLAM, "step_frame", slow_first)
    out = tmp_path / "out"
    argv = ["run", "--config", str(small), "--data", "sim:loop?laps=1&frames=20"]
    assert main([*argv, "--out", str(out), "--no-progress"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["startup_s"] >= 1.5
    rest = m["wall_s"] - m["startup_s"]
    assert abs(m["fps"] - (m["frames_this_run"] - 1) / rest) < 1e-6 * m["fps"]
    assert m["fps"] > m["frames_this_run"] / m["wall_s"]  # the pause is not in the figure


def test_the_printed_line_names_a_start_up_worth_saying():
    from dataclasses import replace

    from tests.torchratslam.experiments.test_run_outputs import BASE
    from torchratslam.experiments.run_outputs import summary_line

    line = summary_line(replace(BASE, startup_s=14.2), Path("o"))
    assert "(2.0 frames/s after a start-up of 14.2 s)" in line
    assert "start-up" not in summary_line(replace(BASE, startup_s=0.05), Path("o"))
