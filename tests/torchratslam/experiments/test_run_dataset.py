"""``run_dataset``: checkpoints by default, a run killed with SIGKILL resumes to the
uninterrupted run's map bit for bit, a full disk names the file and keeps the last
checkpoint, ``--load`` runs resume too, and a loaded map that never merged is written
and reported."""

from __future__ import annotations

import errno
import json
import random
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from ratslam_graph.atomic import LOCK_NAME as LOCK
from torchratslam.cli import main
from torchratslam.experiments import run_dataset as rd
from torchratslam.maps.native import load_state, read_map_info

SMALL = Path(__file__).resolve().parents[2] / "data" / "small.yaml"
LONG = 1100  # frames: past the first default checkpoint (frame 1000)
SESSION = "sim:virtual_tour/session1"


def _argv(data, out, *more):
    return ["run", "--config", str(SMALL), "--data", str(data), "--out", str(out), *more]


def _npz(path):
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _same_map(a: Path, b: Path) -> None:
    """state.npz and history.npz arrays equal, and the trajectory, bit for bit."""
    for name in ("state.npz", "history.npz"):
        x, y = _npz(a / "state" / name), _npz(b / "state" / name)
        assert sorted(x) == sorted(y), name
        for k in x:
            assert x[k].dtype == y[k].dtype and np.array_equal(x[k], y[k], equal_nan=True), k
    for name in ("trajectory.csv", "experiences.csv"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


@pytest.fixture(scope="module")
def long_run(tmp_path_factory):
    """An uninterrupted run of LONG frames with default options."""
    root = tmp_path_factory.mktemp("long")
    data = f"sim:loop?laps=3&frames={LONG}"
    full = root / "full"
    assert main([*_argv(data, full), "--no-progress"]) == 0
    return data, full


KILLER = textwrap.dedent(
    """
    import os, signal, sys
    from torchratslam.cli import main
    from torchratslam.readers import datasets

    at = int(sys.argv[1])
    real = datasets.open_data

    class Killing:
        def __init__(self, data):
            self.data = data

        def __getattr__(self, name):
            return getattr(self.data, name)

        def __len__(self):
            return len(self.data)

        def frames(self):
            for k, f in enumerate(self.data.frames()):
                if k == at:  # frames 0..at-1 are mapped: kill -9, no handler runs
                    os.kill(os.getpid(), signal.SIGKILL)
                yield f

    datasets.open_data = lambda *a, **k: Killing(real(*a, **k))
    sys.exit(main(sys.argv[2:]))
    """
)


@pytest.mark.slow
def test_checkpoints_are_on_by_default_and_a_sigkill_resumes_bit_for_bit(long_run, tmp_path):
    data, full = long_run
    at = random.Random(20261125).randrange(rd.DEFAULT_CHECKPOINT_EVERY + 1, LONG)
    out = tmp_path / "out"
    script = tmp_path / "killer.py"
    script.write_text(KILLER)
    done = subprocess.run(
        [sys.executable, str(script), str(at), *_argv(data, out), "--no-progress"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == -9, done.stderr[-2000:]
    info = read_map_info(out / "state")  # the default checkpoint, nothing said at the kill
    assert info["partial"] and info["stopped_at_frame"] == rd.DEFAULT_CHECKPOINT_EVERY
    assert not (out / "metrics.json").exists()
    # a plain re-run refuses and points to --resume
    assert main([*_argv(data, out), "--no-progress"]) == 2
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    _same_map(full, out)
    assert json.loads((out / "run.json").read_text())["finished"] is True


def test_a_sigkill_before_the_first_checkpoint_resumes_from_the_first_frame(tmp_path, capsys):
    data = "sim:loop?laps=1&frames=40"
    full = tmp_path / "full"
    assert main([*_argv(data, full), "--no-progress"]) == 0
    out = tmp_path / "out"
    script = tmp_path / "killer.py"
    script.write_text(KILLER)
    done = subprocess.run(
        [sys.executable, str(script), "17", *_argv(data, out), "--no-progress"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == -9, done.stderr[-2000:]
    assert not (out / "state").exists() and (out / "run.json").is_file()
    capsys.readouterr()
    assert main([*_argv(data, out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "stopped before its first checkpoint" in err and f"--resume {out}" in err
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    assert "from its first frame" in capsys.readouterr().err
    _same_map(full, out)


def test_checkpoint_every_zero_saves_none(tmp_path, monkeypatch):
    from torchratslam.experiments import run_state

    calls = []
    monkeypatch.setattr(rd, "DEFAULT_CHECKPOINT_EVERY", 10)
    real = run_state.save_run_state
    monkeypatch.setattr(
        run_state,
        "save_run_state",
        lambda slam, out, rec, info: (calls.append(info), real(slam, out, rec, info)),
    )
    data = "sim:loop?laps=1&frames=25"
    assert main([*_argv(data, tmp_path / "a"), "--no-progress"]) == 0
    assert [i.get("stopped_at_frame") for i in calls] == [10, 20, None]  # default, then final
    calls.clear()
    assert main([*_argv(data, tmp_path / "b"), "--no-progress", "--checkpoint-every", "0"]) == 0
    assert [i.get("stopped_at_frame") for i in calls] == [None]  # the final save only


def test_a_full_disk_names_the_file_keeps_the_checkpoint_and_says_how_to_resume(
    tmp_path, monkeypatch, capsys
):
    from torchratslam.maps import native

    monkeypatch.setattr(rd, "DEFAULT_CHECKPOINT_EVERY", 10)
    data = "sim:loop?laps=1&frames=40"
    full = tmp_path / "full"
    assert main([*_argv(data, full), "--no-progress"]) == 0
    real = native.write_directory_atomically
    saves = {"n": 0}

    def full_disk(target, *a, **k):
        saves["n"] += 1
        if saves["n"] >= 3:  # the third checkpoint (frame 30): the disk is full
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(target, *a, **k)

    monkeypatch.setattr(native, "write_directory_atomically", full_disk)
    out = tmp_path / "out"
    capsys.readouterr()
    assert main([*_argv(data, out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"cannot write {out / 'state'} (No space left on device)" in err
    assert "the last checkpoint (frame 20) is kept" in err and f"--resume {out}" in err
    assert read_map_info(out / "state")["stopped_at_frame"] == 20
    assert load_state(out).frame_index == 20  # whole and loadable
    assert not [p.name for p in out.iterdir() if ".new-" in p.name]  # no leftovers
    monkeypatch.setattr(native, "write_directory_atomically", real)
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    _same_map(full, out)


def test_load_runs_resume_and_an_unmerged_map_is_written_and_reported(tmp_path, capsys):
    s1 = tmp_path / "s1"
    assert main([*_argv(SESSION, s1), "--max-frames", "30"]) == 0
    # session 1 again, longer: its first template matches the stored map's (a merge)
    argv = [*_argv(SESSION, tmp_path / "m"), "--load", str(s1)]
    assert main([*argv, "--max-frames", "40", "--no-progress"]) == 0
    m = json.loads((tmp_path / "m" / "metrics.json").read_text())
    assert len(m["merges"]) == 1 and m["unmerged"] == []  # all merged
    # a --load run killed after its merge resumes to the uninterrupted run's map
    out = tmp_path / "out"
    script = tmp_path / "killer.py"
    script.write_text(KILLER)
    more = ["--max-frames", "40", "--checkpoint-every", "15", "--no-progress"]
    done = subprocess.run(
        [sys.executable, str(script), "35", *_argv(SESSION, out), "--load", str(s1), *more],
        capture_output=True,
        text=True,
    )
    assert done.returncode == -9, done.stderr[-2000:]
    info = read_map_info(out / "state")
    assert info["stopped_at_frame"] == 30 and len(info["multisession"]["merges"]) == 1
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    _same_map(tmp_path / "m", out)
    resumed = json.loads((out / "metrics.json").read_text())["merges"]
    assert [{**r, "time_s": 0} for r in resumed] == [{**r, "time_s": 0} for r in m["merges"]]
    capsys.readouterr()
    # a map of another place never merges: it is written to OUT/unmerged and said
    other = tmp_path / "other"
    assert main([*_argv("sim:loop?laps=1&frames=20", other), "--no-progress"]) == 0
    u = tmp_path / "u"
    argv = [*_argv(SESSION, u), "--load", str(other), "--no-progress"]
    assert main([*argv, "--max-frames", "20"]) == 0
    io = capsys.readouterr()
    assert "never merged" in io.err and "never merged" in io.out
    m = json.loads((u / "metrics.json").read_text())
    assert m["merges"] == [] and m["unmerged"] == [{"map": str(other), "written": "unmerged/map0"}]
    assert load_state(u / "unmerged" / "map0").equals(load_state(other))


@pytest.mark.parametrize("gone", ["moved", "deleted"])
def test_a_load_run_resumes_after_its_loaded_map_moved_or_went(tmp_path, capsys, gone):
    """The stored maps a ``--load`` run began with are kept in OUT while it can be
    resumed: the resumed run needs OUT alone, and ends with the uninterrupted run's map,
    bit for bit; a map merged before the stop and one never merged alike."""
    s1, other = tmp_path / "s1", tmp_path / "other"
    assert main([*_argv(SESSION, s1), "--max-frames", "30", "--no-progress"]) == 0
    assert main([*_argv("sim:loop?laps=1&frames=20", other), "--no-progress"]) == 0
    loads = ["--load", str(s1), "--load", str(other)]
    more = ["--max-frames", "40", "--checkpoint-every", "15", "--no-progress"]
    full = tmp_path / "full"
    assert main([*_argv(SESSION, full), *loads, *more]) == 0
    m = json.loads((full / "metrics.json").read_text())
    assert len(m["merges"]) == 1 and len(m["unmerged"]) == 1  # s1 merged, other never
    assert not (full / "loaded").exists()  # a finished run keeps no copies
    out = tmp_path / "out"
    script = tmp_path / "killer.py"
    script.write_text(KILLER)
    done = subprocess.run(
        [sys.executable, str(script), "35", *_argv(SESSION, out), *loads, *more],
        capture_output=True,
        text=True,
    )
    assert done.returncode == -9, done.stderr[-2000:]
    assert read_map_info(out / "state")["stopped_at_frame"] == 30
    before = {p: load_state(p) for p in (s1, other)}
    for p in (s1, other):  # the loaded maps move away (or are deleted) before the resume
        if gone == "moved":
            p.rename(tmp_path / f"{p.name}-moved")
        else:
            import shutil

            shutil.rmtree(p)
    capsys.readouterr()
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0, capsys.readouterr().err
    _same_map(full, out)
    resumed = json.loads((out / "metrics.json").read_text())
    assert [{**r, "time_s": 0} for r in resumed["merges"]] == [
        {**r, "time_s": 0} for r in m["merges"]
    ]
    assert resumed["unmerged"] == m["unmerged"] and resumed["loaded"] == m["loaded"]
    assert load_state(out / "unmerged" / "map1").equals(before[other])
    assert not (out / "loaded").exists()


def test_a_resume_whose_loaded_map_is_gone_and_not_kept_names_both_places(tmp_path, capsys):
    """A run stopped before runs kept their loaded maps (no OUT/loaded) cannot go on
    without the map: one line naming where it was and what OUT lacks; OUT untouched."""
    s1 = tmp_path / "s1"
    assert main([*_argv(SESSION, s1), "--max-frames", "20", "--no-progress"]) == 0
    out = tmp_path / "out"
    script = tmp_path / "killer.py"
    script.write_text(KILLER)
    more = ["--max-frames", "30", "--checkpoint-every", "10", "--no-progress"]
    done = subprocess.run(
        [sys.executable, str(script), "15", *_argv(SESSION, out), "--load", str(s1), *more],
        capture_output=True,
        text=True,
    )
    assert done.returncode == -9, done.stderr[-2000:]
    import shutil

    shutil.rmtree(out / "loaded")  # as an older run left it
    shutil.rmtree(s1)

    def files():  # the lock is taken and released again: its content is not the run's
        return sorted((p, p.stat().st_mtime_ns) for p in out.rglob("*") if p.name != LOCK)

    before = files()
    capsys.readouterr()
    assert main(["run", "--resume", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"the loaded map {s1} is gone" in err and "put the map back" in err
    assert len(err.strip().splitlines()) == 2 and "Traceback" not in err
    assert files() == before
