"""The one atomic writer: no window without a map, crash recovery, umask, lock, manifest."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
import textwrap

import pytest

from ratslam_graph import atomic
from ratslam_graph.atomic import (
    DirectoryLock,
    Manifest,
    atomic_write_text,
    write_directory_atomically,
)
from torchratslam.errors import InputError
from torchratslam.maps.native import load_map, load_state, save_map

from ..torchratslam.maps.test_state import random_map


def _crash_save(target, seed: int, at: int, *, exchange: bool) -> int:
    """Save random_map(seed) over ``target`` in a forked child that exits abruptly at the
    ``at``-th file-system step; returns the child's exit code (86: it crashed there)."""
    pid = os.fork()
    if pid == 0:  # child
        code = 0
        try:
            os.environ["TORCHRATSLAM_CRASH_AT"] = str(at)
            if not exchange:
                os.environ["TORCHRATSLAM_NO_EXCHANGE"] = "1"
            atomic._steps = 0
            save_map(random_map(seed), target)
        except BaseException:
            code = 1
        os._exit(code)
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status)


@pytest.mark.parametrize("exchange", [True, False], ids=["exchange", "two-renames"])
def test_a_kill_at_any_step_of_a_save_leaves_a_loadable_map(tmp_path, exchange):
    old, new = random_map(0), random_map(1)
    crashed_at = []
    for at in range(1, 40):
        target = tmp_path / f"run{at}" / "state"
        save_map(old, target)
        code = _crash_save(target, 1, at, exchange=exchange)
        assert code in (0, atomic.CRASH_EXIT_CODE)
        got = load_state(target)  # the map itself, as --load gives it
        assert got.equals(old) or got.equals(new), at
        assert load_state(target.parent).equals(got)  # the run's OUT works too
        if code == 0:
            assert got.equals(new)
            break
        crashed_at.append(at)
        # the next save cleans what the crash left
        save_map(new, target)
        assert load_map(target).equals(new)
        assert [p.name for p in target.parent.iterdir()] == ["state"]
    else:
        pytest.fail("the save never finished")
    assert len(crashed_at) >= 5  # every file write, fsync and rename was a kill point


@pytest.mark.parametrize("loader", ["native", "any format"])
def test_a_crash_between_the_two_renames_is_recovered_by_the_next_load(tmp_path, loader):
    from torchratslam.maps import io

    load_state_ = load_state if loader == "native" else io.load_state
    # the state the two-rename fallback leaves when killed between its renames
    target = tmp_path / "out" / "state"
    save_map(random_map(0), target)
    os.rename(target, tmp_path / "out" / ".state.old-999999-aa")
    save_map(random_map(1), tmp_path / "out" / ".state.new-999999-bb")
    assert not target.exists()
    assert load_state_(tmp_path / "out").equals(random_map(1))  # the finished new one
    assert target.is_dir()


def test_files_and_directories_respect_the_umask(tmp_path):
    old = os.umask(0o022)
    try:
        atomic_write_text(tmp_path / "a.txt", "x")
        write_directory_atomically(tmp_path / "d", {"f.bin": lambda fh: fh.write(b"1")})
        assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o644
        assert stat.S_IMODE((tmp_path / "d").stat().st_mode) == 0o755
        assert stat.S_IMODE((tmp_path / "d" / "f.bin").stat().st_mode) == 0o644
        os.umask(0o007)
        atomic_write_text(tmp_path / "b.txt", "x")
        assert stat.S_IMODE((tmp_path / "b.txt").stat().st_mode) == 0o660
    finally:
        os.umask(old)


def test_temporary_names_are_unique(tmp_path):
    names = {atomic.unique_name(tmp_path / "pose_cells.png", "tmp") for _ in range(100)}
    assert len(names) == 100


def test_a_second_writer_stops_at_once_naming_the_first(tmp_path):
    code = textwrap.dedent(
        f"""
        import sys, time
        from ratslam_graph.atomic import DirectoryLock
        lock = DirectoryLock({str(tmp_path)!r}, "torchratslam run").acquire()
        print("locked", flush=True)
        sys.stdin.read()
        """
    )
    child = subprocess.Popen(
        [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert child.stdout.readline().strip() == "locked"
        with pytest.raises(InputError, match=rf"in use by torchratslam run \(pid {child.pid}"):
            DirectoryLock(tmp_path).acquire()
    finally:
        child.communicate("")
    with DirectoryLock(tmp_path):  # free again once the first has ended
        pass


def test_manifest_overwrite_removes_only_recorded_files(tmp_path):
    (tmp_path / "a.csv").write_text("1")
    (tmp_path / "sub").mkdir()
    m = Manifest(tmp_path)
    m.add(["a.csv", "sub"])
    m.check_overwrite("overwrite it")
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match=r"did not write \(notes.txt\)"):
        m.check_overwrite("overwrite it")
    m.remove_recorded()
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        ".torchratslam-manifest.json",
        "notes.txt",
    ]


def test_two_writers_of_one_file_never_collide_on_a_temporary_name(tmp_path):
    import threading

    errors = []

    def write(tag):
        try:
            for _ in range(30):
                atomic_write_text(tmp_path / "pose_cells.png", tag * 1000)
        except Exception as exc:  # a shared temporary name fails here
            errors.append(exc)

    threads = [threading.Thread(target=write, args=(t,)) for t in "ab"]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert (tmp_path / "pose_cells.png").read_text() in ("a" * 1000, "b" * 1000)
    assert [p.name for p in tmp_path.iterdir()] == ["pose_cells.png"]
