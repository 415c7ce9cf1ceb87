"""Sweeps end to end: the same table serially, on a local process pool and on Ray's
local cluster; kill -9 then --resume; failed runs recorded; figures."""

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

import torchratslam
from torchratslam.cli import main
from torchratslam.errors import InputError
from torchratslam.sweeps.table import deterministic_text, read_table

ROOT = Path(__file__).resolve().parents[3]

# 2 x 3 values x 2 seeds = 12 tiny runs (25 frames of one lap of the loop tour)
SWEEP = {
    "base": "virtual_tour",
    "set": {
        "pc_dim_xy": 21,
        "exp_loops": 5,
        "pc_engine": "torch",
        "skip_first_odometry": False,
    },  # batchable (the torch pose-cell step, a step at frame 0)
    "parameters": {
        "vt_match_threshold": [0.05, 0.08],
        "pc_vt_inject_energy": {"start": 0.05, "stop": 0.25, "num": 3},
    },
    "datasets": [{"data": "sim:loop?laps=1&frames=25&lasers=0", "max_frames": 25}],
    "seeds": [0, 1],
}


@pytest.fixture(scope="module")
def sweep_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("sweep") / "sweep.yaml"
    path.write_text(yaml.safe_dump(SWEEP, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def reference(sweep_file, tmp_path_factory):
    """The uninterrupted table: in this process, batched where possible."""
    out = tmp_path_factory.mktemp("ref")
    table = torchratslam.sweep(sweep_file, out, workers=1, progress=False)
    return out, table


def test_table_has_every_parameter_and_metric(reference):
    out, table = reference
    rows = table.to_dict("records") if hasattr(table, "to_dict") else table
    assert len(rows) == 12
    assert [r["index"] for r in rows] == list(range(12))
    for col in (
        "vt_match_threshold",
        "pc_vt_inject_energy",
        "ate_m",
        "dead_reckoning_ate_m",
        "templates",
        "experiences",
        "links",
        "wall_s",
        "ms_local_view",
        "ms_pose_cells",
        "ms_experience_map",
        "ms_odometry",
        "status",
        "error",
    ):
        assert col in rows[0]
    assert all(r["status"] == "ok" and r["frames"] == 25 for r in rows)
    # the swept values reach the runs: a looser threshold never learns more templates
    for seed in (0, 1):
        for e in (0.05, 0.15, 0.25):
            t = {
                r["vt_match_threshold"]: r["templates"]
                for r in rows
                if r["seed"] == seed and r["pc_vt_inject_energy"] == e
            }
            assert t[0.08] <= t[0.05]
    assert len({r["dead_reckoning_ate_m"] for r in rows}) == 2  # one per seed
    # each ATE says how many frames it is over: a simulated run has ground truth and a
    # map pose on every frame
    assert all(r["ate_frames"] == r["frames"] >= 3 for r in rows)
    figs = sorted(p.name for p in (out / "figures").glob("*.png"))
    assert figs == [
        "metrics_vs_pc_vt_inject_energy.png",
        "metrics_vs_vt_match_threshold.png",
        "speed_vs_accuracy.png",
    ]
    assert (out / "results.parquet").exists() == _has("pyarrow")
    # the same sweep again, unbatched, gives the same table (timing columns aside)
    again = out.parent / "again"
    torchratslam.sweep(SWEEP, again, workers=1, batch=False, figures=False, progress=False)
    assert deterministic_text(again / "results.csv") == deterministic_text(out / "results.csv")


def _has(module):
    try:
        __import__(module)
    except ImportError:
        return False
    return True


def test_local_pool_and_ray_give_the_same_table(sweep_file, reference, tmp_path):
    ref_out, _ = reference
    expected = deterministic_text(ref_out / "results.csv")
    torchratslam.sweep(sweep_file, tmp_path / "pool", workers=2, figures=False, progress=False)
    assert deterministic_text(tmp_path / "pool" / "results.csv") == expected
    rows = read_table(tmp_path / "pool" / "results.csv")
    assert max(r["batch"] for r in rows) > 1  # some runs shared a batched network
    pytest.importorskip("ray", reason="ray (the 'ray' extra) is not installed")
    torchratslam.sweep(
        sweep_file, tmp_path / "ray", ray=True, workers=2, figures=False, progress=False
    )
    assert deterministic_text(tmp_path / "ray" / "results.csv") == expected


def test_kill_then_resume_equals_uninterrupted(sweep_file, reference, tmp_path):
    ref_out, _ = reference
    out = tmp_path / "killed"
    table = out / "results.csv"
    cmd = [
        sys.executable,
        "-m",
        "torchratslam",
        "sweep",
        str(sweep_file),
        "--out",
        str(out),
        "--workers",
        "1",
        "--no-batch",
        "--no-figures",
        "--no-progress",
    ]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        n = 0
        while time.monotonic() < deadline and proc.poll() is None:
            if table.exists():
                n = len(read_table(table))
                if n >= 3:
                    break
            time.sleep(0.05)
        assert proc.poll() is None, "the sweep ended before it could be killed"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait()
    partial = read_table(table)
    assert 3 <= len(partial) < 12
    # a plain re-run refuses (one line, pointing to --resume) and leaves the table alone
    before = table.read_bytes()
    argv = ["sweep", str(sweep_file), "--out", str(out), "--workers", "1", "--no-progress"]
    assert main(argv) == 2
    assert table.read_bytes() == before
    torchratslam.sweep(sweep_file, out, resume=True, workers=1, figures=False, progress=False)
    assert deterministic_text(table) == deterministic_text(ref_out / "results.csv")
    final = {r["run_id"]: r for r in read_table(table)}
    for r in partial:  # finished runs were kept, not redone
        assert final[r["run_id"]]["wall_s"] == r["wall_s"]


def test_failed_run_is_recorded_and_the_sweep_goes_on(tmp_path):
    raw = {
        "base": "virtual_tour",
        "set": {"pc_dim_xy": 21},
        "parameters": {"exp_loops": [1, 2]},
        "datasets": ["sim:loop?frames=12&lasers=0", "sim:loop?laps=-1"],
        "max_frames": 12,
    }
    rows = torchratslam.sweep(raw, tmp_path, workers=1, progress=False)
    rows = rows.to_dict("records") if hasattr(rows, "to_dict") else rows
    assert [r["status"] for r in rows] == ["ok", "ok", "error", "error"]
    assert all("InputError" in r["error"] and "laps" in r["error"] for r in rows[2:])
    assert all(r["frames"] == 12 for r in rows[:2])
    if _has("pyarrow"):  # the Parquet copy holds the same rows, errors included
        import pyarrow.parquet as pq

        pq_rows = pq.read_table(tmp_path / "results.parquet").to_pylist()
        assert [r["status"] for r in pq_rows] == ["ok", "ok", "error", "error"]
        assert [r["run_id"] for r in pq_rows] == [r["run_id"] for r in rows]
    # resume keeps failed runs unless asked to retry them
    again = torchratslam.sweep(raw, tmp_path, resume=True, workers=1, progress=False, figures=False)
    assert len(again) == 4
    # the finished sweep, a stopped one (2 of 4 rows) or another sweep's table is refused
    # unless resumed or overwritten
    kw = {"workers": 1, "progress": False, "figures": False}
    with pytest.raises(InputError, match="holds this sweep, finished"):
        torchratslam.sweep(raw, tmp_path, **kw)
    table = tmp_path / "results.csv"
    lines = table.read_text().splitlines(keepends=True)
    table.write_text("".join(lines[:3]))
    with pytest.raises(InputError, match=r"holds 2 of this sweep's 4 runs .*resume=True"):
        torchratslam.sweep(raw, tmp_path, **kw)
    assert table.read_text() == "".join(lines[:3])
    other = {**raw, "parameters": {"exp_loops": [3]}}
    with pytest.raises(InputError, match="runs of another sweep"):
        torchratslam.sweep(other, tmp_path, **kw)
    assert len(torchratslam.sweep(raw, tmp_path, overwrite=True, **kw)) == 4
    assert len(read_table(table)) == 4


def test_a_finished_sweep_is_not_run_again_without_overwrite(sweep_file, reference, tmp_path):
    """The same sweep command typed twice refuses in one line and changes nothing; with
    --overwrite it runs again and writes the same table."""
    ref_out, _ = reference
    out = tmp_path / "twice"
    shutil.copytree(ref_out, out)
    before = {p.name: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    with pytest.raises(InputError, match=r"holds this sweep, finished.*overwrite=True"):
        torchratslam.sweep(sweep_file, out, workers=1, progress=False)
    assert {p.name: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    torchratslam.sweep(sweep_file, out, workers=1, figures=False, overwrite=True, progress=False)
    assert deterministic_text(out / "results.csv") == deterministic_text(ref_out / "results.csv")
