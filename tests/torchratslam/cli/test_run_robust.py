"""``torchratslam run`` loses nothing and says everything: checks before the work, a
partial map on any stop, checkpoints, ``--resume`` bit for bit, one writer per OUT,
nothing it did not write replaced, no empty OUT after a failure, global options."""

from __future__ import annotations

import json
import os
import shutil
import signal
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch

from ratslam_graph.atomic import LOCK_NAME as LOCK
from torchratslam.cli import main
from torchratslam.maps.native import load_map, load_state, read_map_info

SMALL = (Path(__file__).resolve().parents[2] / "data" / "small.yaml").read_text()
N = 40


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    """A 40-frame dataset directory, the config, and an uninterrupted run of it."""
    from torchratslam.sim import open_sim, write_dataset

    root = tmp_path_factory.mktemp("robust")
    cfg = root / "small.yaml"
    cfg.write_text(SMALL)
    data = write_dataset(open_sim(f"sim:loop?laps=1&frames={N}"), root / "ds")
    full = root / "full"
    assert main(_argv(cfg, data, full)) == 0
    return root, cfg, data, full


def _argv(cfg, data, out, *more):
    return ["run", "--config", str(cfg), "--data", str(data), "--out", str(out), "--no-progress"]


def _same_run(a, b):
    assert load_map(a / "state").equals(load_map(b / "state"))
    for name in ("experiences.csv", "trajectory.csv"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


def _copy_data(data, dst):
    shutil.copytree(data, dst)
    return dst


def test_a_bad_frame_keeps_the_map_and_resume_gives_the_uninterrupted_map(setup, tmp_path, capsys):
    _, cfg, data, full = setup
    ds = _copy_data(data, tmp_path / "ds")
    good = (ds / "frames" / "000025.png").read_bytes()
    (ds / "frames" / "000025.png").write_bytes(b"not a png")
    out = tmp_path / "out"
    capsys.readouterr()
    assert main(_argv(cfg, ds, out)) == 2
    err = capsys.readouterr().err
    assert "stopped at frame 25" in err and "--resume" in err and "000025.png" in err
    info = read_map_info(out / "state")
    assert info["partial"] and info["stopped_at_frame"] == 25 and "000025.png" in info["reason"]
    assert load_state(out).frame_index == 25  # a valid, loadable map as of frame 25
    m = json.loads((out / "metrics.json").read_text())
    assert m["partial"] and m["stopped_at_frame"] == 25 and m["frames"] == 25
    (ds / "frames" / "000025.png").write_bytes(good)
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    _same_run(full, out)  # bit for bit
    assert not read_map_info(out / "state")["partial"]
    assert main(["run", "--resume", str(out), "--no-progress"]) == 2  # finished: nothing to do
    assert "nothing to resume" in capsys.readouterr().err


def test_the_budgeted_relaxation_resumes_where_it_stopped(setup, tmp_path, capsys):
    """``exp_relax_budget`` goes on round the links from a saved position: a run stopped
    by a bad frame and resumed makes the uninterrupted run's map, bit for bit."""
    _, cfg, data, _ = setup
    sets = ["--set", "exp_relax_budget=37", "--set", "exp_correction=0.95"]
    full = tmp_path / "full"
    assert main([*_argv(cfg, data, full), *sets]) == 0
    ds = _copy_data(data, tmp_path / "ds")
    good = (ds / "frames" / "000031.png").read_bytes()
    (ds / "frames" / "000031.png").write_bytes(b"not a png")
    out = tmp_path / "out"
    assert main([*_argv(cfg, ds, out), *sets]) == 2
    state = load_state(out)
    assert state.frame_index == 31 and 5 * state.n_links > 37  # the budget binds
    (ds / "frames" / "000031.png").write_bytes(good)
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    _same_run(full, out)
    capsys.readouterr()


class _Interrupting:
    """Wraps a reader; sends this process a real SIGINT while frame ``at`` is read."""

    def __init__(self, data, at):
        self.data, self.at = data, at
        self.has_odometry, self.mirrored = data.has_odometry, data.mirrored

    def __len__(self):
        return len(self.data)

    def groundtruth(self):
        return self.data.groundtruth()

    def frames(self):
        for k, f in enumerate(self.data.frames()):
            if k == self.at:
                os.kill(os.getpid(), signal.SIGINT)
            yield f


def test_ctrl_c_stops_between_frames_keeps_the_map_and_checkpoints_load(
    setup, tmp_path, monkeypatch, capsys
):
    from torchratslam.experiments import run_state as run_mod
    from torchratslam.readers import datasets

    _, cfg, data, full = setup
    real_open = datasets.open_data
    monkeypatch.setattr(
        datasets, "open_data", lambda *a, **k: _Interrupting(real_open(*a, **k), 17)
    )
    saved = []
    real_save = run_mod.save_run_state

    def spy(slam, out, record, info):
        real_save(slam, out, record, info)
        saved.append((load_state(out / "state").frame_index, read_map_info(out / "state")))

    monkeypatch.setattr(run_mod, "save_run_state", spy)
    out = tmp_path / "out"
    assert main([*_argv(cfg, data, out), "--checkpoint-every", "5"]) == 130
    err = capsys.readouterr().err
    assert "stopping after this frame" in err and "stopped at frame 17" in err
    # checkpoints at 5, 10, 15, each a loadable partial map; then the stop at 17
    assert [f for f, _ in saved] == [5, 10, 15, 17]
    assert all(i["partial"] for _, i in saved)
    assert saved[-1][1]["reason"] == "interrupted (Ctrl-C)"
    monkeypatch.setattr(datasets, "open_data", real_open)
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    _same_run(full, out)


def test_checks_before_the_work_fail_with_one_line_and_leave_no_out(setup, tmp_path, capsys):
    _, cfg, data, _ = setup
    out = tmp_path / "new" / "out"
    cases = [
        (["--device", "foo"], "not a torch device"),
        (["--set", "pc_dim_xy=100000"], "pose-cell network needs"),
        (["--set", "image_crop_x_min=10", "--set", "image_crop_x_max=5"], "image_crop_x_max"),
        (["--set", "pc_dim_xy=abc"], "--set: parameter 'pc_dim_xy'"),
        (["--image-topic", "/cam"], "--image-topic does not apply to directory data"),
    ]
    if not torch.cuda.is_available():
        cases.append((["--device", "cuda"], "has no CUDA"))
    for more, match in cases:
        capsys.readouterr()
        assert main([*_argv(cfg, data, out), *more]) == 2, more
        err = capsys.readouterr().err.strip().splitlines()
        assert match in err[0] and len(err) == 2, err
        assert not (tmp_path / "new").exists()  # a failed run leaves no empty OUT
    sim = ["run", "--config", str(cfg), "--data", "sim:loop", "--out", str(out)]
    for opt in ("--odometry", "--groundtruth"):
        assert main([*sim, opt, str(data / "odometry.csv")]) == 2
        assert f"{opt} does not apply to sim data" in capsys.readouterr().err
    # a file where the map directory goes
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "state").write_text("x")
    assert main(_argv(cfg, data, bad)) == 2
    assert "state exists and is not a directory" in capsys.readouterr().err


