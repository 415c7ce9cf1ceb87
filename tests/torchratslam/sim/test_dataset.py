"""write_dataset (torchratslam simulate) cleans up after a killed earlier write."""

from __future__ import annotations

import logging
import os
import subprocess
import sys

from torchratslam.sim import open_sim, write_dataset


def test_a_killed_simulates_hidden_temp_folder_is_removed_and_said(tmp_path, caplog):
    """A simulate killed mid-write leaves .NAME.new-PID-RANDOM; the next simulate into the
    same place removes it (its process is gone) and says so; a live writer's is kept."""
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    stale = tmp_path / f".ds.new-{int(dead.stdout)}-0123abcd"
    (stale / "frames").mkdir(parents=True)
    (stale / "frames" / "000000.png").write_bytes(b"x" * 1000)
    live = tmp_path / f".ds.new-{os.getppid()}-4567cdef"
    live.mkdir()
    other = tmp_path / ".other.new-1-0123abcd"  # another target's: not ours to judge
    other.mkdir()
    with caplog.at_level(logging.WARNING, logger="torchratslam.sim.dataset"):
        write_dataset(open_sim("sim:loop?frames=4&lasers=0"), tmp_path / "ds", progress=False)
    assert not stale.exists() and live.exists() and other.exists()
    assert any(str(stale) in r.getMessage() and "stopped" in r.getMessage() for r in caplog.records)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [live.name, ".other.new-1-0123abcd", "ds"]
    )
