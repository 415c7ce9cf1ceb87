"""The per-frame history: trajectory through the map, ATE, remapping and saving."""

import numpy as np
import pytest

from torchratslam.eval.metrics import ate_rmse, dead_reckoning
from torchratslam.pipeline.history import History


def _history(n=12, seed=0, gt=True, missing=()):
    rng = np.random.default_rng(seed)
    h = History()
    for k in range(n):
        pose = tuple(rng.random(3)) if gt and k not in missing else None
        odo = (float(rng.random()), float(rng.random() - 0.5), 0.0 if k == 0 else 0.5)
        h.append(k, 0.5 * k, -1 if k == 0 else k // 3, pose, odo, tuple(rng.random(3)))
    return h


def test_trajectory_reads_each_frames_experience_pose():
    h = _history()
    poses = np.arange(12.0).reshape(4, 3)  # experience 3 (frames 9..11) exists
    traj = h.trajectory(poses[:3])  # ...but not in this map: NaN like frame 0
    assert traj.shape == (12, 6) and len(h) == 12
    for row in traj:
        frame, t, exp = int(row[0]), row[1], int(row[2])
        assert t == 0.5 * frame
        if 0 <= exp < 3:
            assert np.array_equal(row[3:], poses[exp])
        else:
            assert np.isnan(row[3:]).all()


def test_ate_and_dead_reckoning_use_the_frames_ground_truth():
    h = _history()
    poses = np.random.default_rng(1).random((4, 3))
    traj = h.trajectory(poses)
    gt = h.groundtruth_poses()
    ok = np.isfinite(traj[:, 3])
    assert h.ate(poses) == pytest.approx(ate_rmse(traj[ok, 3:5], gt[ok, :2]))
    odo = h.odometry_log()
    dr = dead_reckoning(odo[:, 0], odo[:, 1], odo[:, 2])
    assert h.dead_reckoning_ate() == pytest.approx(ate_rmse(dr[:, :2], gt[:, :2]))
    # a ground-truth table interpolated at the frame times replaces the frames' own
    table = np.column_stack([h.times(), gt])
    assert h.ate(poses, table) == pytest.approx(h.ate(poses))
    blind = _history(gt=False)
    assert blind.groundtruth_poses() is None and blind.ate(poses) is None
    assert blind.dead_reckoning_ate() is None and History().ate(poses) is None


def test_remap_repoints_only_known_experiences():
    h = _history()
    before = h.trajectory(np.zeros((4, 3)))[:, 2].astype(int)
    old_to_new = np.array([2, -1, 0])  # experience 3 is beyond the mapping: kept
    h.remap_experiences(old_to_new)
    after = h.trajectory(np.zeros((4, 3)))[:, 2].astype(int)
    want = [old_to_new[e] if 0 <= e < 3 else e for e in before]
    assert after.tolist() == want and before.tolist() != want


def test_arrays_restore_round_trip_and_clear():
    h = _history(missing=(4,))  # one frame without ground truth
    a = h.arrays()
    assert a["gt_ok"].tolist() == [k != 4 for k in range(12)] and np.isnan(a["gt"][4]).all()
    back = History()
    back.restore(a)
    b = back.arrays()
    assert a.keys() == b.keys()
    assert all(np.array_equal(a[k], b[k], equal_nan=True) for k in a)
    assert back.groundtruth_poses() is None and np.array_equal(back.pc_log(), h.pc_log())
    with pytest.raises(ValueError, match="different lengths"):
        back.restore({**a, "t": a["t"][:-1]})
    with pytest.raises(KeyError):
        back.restore({k: v for k, v in a.items() if k != "pc"})
    back.clear()
    assert len(back) == 0 and back.trajectory(np.zeros((1, 3))).shape == (0, 6)
