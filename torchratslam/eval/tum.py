"""Trajectories in the TUM RGB-D format, for evo and other trajectory tools.

A TUM file has one pose per line, ``timestamp tx ty tz qx qy qz qw`` (seconds, metres,
a unit quaternion), with ``#`` comment lines. RatSLAM is planar: ``tz = qx = qy = 0``
and the heading ``th`` is the rotation about z (``qz = sin(th/2)``, ``qw = cos(th/2)``).
Values are written with Python's ``repr`` (lossless), so a tool reading the file sees
exactly the numbers the project evaluated.

Two estimates are written, each named after what it is:

* **experience** (``tum_experience.txt``): per frame, the final pose of the experience
  current after that frame. This is what OpenRatSLAM publishes (and what
  :meth:`torchratslam.pipeline.RatSLAM.trajectory` returns); it stays on an experience
  until the next one becomes current, so it lags the robot between experiences.
* **frame** (``tum_frame.txt``): per frame, the current experience's final pose
  composed with the odometry accumulated since that experience became current, i.e.
  the pose at which the experience map would place a new experience now (see
  :func:`frame_poses`).

And the ground truth (``tum_groundtruth.txt``) at the same timestamps. Then::

    evo_ape tum tum_groundtruth.txt tum_frame.txt -a

gives the same ATE as :func:`tum_ate` (tested to 1e-6 m), for planar trajectories
whose best 2D alignment is a rotation (evo's SE(3) Umeyama alignment of points in a
plane reduces to the 2D one; it could use a mirror image plus a flip of z when that
fitted better, which no sensible estimate does).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ratslam_graph.atomic import atomic_write_text
from ratslam_graph.geometry import wrap_angle
from ratslam_graph.messages import ActionKind
from torchratslam.errors import InputError, MapFormatError

__all__ = [
    "FramePoseRecorder",
    "frame_poses",
    "read_tum",
    "tum_ate",
    "write_tum",
    "write_tum_files",
]

TUM_HEADER = "# timestamp tx ty tz qx qy qz qw"


def write_tum(path: str | Path, t: np.ndarray, poses: np.ndarray, *, comment: str = "") -> Path:
    """Write planar poses as a TUM trajectory (atomically).

    Rows with a non-finite time or pose are skipped (frames before the first experience).

    Args:
        path: the file to write (replaced).
        t: timestamps (s). Shape: ``(N,)``.
        poses: ``[x, y, th]`` (m, m, rad). Shape: ``(N, 3)``.
        comment: an optional first comment line (without ``#``).

    Returns:
        The path written.

    Raises:
        InputError: shapes do not match.
    """
    tt = np.asarray(t, dtype=np.float64).reshape(-1)
    p = np.asarray(poses, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] < 3 or p.shape[0] != tt.shape[0]:
        raise InputError(
            f"TUM output needs (N,) times and (N, 3) poses, got {tt.shape} and {p.shape}"
        )
    ok = np.isfinite(tt) & np.all(np.isfinite(p[:, :3]), axis=1)
    half = 0.5 * p[ok, 2]
    zero = np.zeros(half.shape)
    rows = np.column_stack(
        [tt[ok], p[ok, 0], p[ok, 1], zero, zero, zero, np.sin(half), np.cos(half)]
    )
    lines = [f"# {comment}"] if comment else []
    lines.append(TUM_HEADER)
    lines += [" ".join(repr(float(v)) for v in row) for row in rows.tolist()]
    path = Path(path)
    try:
        return atomic_write_text(path, "\n".join(lines) + "\n")
    except OSError as exc:  # named by the user's file, not the temporary one beside it
        raise InputError(f"{path}: cannot be written ({exc.strerror or exc})") from None


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM trajectory as planar poses.

    Args:
        path: a TUM file (``timestamp tx ty tz qx qy qz qw`` per line).

    Returns:
        ``(t, poses)``: timestamps ``(N,)`` and ``[x, y, th]`` poses ``(N, 3)``; the
        heading is the yaw of the quaternion.

    Raises:
        MapFormatError: a line without 8 numbers.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: TUM file not found")
    rows = []
    for n, line in enumerate(path.read_text().splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.replace(",", " ").split()
        try:
            vals = [float(v) for v in parts]
        except ValueError:
            vals = []
        if len(vals) != 8:
            raise MapFormatError(f"{path}, line {n}: expected 8 numbers (TUM format), got {s!r}")
        rows.append(vals)
    a = np.asarray(rows, dtype=np.float64).reshape(-1, 8)
    qx, qy, qz, qw = a[:, 4], a[:, 5], a[:, 6], a[:, 7]
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return a[:, 0], np.column_stack([a[:, 1], a[:, 2], yaw])


def _associate(t_ref: np.ndarray, t_est: np.ndarray, max_diff: float) -> tuple[np.ndarray, ...]:
    """Pairs ``(i_ref, i_est)`` of nearest timestamps within ``max_diff`` (s)."""
    if t_ref.size == 0 or t_est.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    order = np.argsort(t_ref, kind="stable")
    tr = t_ref[order]
    j = (
        np.clip(np.searchsorted(tr, t_est), 1, tr.size - 1)
        if tr.size > 1
        else np.zeros_like(t_est, dtype=np.int64)
    )
    if tr.size > 1:
        left = np.abs(t_est - tr[j - 1]) <= np.abs(t_est - tr[j])
        j = np.where(left, j - 1, j)
    keep = np.abs(t_est - tr[j]) <= max_diff
    return order[j[keep]], np.flatnonzero(keep)


TUM_ATE_OVER = "poses matched to ground truth by nearest timestamp within 0.01 s"
"""What a ``--tum`` ATE is taken over (evo's association), beside its alignment."""
TUM_ATE_ALIGNMENT = "rigid, no scale (evo_ape -a)"


def tum_matched(groundtruth: str | Path, estimate: str | Path, *, max_diff: float = 0.01) -> int:
    """How many poses of ``estimate`` have a ground-truth pose within ``max_diff`` seconds:
    the poses :func:`tum_ate` is taken over."""
    t_g, _ = read_tum(groundtruth)
    t_e, _ = read_tum(estimate)
    return int(_associate(t_g, t_e, max_diff)[0].size)


def tum_ate(
    groundtruth: str | Path, estimate: str | Path, *, max_diff: float = 0.01, align: bool = True
) -> float:
    """ATE (m) between two TUM files, as ``evo_ape tum GT EST -a`` computes it.

    Poses are matched by nearest timestamp within ``max_diff`` seconds (evo's default),
    the estimate is aligned onto the ground truth by the least-squares rigid motion (no
    scale), and the RMSE of the position differences is returned.

    Args:
        groundtruth: the reference TUM file.
        estimate: the estimated TUM file.
        max_diff: largest timestamp difference of a matched pair (s).
        align: align first (evo's ``-a``).

    Raises:
        InputError: fewer than 2 matched poses.
    """
    from torchratslam.eval.metrics import ate_rmse

    t_g, g = read_tum(groundtruth)
    t_e, e = read_tum(estimate)
    i_g, i_e = _associate(t_g, t_e, max_diff)
    if i_g.size < 2:
        raise InputError(
            f"{estimate}: only {i_g.size} poses match {groundtruth} within {max_diff} s; "
            "are the timestamps in the same clock?"
        )
    return ate_rmse(e[i_e], g[i_g], align=align)


def frame_poses(
    trajectory: np.ndarray,
    odometry: np.ndarray,
    reset: np.ndarray,
    relative_rad: np.ndarray,
) -> np.ndarray:
    """Per-frame poses: the current experience composed with the odometry since it.

    The experience map restarts its accumulators whenever another experience becomes
    current (``reset``): position delta 0, heading the experience's plus the view's
    relative angle (``relative_rad``; 0 for a created experience). Each later frame
    turns by ``vrot*dt`` then steps ``vtrans*dt`` along the new heading, exactly as
    :meth:`ratslam_graph.experience_map.ExperienceMap.on_odometry`. The delta is
    expressed in the experience's frame and composed with the experience's final pose,
    so loop-closure corrections carry over to the frames around it.

    Args:
        trajectory: :meth:`RatSLAM.trajectory` rows ``[frame, t, experience_id, x, y,
            th]``. Shape: ``(F, 6)``.
        odometry: :meth:`RatSLAM.odometry_log` rows ``(vtrans, vrot, dt)``. Shape: ``(F, 3)``.
        reset: whether another experience became current at that frame. Shape: ``(F,)``.
        relative_rad: the heading offset at a reset (rad). Shape: ``(F,)``.

    Returns:
        ``[x, y, th]`` per frame (NaN before the first experience). Shape: ``(F, 3)``.

    Raises:
        InputError: lengths differ.
    """
    traj = np.asarray(trajectory, dtype=np.float64).reshape(-1, 6)
    odo = np.asarray(odometry, dtype=np.float64).reshape(-1, 3)
    rs = np.asarray(reset, dtype=bool).reshape(-1)
    rel = np.asarray(relative_rad, dtype=np.float64).reshape(-1)
    n = traj.shape[0]
    if not (odo.shape[0] == rs.shape[0] == rel.shape[0] == n):
        raise InputError(
            f"per-frame poses need one row per frame: trajectory {n}, odometry "
            f"{odo.shape[0]}, resets {rs.shape[0]}, relative angles {rel.shape[0]}"
        )
    if n == 0:
        return np.zeros((0, 3))
    rs = rs.copy()
    rs[0] = True
    # segment start of every frame (the last reset at or before it)
    start = np.maximum.accumulate(np.where(rs, np.arange(n), 0))
    turn = odo[:, 1] * odo[:, 2]
    turn[rs] = 0.0  # a reset frame's odometry went into the previous experience
    cum_turn = np.cumsum(turn)
    heading = rel[start] + cum_turn - cum_turn[start]
    step = odo[:, 0] * odo[:, 2]
    step[rs] = 0.0
    dx, dy = step * np.cos(heading), step * np.sin(heading)
    cx, cy = np.cumsum(dx), np.cumsum(dy)
    lx, ly = cx - cx[start], cy - cy[start]
    ex, ey, eth = traj[:, 3], traj[:, 4], traj[:, 5]
    c, s = np.cos(eth), np.sin(eth)
    out = np.column_stack([ex + c * lx - s * ly, ey + s * lx + c * ly, eth + heading])
    out[:, 2] = wrap_angle(out[:, 2], include_pi=True)
    return out


class FramePoseRecorder:
    """Records, per step, what :func:`frame_poses` needs (pass it as ``run(callback=)``).

    Uses only the public :class:`~torchratslam.pipeline.StepResult`: the experience
    current after the step and the action (its kind and relative angle).

    Example:
        >>> rec = FramePoseRecorder()  # doctest: +SKIP
        >>> slam.run(data, callback=rec)  # doctest: +SKIP
        >>> poses = rec.poses(slam)  # doctest: +SKIP
    """

    def __init__(self) -> None:
        self.reset: list[bool] = []
        self.relative_rad: list[float] = []
        self._last = -1

    def __call__(self, step: Any) -> None:
        exp = int(step.experience_id)
        changed = exp != self._last
        action = step.action
        rel = 0.0
        if changed and ActionKind(action.kind) != ActionKind.CREATE:
            rel = float(action.relative_rad)
        self.reset.append(changed)
        self.relative_rad.append(rel)
        self._last = exp

    def poses(self, slam: Any) -> np.ndarray:
        """Per-frame poses of ``slam``'s recorded frames (see :func:`frame_poses`).

        Shape:
            returns ``(F, 3)``.
        """
        traj = slam.trajectory()
        odo = slam.odometry_log()
        n = traj.shape[0]
        if len(self.reset) < n:
            raise InputError(
                f"the recorder saw {len(self.reset)} frames but the run has {n}; pass it as "
                "run(callback=...) from the first frame"
            )
        k = len(self.reset) - n  # the run's history may have been reset since
        return frame_poses(traj, odo, np.asarray(self.reset[k:]), np.asarray(self.relative_rad[k:]))


def write_tum_files(
    slam: Any,
    out: str | Path,
    *,
    recorder: FramePoseRecorder | None = None,
    groundtruth: np.ndarray | None = None,
) -> dict[str, Path]:
    """Write ``tum_experience.txt``, ``tum_frame.txt`` (with a recorder) and
    ``tum_groundtruth.txt`` (when known) for a finished run.

    Args:
        slam: the :class:`~torchratslam.pipeline.RatSLAM` after its run.
        out: the directory (created).
        recorder: the :class:`FramePoseRecorder` passed to the run (for the per-frame
            estimate); None writes the experience estimate only.
        groundtruth: ``(T, 4)`` rows ``[t, x, y, theta]`` to interpolate at the frame
            times when the frames carried no poses themselves.

    Returns:
        ``{"experience": path, "frame": path, "groundtruth": path}`` for the files written.
    """
    from torchratslam.eval.metrics import interpolate_groundtruth

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    traj = slam.trajectory()
    t = traj[:, 1]
    files = {
        "experience": write_tum(
            out / "tum_experience.txt",
            t,
            traj[:, 3:6],
            comment="RatSLAM: the current experience's pose after each frame",
        )
    }
    if recorder is not None:
        files["frame"] = write_tum(
            out / "tum_frame.txt",
            t,
            recorder.poses(slam),
            comment="RatSLAM: current experience composed with the odometry since it",
        )
    gt = slam.groundtruth_poses()
    if gt is None and groundtruth is not None and len(groundtruth) and t.size:
        gt = interpolate_groundtruth(groundtruth, t)
    if gt is not None:
        files["groundtruth"] = write_tum(
            out / "tum_groundtruth.txt", t, gt, comment="ground truth at the frame times"
        )
    return files
