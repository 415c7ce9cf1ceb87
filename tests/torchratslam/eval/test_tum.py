"""TUM trajectories: lossless files, evo's ATE equals the project's, and the per-frame
pose equals the experience map's own accumulators."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from torchratslam.cli import main
from torchratslam.config import load_config
from torchratslam.errors import InputError, MapFormatError
from torchratslam.eval.tum import (
    FramePoseRecorder,
    frame_poses,
    read_tum,
    tum_ate,
    write_tum,
)
from torchratslam.pipeline import RatSLAM
from torchratslam.readers.datasets import open_data

SMALL = (Path(__file__).resolve().parents[2] / "data" / "small.yaml").read_text()
SIM = "sim:loop?laps=2&frames=120"


def test_write_read_round_trip_is_lossless(tmp_path):
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.05, 0.2, 50)) + 1.3e9
    poses = np.column_stack([rng.normal(size=(50, 2)) * 10, rng.uniform(-np.pi, np.pi, 50)])
    poses[3] = np.nan  # skipped
    write_tum(tmp_path / "a.txt", t, poses, comment="test")
    tt, pp = read_tum(tmp_path / "a.txt")
    keep = np.ones(50, bool)
    keep[3] = False
    np.testing.assert_array_equal(tt, t[keep])
    np.testing.assert_array_equal(pp[:, :2], poses[keep, :2])
    np.testing.assert_allclose(pp[:, 2], poses[keep, 2], atol=1e-12)
    lines = (tmp_path / "a.txt").read_text().splitlines()
    assert lines[0] == "# test" and lines[1].startswith("# timestamp")
    assert all(len(s.split()) == 8 for s in lines[2:])
    (tmp_path / "bad.txt").write_text("1 2 3\n")
    with pytest.raises(MapFormatError, match="line 1"):
        read_tum(tmp_path / "bad.txt")


def test_a_file_that_cannot_be_written_is_named_not_its_temporary(tmp_path):
    (tmp_path / "a_file").write_text("")
    target = tmp_path / "a_file" / "tum.txt"  # its folder is a file
    with pytest.raises(InputError) as err:
        write_tum(target, np.array([1.0]), np.zeros((1, 3)))
    assert str(err.value).startswith(f"{target}: cannot be written")
    assert "tmp" not in str(err.value).replace(str(tmp_path), "")


def test_tum_ate_associates_by_timestamp(tmp_path):
    # the estimate covers every other ground-truth stamp, 1 ms late; a rigid motion apart
    t = np.arange(40) * 0.1
    gt = np.column_stack([np.cos(t), np.sin(2 * t), t])
    c, s = np.cos(0.7), np.sin(0.7)
    est = gt.copy()
    est[:, :2] = gt[:, :2] @ np.array([[c, -s], [s, c]]).T + [3.0, -1.0]
    est[::3, 0] += 0.05  # an error the alignment cannot remove
    write_tum(tmp_path / "gt.txt", t, gt)
    write_tum(tmp_path / "est.txt", t[::2] + 0.001, est[::2])
    # brute force: align the matched pairs by searching the rotation finely
    g, e = gt[::2, :2], est[::2, :2]
    best = np.inf
    for a in np.linspace(-np.pi, np.pi, 20001):
        r = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        m = e @ r.T
        m += (g - m).mean(axis=0)
        best = min(best, float(np.sqrt(np.mean(np.sum((m - g) ** 2, axis=1)))))
    assert tum_ate(tmp_path / "gt.txt", tmp_path / "est.txt") == pytest.approx(best, abs=1e-6)
    assert best > 0.005
    with pytest.raises(InputError, match="match"):
        tum_ate(tmp_path / "gt.txt", tmp_path / "est.txt", max_diff=1e-4)


def test_frame_pose_equals_the_experience_maps_accumulators(tmp_path):
    # without relaxation the experiences never move, so the per-frame pose must be the
    # pose at which the map would create an experience: current + accumulated odometry
    cfg_path = tmp_path / "small.yaml"
    # OpenRatSLAM does not restart the accumulators at its first experience, so on that one
    # frame the map's own pose counts the odometry before it twice: first experience at 0
    cfg_path.write_text(
        "exp_first_at_origin: true\n" + SMALL.replace("exp_loops: 5", "exp_loops: 0")
    )
    slam = RatSLAM(load_config(cfg_path))
    rec = FramePoseRecorder()
    live, kinds, seen = [], [], []

    def cb(r):
        rec(r)
        em = slam.experience_map
        if em.current_id < 0:  # OpenRatSLAM's frame 0: no experience yet, no pose
            return
        seen.append(r.frame)
        p = np.asarray(em.poses)[em.current_id]
        live.append((p[0] + em.accum_x, p[1] + em.accum_y, em.accum_facing))
        kinds.append((int(r.action.kind), r.action.relative_rad))

    slam.run(open_data(SIM), progress=False, callback=cb)
    got = rec.poses(slam)[seen]
    live = np.asarray(live)
    d = got - live
    d[:, 2] = np.angle(np.exp(1j * d[:, 2]))
    assert np.abs(d).max() < 1e-9
    assert any(k == 2 and r != 0 for k, r in kinds)  # a LINK with a view offset was checked
    assert not all(rec.reset)  # and frames that accumulate odometry


def test_frame_poses_hand_example():
    # one experience at (1, 2, pi/2); then two frames of 1 m forward, a 90 degree turn
    traj = np.array([[0, 0, 0, 1, 2, np.pi / 2]] * 3, dtype=float)
    odo = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [1.0, np.pi / 2, 1.0]])
    out = frame_poses(traj, odo, np.array([True, False, False]), np.zeros(3))
    np.testing.assert_allclose(out[0], [1, 2, np.pi / 2], atol=1e-12)
    np.testing.assert_allclose(out[1], [1, 3, np.pi / 2], atol=1e-12)
    np.testing.assert_allclose(out[2], [0, 3, np.pi], atol=1e-12)
    with pytest.raises(InputError, match="one row per frame"):
        frame_poses(traj, odo[:2], np.ones(3, bool), np.zeros(3))


@pytest.fixture(scope="module")
def tum_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("tum")
    cfg = root / "small.yaml"
    cfg.write_text(SMALL)
    out = root / "out"
    args = ["run", "--config", str(cfg), "--data", SIM, "--out", str(out), "--no-progress"]
    assert main([*args, "--tum"]) == 0
    return out


def _evo_ate(gt: Path, est: Path) -> float:
    pytest.importorskip("evo", reason="evo (the 'evo' extra) is not installed")
    from evo.core import metrics, sync
    from evo.tools import file_interface

    ref = file_interface.read_tum_trajectory_file(str(gt))
    e = file_interface.read_tum_trajectory_file(str(est))
    ref, e = sync.associate_trajectories(ref, e, max_diff=0.01)
    e.align(ref, correct_scale=False)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, e))
    return float(ape.get_statistic(metrics.StatisticsType.rmse))


def _stamps(path: Path) -> list[float]:
    return [float(line.split()[0]) for line in path.read_text().splitlines() if line[:1] != "#"]


def _matched(gt: Path, est: Path) -> int:
    """The estimate's poses with a ground-truth pose within 0.01 s, counted one by one."""
    t_gt = _stamps(gt)
    return sum(1 for t in _stamps(est) if min(abs(t - g) for g in t_gt) <= 0.01)


