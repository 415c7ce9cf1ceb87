"""The per-frame record of a run (:class:`History`) and what is read from it: the
trajectory through the experience map, the ATE against ground truth, the dead-reckoning
baseline and the pose-cell centres."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

__all__ = ["History"]


class History:
    """One row per processed frame: frame index, time, current experience, ground-truth
    pose (None when the frame had none), odometry ``(vtrans, vrot, dt)`` and pose-cell
    packet centre ``(x, y, th)`` in cells.

    Example:
        >>> h = History()
        >>> h.append(0, 0.0, -1, None, (0.0, 0.0, 0.0), (1.0, 2.0, 3.0))
        >>> h.append(1, 0.5, 0, (0.1, 0.0, 0.0), (0.2, 0.0, 0.5), (1.0, 2.0, 3.0))
        >>> h.trajectory(np.array([[4.0, 5.0, 0.0]]))[:, 2:4].tolist()
        [[-1.0, nan], [0.0, 4.0]]
    """

    def __init__(self) -> None:
        self._frames: list[int] = []
        self._t: list[float] = []
        self._exp: list[int] = []
        self._gt: list[tuple[float, ...] | None] = []
        self._odo: list[tuple[float, float, float]] = []
        self._pc: list[tuple[float, float, float]] = []

    def __len__(self) -> int:
        return len(self._frames)

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
        self._frames.append(frame)
        self._t.append(float(t))
        self._exp.append(experience_id)
        self._gt.append(None if pose is None else tuple(float(v) for v in pose))
        self._odo.append(odometry)
        self._pc.append(pc)

    def clear(self) -> None:
        """Forget every frame."""
        for rows in (self._frames, self._t, self._exp, self._gt, self._odo, self._pc):
            rows.clear()

    # ------------------------------------------------------------------ outputs
    def times(self) -> np.ndarray:
        """The frames' time stamps (s). Shape: ``(F,)`` float64."""
        return np.asarray(self._t)

    def trajectory(self, poses: np.ndarray) -> np.ndarray:
        """Per frame: ``[frame, t, experience_id, x, y, th]`` with the experience's pose
        from ``poses`` (NaN where the frame had no experience).

        Shape:
            poses: ``(N, 3)``, row = experience id; returns ``(F, 6)`` float64.
        """
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        exp = np.asarray(self._exp, dtype=np.int64)
        out = np.full((exp.shape[0], 6), np.nan)
        out[:, 0] = self._frames
        out[:, 1] = self._t
        out[:, 2] = exp
        ok = (exp >= 0) & (exp < poses.shape[0])
        out[ok, 3:] = poses[exp[ok]]
        return out

    def groundtruth_poses(self) -> np.ndarray | None:
        """The frames' ground-truth poses ``(F, 3)``, or None if any frame had none."""
        if not self._gt or any(p is None for p in self._gt):
            return None
        return np.asarray(self._gt, dtype=np.float64)

    def odometry_log(self) -> np.ndarray:
        """The ``(vtrans, vrot, dt)`` used for each frame. Shape: ``(F, 3)``."""
        return np.asarray(self._odo, dtype=np.float64).reshape(-1, 3)

    def pc_log(self) -> np.ndarray:
        """The pose-cell packet centre ``(x, y, th)`` in cells after each frame.

        Shape:
            returns ``(F, 3)``.
        """
        return np.asarray(self._pc, dtype=np.float64).reshape(-1, 3)

    def ate(self, poses: np.ndarray, groundtruth: np.ndarray | None = None) -> float | None:
        """ATE (m) of :meth:`trajectory` (``poses``: the experiences') after SE(2)
        alignment; ``groundtruth``: ``(T, 4)`` rows ``[t, x, y, theta]`` interpolated at
        the frame times (default: the frames' own poses). None without ground truth."""
        from torchratslam.eval.metrics import ate_rmse, interpolate_groundtruth

        traj = self.trajectory(poses)
        if traj.shape[0] < 2:
            return None
        gt = self.groundtruth_poses()
        if groundtruth is not None:
            gt = interpolate_groundtruth(groundtruth, traj[:, 1])
        if gt is None:
            return None
        ok = np.isfinite(traj[:, 3])
        return ate_rmse(traj[ok, 3:5], gt[ok, :2])

    def dead_reckoning_ate(self, groundtruth: np.ndarray | None = None) -> float | None:
        """ATE (m) of the integrated odometry alone (``groundtruth`` as in :meth:`ate`)."""
        from torchratslam.eval.metrics import ate_rmse, dead_reckoning, interpolate_groundtruth

        odo = self.odometry_log()
        if odo.shape[0] < 2:
            return None
        gt = self.groundtruth_poses()
        if groundtruth is not None:
            gt = interpolate_groundtruth(groundtruth, self.times())
        if gt is None:
            return None
        dr = dead_reckoning(odo[:, 0], odo[:, 1], odo[:, 2])
        return ate_rmse(dr[:, :2], gt[:, :2])

    # ------------------------------------------------------------------ edits
    def remap_experiences(self, old_to_new: np.ndarray) -> None:
        """Re-point the frames at new experience ids (after a map merge).

        Args:
            old_to_new: ``old_to_new[i]`` is the new id of experience ``i`` (-1: dropped;
                ids beyond its length are kept). Shape: ``(M,)``.
        """
        ids = np.asarray(old_to_new, dtype=np.int64).reshape(-1)
        old = np.asarray(self._exp, dtype=np.int64)
        ok = (old >= 0) & (old < ids.size)
        if not ok.any():  # nothing to re-point (e.g. no experience yet: frame 0 only)
            return
        new = np.where(ok, ids[np.where(ok, old, 0)], old)
        self._exp[:] = [int(v) for v in new]

    def arrays(self) -> dict[str, np.ndarray]:
        """The records as arrays, for saving: ``frames`` ``(F,)`` int64, ``t`` ``(F,)``,
        ``exp`` ``(F,)`` int64, ``gt`` ``(F, 3)`` (NaN rows where ``gt_ok`` ``(F,)`` is
        False), ``odo`` ``(F, 3)``, ``pc`` ``(F, 3)``."""
        gt = np.asarray(
            [(np.nan, np.nan, np.nan) if p is None else p for p in self._gt], np.float64
        ).reshape(-1, 3)
        return {
            "frames": np.asarray(self._frames, np.int64),
            "t": np.asarray(self._t, np.float64),
            "exp": np.asarray(self._exp, np.int64),
            "gt": gt,
            "gt_ok": np.asarray([p is not None for p in self._gt], bool),
            "odo": np.asarray(self._odo, np.float64).reshape(-1, 3),
            "pc": np.asarray(self._pc, np.float64).reshape(-1, 3),
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
        self._frames[:] = [int(v) for v in a["frames"]]
        self._t[:] = [float(v) for v in a["t"]]
        self._exp[:] = [int(v) for v in a["exp"]]
        self._gt[:] = [
            tuple(float(x) for x in g) if ok else None
            for g, ok in zip(a["gt"], a["gt_ok"], strict=True)
        ]
        self._odo[:] = [_triple(o) for o in a["odo"]]
        self._pc[:] = [_triple(c) for c in a["pc"]]


def _triple(row: np.ndarray) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in row)
    return x, y, z
