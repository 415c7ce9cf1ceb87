"""The per-frame record of a run (:class:`History`) and what is read from it: the
trajectory through the experience map, the ATE against ground truth, the dead-reckoning
baseline and the pose-cell centres."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

__all__ = ["History"]

# the columns of a row
_FRAME, _T, _EXP, _GT_OK, _GT, _ODO, _PC = 0, 1, 2, 3, 4, 7, 10
_COLUMNS = 13
_NO_POSE = (np.nan, np.nan, np.nan)


# An ATE is undefined below this many poses with ground truth (a rigid SE(2) alignment
# fits two poses exactly).
MIN_ATE_POSES = 3


def _inside(groundtruth: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Which times lie inside the ground truth's time range (no clamped poses)."""
    gt_t = np.asarray(groundtruth, dtype=np.float64)[:, 0]
    return (t >= gt_t[0] - 1e-9) & (t <= gt_t[-1] + 1e-9)


class History:
    """One row per processed frame: frame index, time, current experience, ground-truth
    pose (None when the frame had none), odometry ``(vtrans, vrot, dt)`` and pose-cell
    packet centre ``(x, y, th)`` in cells.

    The rows live in one float64 array grown by doubling (13 numbers a frame, no Python
    object per frame); frame indices and experience ids are exact in float64.

    Example:
        >>> h = History()
        >>> h.append(0, 0.0, -1, None, (0.0, 0.0, 0.0), (1.0, 2.0, 3.0))
        >>> h.append(1, 0.5, 0, (0.1, 0.0, 0.0), (0.2, 0.0, 0.5), (1.0, 2.0, 3.0))
        >>> h.trajectory(np.array([[4.0, 5.0, 0.0]]))[:, 2:4].tolist()
        [[-1.0, nan], [0.0, 4.0]]
    """

    def __init__(self) -> None:
        self._rows = np.zeros((0, _COLUMNS))
        self._n = 0

    def __len__(self) -> int:
        return self._n

    def append(
        self,
        frame: int,
        t: float,
        experience_id: int,
        pose: Sequence[float] | None,
        odometry: tuple[float, float, float],
        pc: tuple[float, float, float],
    ) -> None:
        """Record one frame (``pose``: its ground truth ``(x, y, th)`` or None)."""
        i = self._n
        if i == len(self._rows):
            grown = np.zeros((max(64, 2 * i), _COLUMNS))
            grown[:i] = self._rows[:i]
            self._rows = grown
        gx, gy, gth = _NO_POSE if pose is None else pose
        self._rows[i] = (
            frame,
            t,
            experience_id,
            pose is not None,
            gx,
            gy,
            gth,
            *odometry,
            *pc,
        )
        self._n = i + 1

    def clear(self) -> None:
        """Forget every frame."""
        self._n = 0

    def _col(self, a: int, b: int | None = None) -> np.ndarray:
        """Columns ``a`` (or ``a:b``) of the rows in use, copied."""
        rows = self._rows[: self._n]
        return (rows[:, a] if b is None else rows[:, a:b]).copy()

    # ------------------------------------------------------------------ outputs
    def times(self) -> np.ndarray:
        """The frames' time stamps (s). Shape: ``(F,)`` float64."""
        return self._col(_T)

    def trajectory(self, poses: np.ndarray) -> np.ndarray:
        """Per frame: ``[frame, t, experience_id, x, y, th]`` with the experience's pose
        from ``poses`` (NaN where the frame had no experience).

        Shape:
            poses: ``(N, 3)``, row = experience id; returns ``(F, 6)`` float64.
        """
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        exp = self._col(_EXP).astype(np.int64)
        out = np.full((exp.shape[0], 6), np.nan)
        out[:, :3] = self._col(_FRAME, _EXP + 1)
        ok = (exp >= 0) & (exp < poses.shape[0])
        out[ok, 3:] = poses[exp[ok]]
        return out

    def groundtruth_poses(self) -> np.ndarray | None:
        """The frames' ground-truth poses ``(F, 3)``, or None if any frame had none."""
        if self._n == 0 or not self._rows[: self._n, _GT_OK].all():
            return None
        return self._col(_GT, _GT + 3)

    def odometry_log(self) -> np.ndarray:
        """The ``(vtrans, vrot, dt)`` used for each frame. Shape: ``(F, 3)``."""
        return self._col(_ODO, _ODO + 3)

    def pc_log(self) -> np.ndarray:
        """The pose-cell packet centre ``(x, y, th)`` in cells after each frame.

        Shape:
            returns ``(F, 3)``.
        """
        return self._col(_PC, _PC + 3)

    def ate(self, poses: np.ndarray, groundtruth: np.ndarray | None = None) -> float | None:
        """ATE (m) of :meth:`trajectory` (``poses``: the experiences') after SE(2)
        alignment; ``groundtruth``: ``(T, 4)`` rows ``[t, x, y, theta]`` interpolated at
        the frame times (default: the frames' own poses). None without ground truth."""
        from torchratslam.eval.metrics import ate_rmse, interpolate_groundtruth

        traj = self.trajectory(poses)
        gt = self.groundtruth_poses()
        covered = np.ones(traj.shape[0], dtype=bool)
        if groundtruth is not None and traj.shape[0]:
            gt = interpolate_groundtruth(groundtruth, traj[:, 1])
            covered = _inside(groundtruth, traj[:, 1])
        if gt is None:
            return None
        ok = np.isfinite(traj[:, 3]) & covered
        if int(ok.sum()) < MIN_ATE_POSES:
            return None  # an SE(2) alignment of fewer poses says nothing
        return ate_rmse(traj[ok, 3:5], gt[ok, :2])

    def ate_frames(self, poses: np.ndarray, groundtruth: np.ndarray | None = None) -> int:
        """How many frames :meth:`ate` is taken over: those with a map pose and a
        ground-truth pose (inside ``groundtruth``'s time range when given)."""
        traj = self.trajectory(poses)
        if traj.shape[0] == 0:
            return 0
        ok = np.isfinite(traj[:, 3])
        if groundtruth is not None:
            ok &= _inside(groundtruth, traj[:, 1])
        elif self.groundtruth_poses() is None:
            return 0
        return int(ok.sum())

    def dead_reckoning_ate(self, groundtruth: np.ndarray | None = None) -> float | None:
        """ATE (m) of the integrated odometry alone (``groundtruth`` as in :meth:`ate`)."""
        from torchratslam.eval.metrics import ate_rmse, dead_reckoning, interpolate_groundtruth

        odo = self.odometry_log()
        gt = self.groundtruth_poses()
        covered = np.ones(odo.shape[0], dtype=bool)
        if groundtruth is not None and odo.shape[0]:
            gt = interpolate_groundtruth(groundtruth, self.times())
            covered = _inside(groundtruth, self.times())
        if gt is None or int(covered.sum()) < MIN_ATE_POSES:
            return None
        dr = dead_reckoning(odo[:, 0], odo[:, 1], odo[:, 2])
        return ate_rmse(dr[covered, :2], gt[covered, :2])

    # ------------------------------------------------------------------ edits
    def remap_experiences(self, old_to_new: np.ndarray) -> None:
        """Re-point the frames at new experience ids (after a map merge).

        Args:
            old_to_new: ``old_to_new[i]`` is the new id of experience ``i`` (-1: dropped;
                ids beyond its length are kept). Shape: ``(M,)``.
        """
        ids = np.asarray(old_to_new, dtype=np.int64).reshape(-1)
        old = self._col(_EXP).astype(np.int64)
        ok = (old >= 0) & (old < ids.size)
        if not ok.any():  # nothing to re-point (e.g. no experience yet: frame 0 only)
            return
        self._rows[: self._n, _EXP] = np.where(ok, ids[np.where(ok, old, 0)], old)

    def arrays(self) -> dict[str, np.ndarray]:
        """The records as arrays, for saving: ``frames`` ``(F,)`` int64, ``t`` ``(F,)``,
        ``exp`` ``(F,)`` int64, ``gt`` ``(F, 3)`` (NaN rows where ``gt_ok`` ``(F,)`` is
        False), ``odo`` ``(F, 3)``, ``pc`` ``(F, 3)``."""
        return {
            "frames": self._col(_FRAME).astype(np.int64),
            "t": self._col(_T),
            "exp": self._col(_EXP).astype(np.int64),
            "gt": self._col(_GT, _GT + 3),
            "gt_ok": self._col(_GT_OK).astype(bool),
            "odo": self._col(_ODO, _ODO + 3),
            "pc": self._col(_PC, _PC + 3),
        }

    def restore(self, arrays: Mapping[str, np.ndarray]) -> None:
        """Replace the records with :meth:`arrays`' output.

        Raises:
            KeyError: an array is missing.
            ValueError: the arrays have different lengths.
        """
        a = {k: arrays[k] for k in ("frames", "t", "exp", "gt", "gt_ok", "odo", "pc")}
        n = a["frames"].shape[0]
        if any(v.shape[0] != n for v in a.values()):
            raise ValueError("arrays of different lengths")
        rows = np.zeros((max(64, n), _COLUMNS))
        rows[:n, _FRAME] = a["frames"]
        rows[:n, _T] = a["t"]
        rows[:n, _EXP] = a["exp"]
        rows[:n, _GT_OK] = a["gt_ok"]
        rows[:n, _GT : _GT + 3] = np.where(a["gt_ok"][:, None], a["gt"], np.nan)
        rows[:n, _ODO : _ODO + 3] = a["odo"]
        rows[:n, _PC : _PC + 3] = a["pc"]
        self._rows, self._n = rows, n