def test_evo_ate_equals_the_projects(tum_run):
    out = tum_run
    m = json.loads((out / "metrics.json").read_text())
    assert m["tum"] == {
        "experience": "tum_experience.txt",
        "frame": "tum_frame.txt",
        "groundtruth": "tum_groundtruth.txt",
    }
    gt = out / "tum_groundtruth.txt"
    for name in ("experience", "frame"):
        est = out / f"tum_{name}.txt"
        ours = tum_ate(gt, est)
        assert ours == pytest.approx(_evo_ate(gt, est), abs=1e-6)
        assert m[f"ate_{name}_rmse_m"] == ours
    # the experience estimate is the run's trajectory: same ATE as metrics.json's
    assert m["ate_experience_rmse_m"] == pytest.approx(m["ate_rmse_m"], abs=1e-9)
    # the TUM ATEs say what they are taken over: their alignment and the matched poses,
    # counted here by a loop over the files' timestamps
    said = m["tum_ate_poses"]
    assert "evo_ape -a" in said["alignment"] and "0.01 s" in said["over"]
    for name in ("experience", "frame"):
        assert said[name] == _matched(gt, out / f"tum_{name}.txt") >= 3
    assert m["ate_frame_rmse_m"] != m["ate_experience_rmse_m"]


def test_evo_ape_command_reads_the_files(tum_run):
    evo_ape = Path(sys.executable).parent / "evo_ape"
    if not evo_ape.exists():
        pytest.skip("evo_ape script not on this interpreter's path")
    gt, est = tum_run / "tum_groundtruth.txt", tum_run / "tum_frame.txt"
    res = subprocess.run(
        [str(evo_ape), "tum", str(gt), str(est), "-a"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    rmse = next(float(s.split()[1]) for s in lines if s.strip().startswith("rmse"))
    assert rmse == pytest.approx(tum_ate(gt, est), abs=1e-6)


def test_a_tum_ate_under_three_matched_poses_is_undefined(tmp_path):
    cfg = tmp_path / "small.yaml"
    cfg.write_text(SMALL)
    out = tmp_path / "out"
    args = ["run", "--config", str(cfg), "--data", SIM, "--out", str(out), "--no-progress"]
    assert main([*args, "--tum", "--max-frames", "2"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    gt = out / "tum_groundtruth.txt"
    for name in ("experience", "frame"):
        assert m["tum_ate_poses"][name] == _matched(gt, out / f"tum_{name}.txt") < 3
    assert "ate_frame_rmse_m" not in m and "ate_experience_rmse_m" not in m