def test_the_video_frame_count_is_checked_before_the_work(setup, tmp_path, capsys):
    import cv2

    _, cfg, _, _ = setup
    video = tmp_path / "v.avi"
    w = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 5.0, (32, 24), False)
    for k in range(6):
        w.write(np.full((24, 32), 20 * k, np.uint8))
    w.release()
    odo = tmp_path / "odo.csv"
    odo.write_text("t,vtrans,vrot\n" + "".join(f"{0.2 * k},0.1,0\n" for k in range(5)))
    argv = [*_argv(cfg, video, tmp_path / "o"), "--odometry", str(odo)]
    assert main(argv) == 2
    assert "6 frames but 5 rows" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_files_the_project_did_not_write_are_never_replaced(setup, tmp_path, capsys):
    _, cfg, data, _ = setup
    out = tmp_path / "out"
    out.mkdir()
    (out / "metrics.json").write_text("my notes")
    assert main([*_argv(cfg, data, out), "--max-frames", "3"]) == 2
    assert "did not write" in capsys.readouterr().err
    assert (out / "metrics.json").read_text() == "my notes"
    # a second run over its own outputs (--overwrite: the first one finished) keeps the
    # user's other files
    out2 = tmp_path / "out2"
    out2.mkdir()
    (out2 / "notes.txt").write_text("keep")
    assert main([*_argv(cfg, data, out2), "--max-frames", "3"]) == 0
    assert main([*_argv(cfg, data, out2), "--max-frames", "4", "--overwrite"]) == 0
    assert (out2 / "notes.txt").read_text() == "keep"


