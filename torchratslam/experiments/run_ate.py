"""Why a run's ATE is what it is: the per-frame pose's ATE beside the map's, and a note
when the map's ATE is above dead reckoning's.

A run's ATE (``ate_rmse_m``) compares the experience current after each frame with the
ground truth at the frame's time: a place of the map, up to one experience spacing from
where the robot is. Dead reckoning integrates every frame's odometry, so on a short
session that closes no loop (nothing for the map to correct) the map's ATE is above
dead reckoning's by about the spacing, and the per-frame pose (the experience plus the
odometry since it, what ``--tum`` writes as ``tum_frame.txt``) comes back to dead
reckoning's. :func:`ate_note` says this, with the run's own figures.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from torchratslam.protocols import GroundTruthSource

__all__ = ["EXPLAINED", "ate_note", "frame_pose_ate", "loop_closures", "mean_link_length"]

EXPLAINED = 1.1
""":func:`ate_note`: a per-frame pose ATE within this factor of dead reckoning's means the
place offset explains the map's higher ATE."""


def frame_pose_ate(slam: Any, data: Any, frame_poses: np.ndarray | None) -> float | None:
    """The ATE (m, SE(2)-aligned) of every frame's pose estimate (the experience current
    after it plus the odometry since), over the frames with ground truth; None without
    the poses (a resumed run) or under 3 frames with ground truth."""
    from torchratslam.eval.metrics import MIN_ATE_POSES, ate_at_times, ate_rmse

    traj = slam.trajectory()
    if frame_poses is None or frame_poses.shape[0] != traj.shape[0] or not traj.shape[0]:
        return None
    est = np.asarray(frame_poses, np.float64)[:, :2]
    own = slam.groundtruth_poses()
    if own is not None:
        truth = np.asarray(own, np.float64)[:, :2]
        ok = np.isfinite(est).all(axis=1) & np.isfinite(truth).all(axis=1)
        if int(ok.sum()) < MIN_ATE_POSES:
            return None
        return float(ate_rmse(est[ok], truth[ok]))
    table = data.groundtruth() if isinstance(data, GroundTruthSource) else None
    if table is None or not len(table):
        return None
    return ate_at_times(est, traj[:, 1], table)[0]


def _link_pairs(em: Any) -> np.ndarray:
    if hasattr(em, "links") and callable(em.links):
        lk = em.links()
        return np.stack([lk["src"], lk["dst"]], axis=1).astype(np.int64).reshape(-1, 2)
    return np.asarray(list(em.graph.edges()), dtype=np.int64).reshape(-1, 2)


def mean_link_length(slam: Any) -> float | None:
    """The mean distance (m) between the experiences a link joins (the map's spacing of
    places); None without links."""
    em = slam.experience_map
    pairs = _link_pairs(em)
    if not pairs.shape[0]:
        return None
    p = np.asarray(em.poses, np.float64).reshape(-1, 3)
    return float(np.mean(np.hypot(*(p[pairs[:, 1], :2] - p[pairs[:, 0], :2]).T)))


def loop_closures(slam: Any) -> int:
    """Links that join an experience to one made earlier than its predecessor (a place
    seen again), i.e. links between experiences whose ids are not consecutive."""
    pairs = _link_pairs(slam.experience_map)
    return int(np.sum(np.abs(pairs[:, 1] - pairs[:, 0]) != 1)) if pairs.shape[0] else 0


def ate_note(
    ate: float | None,
    dr: float | None,
    frame_ate: float | None,
    spacing: float | None,
    closures: int,
) -> str | None:
    """Why the map's ATE is above dead reckoning's, measured; None when it is not.

    The place offset explains the gap when the per-frame pose's ATE comes back to within
    :data:`EXPLAINED` of dead reckoning's; when it does not, the map's corrections moved
    the poses off the odometry, and the note says that instead."""
    if ate is None or dr is None or not (np.isfinite(ate) and np.isfinite(dr)) or ate <= dr:
        return None
    head = f"the map's ATE ({ate:.3f} m) is above dead reckoning's ({dr:.3f} m)"
    place = (
        "it compares the experience current after each frame, a place of the map up to "
        "one experience spacing from the robot"
    )
    if spacing is not None:
        place += f" (here {spacing:.2f} m between linked experiences on average)"
    loops = (
        "no loop was closed, so the map had no odometry drift to correct"
        if closures == 0
        else f"{closures} loop-closing link{'s' if closures != 1 else ''}"
    )
    if frame_ate is None:  # a resumed run: the per-frame poses were not all recorded
        return f"{head}; {place}; {loops}"
    if frame_ate <= dr * EXPLAINED:
        return (
            f"{head} because {place}; the per-frame pose (that experience plus the "
            f"odometry since it) gives {frame_ate:.3f} m; {loops}"
        )
    return (
        f"{head}, and so is the per-frame pose's (that experience plus the odometry since "
        f"it: {frame_ate:.3f} m): the map's corrections moved the poses off the odometry "
        f"({loops}); look at map.png for places joined wrongly"
    )