def test_a_second_run_on_one_out_stops_at_once_naming_the_first(setup, tmp_path, capsys):
    _, cfg, data, _ = setup
    out = tmp_path / "out"
    code = textwrap.dedent(
        f"""
        import sys
        from ratslam_graph.atomic import DirectoryLock
        lock = DirectoryLock({str(out)!r}, "torchratslam run --out X").acquire()
        print("locked", flush=True)
        sys.stdin.read()
        """
    )
    child = subprocess.Popen(
        [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert child.stdout.readline().strip() == "locked"
        assert main(_argv(cfg, data, out)) == 2
        err = capsys.readouterr().err
        assert f"in use by torchratslam run --out X (pid {child.pid}, started" in err
    finally:
        child.communicate("")
    assert not (out / "metrics.json").exists()


def test_outputs_respect_the_umask(setup, tmp_path):
    _, cfg, data, _ = setup
    old = os.umask(0o002)
    try:
        out = tmp_path / "out"
        assert main([*_argv(cfg, data, out), "--max-frames", "3"]) == 0
    finally:
        os.umask(old)
    for p in [out, out / "state", *out.iterdir(), *(out / "state").iterdir()]:
        want = 0o775 if p.is_dir() else 0o664
        assert stat.S_IMODE(p.stat().st_mode) == want, p


def test_global_options_anywhere_version_and_quiet_broken_pipes(setup, tmp_path, capsys):
    _, cfg, data, _ = setup
    assert main(["--version"]) == 0 and capsys.readouterr().out.startswith("torchratslam ")
    # --debug after the subcommand: the traceback is shown
    assert main([*_argv(cfg, data, tmp_path / "o"), "--set", "pc_dim_xy=0", "--debug"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" in err and "run with --debug" not in err
    # -v / -q anywhere set the torchratslam logger's level
    import logging

    assert main(["-q", "run", "--config", str(cfg), "--data", "sim:nowhere", "--out", "x"]) == 2
    assert logging.getLogger("torchratslam").level == logging.ERROR
    assert main(["run", "-vv", "--config", str(cfg), "--data", "sim:nowhere", "--out", "x"]) == 2
    assert logging.getLogger("torchratslam").level == logging.DEBUG
    logging.getLogger("torchratslam").setLevel(logging.WARNING)
    # a reader that goes away (| head) ends the command quietly
    code = textwrap.dedent(
        """
        import sys
        from torchratslam.cli import main
        sys.exit(main(["--version"] if len(sys.argv) < 2 else sys.argv[1:]))
        """
    )
    script = tmp_path / "m.py"
    script.write_text(code)
    r, w = os.pipe()
    os.close(r)  # nobody reads: the first write raises BrokenPipeError
    done = subprocess.run(
        [sys.executable, str(script), "--version"], stdout=w, stderr=subprocess.PIPE, text=True
    )
    os.close(w)
    assert "BrokenPipe" not in done.stderr and "Traceback" not in done.stderr


def test_simulate_overwrite_removes_only_what_it_wrote(tmp_path, capsys):
    out = tmp_path / "ds"
    argv = ["simulate", "sim:loop?laps=0.1&frames=4", "--out", str(out), "--quiet"]
    assert main(argv) == 0
    (out / "notes.txt").write_text("mine")
    assert main([*argv, "--overwrite"]) == 2
    assert "did not write (notes.txt)" in capsys.readouterr().err
    assert (out / "notes.txt").read_text() == "mine" and (out / "odometry.csv").is_file()
    (out / "notes.txt").unlink()
    assert main([*argv, "--overwrite"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]  # no leftovers beside it


def test_a_read_only_out_is_refused_before_the_work(setup, tmp_path, monkeypatch, capsys):
    _, cfg, data, _ = setup
    out = tmp_path / "ro"
    out.mkdir()
    if os.geteuid() != 0:  # a real read-only directory
        out.chmod(0o555)
    else:  # root may write anywhere: the OS reports a read-only directory the same way
        real = os.access
        monkeypatch.setattr(os, "access", lambda p, m: False if str(p) == str(out) else real(p, m))
    try:
        assert main(_argv(cfg, data, out)) == 2
        assert f"--out {out}: {out} is not writable" in capsys.readouterr().err
    finally:
        out.chmod(0o755)
    assert list(out.iterdir()) == []


def test_a_run_killed_during_a_checkpoint_resumes_to_the_uninterrupted_map(setup, tmp_path):
    _, cfg, data, full = setup
    out = tmp_path / "out"
    env = {**os.environ, "TORCHRATSLAM_CRASH_AT": "16"}  # inside the second checkpoint's save
    argv = _argv(cfg, data, out)[1:]
    done = subprocess.run(
        [sys.executable, "-m", "torchratslam", "run", *argv, "--checkpoint-every", "10"],
        env=env,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 86, done.stderr[-2000:]  # killed, nothing ran after
    info = read_map_info(out / "state")
    assert info["partial"] and info["stopped_at_frame"] in (10, 20)
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    _same_run(full, out)


def test_a_run_stopped_before_double_became_the_default_resumes_as_it_began(setup, tmp_path):
    """A record without the ``dtype`` key was written when float32 was the default: it
    resumes in float32, to the map an uninterrupted float32 run makes, bit for bit."""
    _, cfg, data, _ = setup
    full32 = tmp_path / "full32"
    assert main([*_argv(cfg, data, full32), "--set", "dtype=float32"]) == 0
    ds = _copy_data(data, tmp_path / "ds")
    good = (ds / "frames" / "000025.png").read_bytes()
    (ds / "frames" / "000025.png").write_bytes(b"not a png")
    out = tmp_path / "out"
    assert main([*_argv(cfg, ds, out), "--set", "dtype=float32"]) == 2
    record = json.loads((out / "run.json").read_text())
    del record["config_flat"]["dtype"]
    (out / "run.json").write_text(json.dumps(record))
    (ds / "frames" / "000025.png").write_bytes(good)
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    _same_run(full32, out)
    assert load_state(out).activity.dtype == np.float32  # float32 throughout


def test_a_plain_re_run_refuses_an_out_holding_a_stopped_run(setup, tmp_path, capsys):
    """Re-running the command of a stopped run refuses in one line and points to
    --resume; --overwrite starts again, replacing only torchratslam's own files."""
    _, cfg, data, full = setup
    ds = _copy_data(data, tmp_path / "ds")
    good = (ds / "frames" / "000021.png").read_bytes()
    (ds / "frames" / "000021.png").write_bytes(b"not a png")
    out = tmp_path / "out"
    assert main(_argv(cfg, ds, out)) == 2
    (out / "notes.txt").write_text("mine")
    (ds / "frames" / "000021.png").write_bytes(good)

    def files():
        return {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and p.name != LOCK}

    before = files()
    capsys.readouterr()
    assert main(_argv(cfg, ds, out)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "holds a run that stopped at frame 21" in err[0]
    assert f"torchratslam run --resume {out}" in err[0] and "--overwrite" in err[0]
    assert files() == before  # the lock file aside, nothing changed
    assert read_map_info(out / "state")["stopped_at_frame"] == 21
    assert main([*_argv(cfg, ds, out), "--overwrite"]) == 0
    _same_run(full, out)
    assert (out / "notes.txt").read_text() == "mine"
    assert main(["run", "--resume", str(out), "--overwrite"]) == 2  # not both


def test_the_same_run_typed_twice_refuses_and_keeps_the_finished_run(setup, tmp_path, capsys):
    """A finished run is never replaced by the same command typed again: one line naming
    --overwrite, every file as it was; with --overwrite the same run again."""
    _, cfg, data, full = setup
    out = tmp_path / "out"
    shutil.copytree(full, out)
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file() and p.name != LOCK}
    capsys.readouterr()
    assert main(_argv(cfg, data, out)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "holds a finished run" in err[0] and "--overwrite" in err[0]
    after = {p: p.read_bytes() for p in out.rglob("*") if p.is_file() and p.name != LOCK}
    assert after == before
    assert main([*_argv(cfg, data, out), "--overwrite"]) == 0
    _same_run(full, out)


def test_run_help_says_what_run_does_and_shows_the_required_options(capsys):
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = capsys.readouterr().out
    usage = text.split("\n\n")[0]
    assert "--config CONFIG --data DATA --out OUT" in usage and "[--config" not in usage
    assert "--resume OUT" in usage
    assert "files in it are replaced" not in text
    assert "replaces only the files it wrote" in " ".join(text.split())
    assert "every 1000 frames" in " ".join(text.split())


@pytest.mark.parametrize("flag", ["--max-speed", "--max-turn-rate"])
@pytest.mark.parametrize("value", ["-1", "0", "nan", "inf"])
def test_a_limit_that_is_not_above_zero_is_refused_naming_the_flag(
    setup, tmp_path, capsys, flag, value
):
    """--max-speed -1 is the user's mistake, not the data's: refused naming the flag,
    before any work, leaving no OUT."""
    _, cfg, data, _ = setup
    out = tmp_path / "new" / "out"
    assert main([*_argv(cfg, data, out), flag, value]) == 2
    err = capsys.readouterr().err
    assert flag in err and "above 0" in err and "Traceback" not in err
    assert "exceeds" not in err and not (tmp_path / "new").exists()


def test_the_python_api_names_the_limit_argument():
    from torchratslam.errors import InputError
    from torchratslam.readers.datasets import check_odometry

    with pytest.raises(InputError, match=r"^max_speed = -1\.0: a limit must be"):
        check_odometry(np.zeros(3), np.zeros(3), "odo.csv", max_speed=-1.0)


def _ate_over(traj_csv, gt, frames):
    """The ATE written out by hand: SE(2) (Kabsch) fit of the trajectory's experience
    positions to the ground truth on the given frames, then the RMS residual."""
    rows = np.loadtxt(traj_csv, delimiter=",", skiprows=1)[frames]
    rows = rows[np.isfinite(rows[:, 3])]  # frames before the first experience
    est = rows[:, 3:5]
    ref = np.stack([np.interp(rows[:, 1], gt[:, 0], gt[:, k]) for k in (1, 2)], axis=1)
    a, b = est - est.mean(0), ref - ref.mean(0)
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(u @ vt))
    rot = (u @ np.diag([1.0, d]) @ vt).T
    res = (rot @ a.T).T - b
    return float(np.sqrt((res**2).sum(1).mean()))


def test_partial_ground_truth_gives_the_ate_over_the_frames_it_covers(setup, tmp_path, capsys):
    """groundtruth.csv covering 24 of 40 frames: the ATE is taken over those 24 frames
    (no pose clamped to the last one), and metrics.json and the printed line say so."""
    _, cfg, data, full = setup
    part = _copy_data(data, tmp_path / "ds")
    gt_path = part / "groundtruth.csv"
    lines = gt_path.read_text().splitlines()
    gt = np.loadtxt(data / "groundtruth.csv", delimiter=",", skiprows=1)
    times = np.loadtxt(full / "trajectory.csv", delimiter=",", skiprows=1)[:, 1]
    keep = int(np.searchsorted(gt[:, 0], times[23], side="right"))
    gt_path.write_text("\n".join(lines[: 1 + keep]) + "\n")
    covered = np.flatnonzero(times <= gt[keep - 1, 0] + 1e-9)
    assert covered.size == 24  # frame 0 has no experience yet: 23 map poses
    capsys.readouterr()
    out = tmp_path / "out"
    assert main(_argv(cfg, part, out)) == 0
    printed = capsys.readouterr().out
    m = json.loads((out / "metrics.json").read_text())
    assert m["ate_frames"] == 23
    want = _ate_over(out / "trajectory.csv", gt, covered)
    assert m["ate_rmse_m"] == pytest.approx(want, rel=1e-9, abs=1e-12)
    assert "SE(2)-aligned, over 23 of 40 frames" in printed
    clamped = _ate_over(out / "trajectory.csv", gt[:keep], np.arange(40))
    assert abs(m["ate_rmse_m"] - clamped) > 1e-6  # what it used to report


def test_a_map_of_fewer_than_three_poses_has_no_ate(setup, tmp_path, capsys):
    _, cfg, data, _ = setup
    out = tmp_path / "out"
    capsys.readouterr()
    assert main([*_argv(cfg, data, out), "--max-frames", "2"]) == 0
    printed = capsys.readouterr().out
    m = json.loads((out / "metrics.json").read_text())
    assert m["ate_rmse_m"] is None and m.get("dead_reckoning_ate_m") is None
    assert m["ate_frames"] == 1 and "needs 3" in m["ate_undefined"]
    assert "ATE undefined (1 of 2 frames have a map pose and ground truth; it needs 3)" in printed
    assert "ATE 0" not in printed and "ATE 7" not in printed


def test_odometry_times_in_another_unit_than_the_ground_truth_are_refused(setup, tmp_path, capsys):
    """Odometry times x 1e-9 with ground truth in seconds used to give "ATE 0.000 m vs
    dead reckoning 0.000 m" (the tour squeezed into nanometres): refused in one line."""
    _, cfg, data, _ = setup
    part = _copy_data(data, tmp_path / "ds")
    odo = part / "odometry.csv"
    lines = odo.read_text().splitlines()
    head = lines[0].split(",")
    col = head.index("t")
    rows = []
    for line in lines[1:]:
        cells = line.split(",")
        cells[col] = repr(float(cells[col]) * 1e-9)
        rows.append(",".join(cells))
    odo.write_text("\n".join([lines[0], *rows]) + "\n")
    out = tmp_path / "out"
    capsys.readouterr()
    assert main(_argv(cfg, part, out)) == 2
    err = capsys.readouterr().err
    assert "different time units" in err and "Traceback" not in err
    assert not out.exists()
