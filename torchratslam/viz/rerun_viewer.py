"""A live view of a run with `rerun <https://rerun.io>`_ (optional extra ``viewer``).

:class:`RerunObserver` is a callback of :meth:`torchratslam.pipeline.RatSLAM.run`: it
reads the public per-step :class:`~torchratslam.pipeline.StepResult` and the modules'
public state, and logs, on the ``frame`` timeline (and ``time``, the frame's timestamp):

==============================  ========================================================
entity                          what
==============================  ========================================================
``camera/image``                the camera image (needs :meth:`RerunObserver.frames`)
``local_view/template``         the matched (or new) template
``local_view/offset``           the match's column offset (time series)
``local_view/error``            the match's error (time series)
``pose_cells/activity``         3D points: cells above ``activity_fraction`` of the
                                peak, at ``(x, y, th)`` in cells, coloured by activity
``pose_cells/centre``           the packet centre
``map/experiences``             the experience map (2D points, m)
``map/links``                   its links
``map/current``                 the current experience
``map/trajectory``              the current experience's pose over time
``map/groundtruth``             ground truth, rigidly aligned onto the trajectory
``map/merges``                  where the map merged with a stored map (multisession)
``events``                      a text log of merges
``timings/<module>``            per-module ms per frame (time series)
==============================  ========================================================

Nothing runs when the viewer is off: the pipeline is untouched and ``rerun`` is only
imported when an observer is built. With ``pipelined=True`` the pose-cell activity and
map shown may be a frame or a few ahead of the frame logged (the workers run ahead).

Example:
    >>> obs = RerunObserver(slam, save="run.rrd")  # doctest: +SKIP
    >>> slam.run(obs.frames(data), callback=obs)  # doctest: +SKIP
    >>> obs.close()  # doctest: +SKIP
"""

from __future__ import annotations

import collections
import logging
import math
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from torchratslam.errors import ConfigError

__all__ = ["ENTITIES", "RerunObserver", "import_rerun"]

log = logging.getLogger(__name__)

ENTITIES = (
    "camera/image",
    "local_view/template",
    "local_view/offset",
    "local_view/error",
    "pose_cells/activity",
    "pose_cells/centre",
    "map/experiences",
    "map/links",
    "map/current",
    "map/trajectory",
    "map/groundtruth",
    "map/merges",
    "events",
    "timings",
)
"""The entity paths (``timings`` holds one child per module)."""


def import_rerun() -> Any:
    """Import ``rerun`` (the ``rerun-sdk`` package) or fail with one clear line.

    Raises:
        ConfigError: rerun-sdk is not installed.
    """
    try:
        import rerun
    except ImportError:
        raise ConfigError(
            "the rerun viewer needs the optional extra: pip install 'torchratslam[viewer]' "
            "(or pip install rerun-sdk)"
        ) from None
    return rerun


def _to_uint8(a: Any) -> np.ndarray:
    """An image or template as uint8 for display (floats are scaled min..max)."""
    if hasattr(a, "detach"):
        a = a.detach().cpu().numpy()
    x = np.asarray(a)
    if x.dtype == np.uint8:
        return x
    x = x.astype(np.float64)
    lo, hi = float(np.nanmin(x)) if x.size else 0.0, float(np.nanmax(x)) if x.size else 1.0
    return np.clip((x - lo) / (hi - lo if hi > lo else 1.0) * 255.0, 0, 255).astype(np.uint8)


class RerunObserver:
    """Logs a run to rerun, one frame per :class:`~torchratslam.pipeline.StepResult`.

    Args:
        slam: the :class:`~torchratslam.pipeline.RatSLAM` (or a multisession one) whose
            run is observed; None: give it later with :meth:`attach`.
        spawn: start a rerun viewer and stream to it.
        save: write the recording to this ``.rrd`` file (with ``spawn`` as well: the
            viewer and the file both get everything).
        application_id: the recording's application id.
        recording: an existing ``rerun.RecordingStream`` to log into (then ``spawn``
            and ``save`` are ignored).
        map_every: log the experience map, trajectory and ground truth every this many
            frames (and at the last one, see :meth:`close`); 1 logs every frame.
        activity_fraction: pose cells whose activity exceeds this fraction of the peak
            are drawn.
        max_cells: at most this many (the most active) cells are drawn.
        session: a name logged with merges (multisession).

    Raises:
        ConfigError: rerun-sdk is not installed.
    """

    def __init__(
        self,
        slam: Any,
        *,
        spawn: bool = False,
        save: str | Path | None = None,
        application_id: str = "torchratslam",
        recording: Any = None,
        map_every: int = 1,
        activity_fraction: float = 0.2,
        max_cells: int = 4000,
        session: str = "",
    ) -> None:
        self.rr = import_rerun()
        if map_every < 1:
            raise ConfigError(f"map_every must be >= 1, got {map_every}")
        self.slam = slam
        self.map_every = int(map_every)
        self.activity_fraction = float(activity_fraction)
        self.max_cells = int(max_cells)
        self.session = session
        if recording is None:
            recording = self.rr.RecordingStream(application_id)
            if save is not None and spawn:
                recording.spawn(connect=False)
                recording.set_sinks(self.rr.GrpcSink(), self.rr.FileSink(str(save)))
            elif save is not None:
                recording.save(str(save))
            elif spawn:
                recording.spawn()
        self.rec = recording
        self._pending: collections.deque = collections.deque()
        self._traj: list[tuple[float, float]] = []
        self._gt: list[tuple[float, float] | None] = []
        self._merge_xy: list[tuple[float, float]] = []
        self._merge_labels: list[str] = []
        self._n = 0
        self._offset = 0
        self._last_step: Any = None
        if slam is not None:
            self._start(slam)

    def _start(self, slam: Any) -> None:
        self.slam = slam
        self._merges_seen = len(getattr(slam, "merges", ()) or ())
        self._timing0 = {m: slam.timings.count(m) for m in slam.timings.modules}
        self._frame0 = int(getattr(slam, "frame_index", 0))

    # ------------------------------------------------------------------ inputs
    def frames(self, data: Any) -> Any:
        """``data`` (a reader or an iterable of frames) with its frames passed through
        unchanged; each frame's image and ground truth are kept for its step's log.
        The result has ``frames()`` and, when ``data`` has one, ``len()``."""
        observed = _Observed(data, self._pending)
        return observed if hasattr(data, "__len__") else observed.frames()

    def attach(self, slam: Any, session: str = "") -> None:
        """Observe another run (the next session of a multisession mapping) on the same
        recording: its frames continue the ``frame`` timeline after the previous run's."""
        self.close(flush=False)
        self._offset += self._n
        self.session = session
        self._pending.clear()
        self._traj.clear()
        self._gt.clear()
        self._n = 0
        self._start(slam)
        if session:
            self.rec.set_time("frame", sequence=self._offset)
            self.rec.log("events", self.rr.TextLog(f"session {session} starts", level="INFO"))

    # ------------------------------------------------------------------ per step
    def __call__(self, step: Any) -> None:
        """Log one step (pass the observer as ``run(callback=...)``)."""
        rr, rec = self.rr, self.rec
        rec.set_time("frame", sequence=self._offset + int(step.frame) - self._frame0)
        rec.set_time("time", duration=float(step.t))
        image, pose = self._pending.popleft() if self._pending else (None, None)
        if image is not None:
            img = np.asarray(image)
            if img.ndim == 3 and img.shape[2] == 3:
                img = img[:, :, ::-1]  # BGR -> RGB
            rec.log("camera/image", rr.Image(_to_uint8(img)))
        view = step.view
        templates = getattr(self.slam, "templates", None)
        tid = int(view.template_id)
        if templates is not None and 0 <= tid < len(templates):
            rec.log("local_view/template", rr.Image(_to_uint8(templates[tid])))
        rec.log("local_view/offset", rr.Scalars(float(view.offset)))
        if math.isfinite(float(view.error)):
            rec.log("local_view/error", rr.Scalars(float(view.error)))
        self._log_pose_cells(step)
        em = self.slam.experience_map
        poses = np.asarray(em.poses, dtype=np.float64).reshape(-1, 3)
        cur = int(step.experience_id)
        if 0 <= cur < poses.shape[0]:
            self._traj.append((float(poses[cur, 0]), float(poses[cur, 1])))
        else:
            self._traj.append((math.nan, math.nan))
        self._gt.append(None if pose is None else (float(pose[0]), float(pose[1])))
        self._log_merges(poses, cur, step)
        if self._n % self.map_every == 0:
            self._log_map(poses, cur)
        self._log_timings()
        self._n += 1
        self._last_step = step

    def _log_pose_cells(self, step: Any) -> None:
        rr, rec = self.rr, self.rec
        act = getattr(self.slam, "activity", None)
        if act is not None:
            a = act.detach().cpu().numpy() if hasattr(act, "detach") else np.asarray(act)
            peak = float(a.max()) if a.size else 0.0
            if peak > 0:
                idx = np.flatnonzero(a.reshape(-1) > self.activity_fraction * peak)
                vals = a.reshape(-1)[idx]
                if idx.size > self.max_cells:
                    keep = np.argpartition(vals, -self.max_cells)[-self.max_cells :]
                    idx, vals = idx[keep], vals[keep]
                th, y, x = np.unravel_index(idx, a.shape)
                level = np.clip(vals / peak, 0.0, 1.0)
                colours = np.stack(
                    [255 * level, 80 + 100 * (1 - level), 255 * (1 - level)], axis=1
                ).astype(np.uint8)
                rec.log(
                    "pose_cells/activity",
                    rr.Points3D(np.stack([x, y, th], axis=1), colors=colours, radii=0.3),
                )
        rec.log(
            "pose_cells/centre",
            rr.Points3D([list(step.pc)], colors=[[255, 255, 0]], radii=0.6, labels=["centre"]),
        )

    def _log_merges(self, poses: np.ndarray, cur: int, step: Any) -> None:
        merges = getattr(self.slam, "merges", None)
        if not merges or len(merges) <= self._merges_seen:
            return
        rr, rec = self.rr, self.rec
        for rec_m in merges[self._merges_seen :]:
            where = poses[cur, :2] if 0 <= cur < poses.shape[0] else np.zeros(2)
            label = f"merge with map {rec_m.get('map', '?')} at frame {step.frame}"
            self._merge_xy.append((float(where[0]), float(where[1])))
            self._merge_labels.append(label)
            rec.log("events", rr.TextLog(f"{self.session} {label}".strip(), level="INFO"))
        self._merges_seen = len(merges)
        rec.log(
            "map/merges",
            rr.Points2D(
                self._merge_xy, labels=self._merge_labels, colors=[[255, 0, 255]], radii=0.3
            ),
        )

    def _log_map(self, poses: np.ndarray, cur: int) -> None:
        rr, rec = self.rr, self.rec
        rec.log("map/experiences", rr.Points2D(poses[:, :2], radii=0.05, colors=[[90, 90, 90]]))
        links = self.slam.experience_map.links()
        seg = np.stack([poses[links["src"], :2], poses[links["dst"], :2]], axis=1)
        rec.log("map/links", rr.LineStrips2D(seg, colors=[[150, 150, 150]], radii=0.02))
        if 0 <= cur < poses.shape[0]:
            rec.log(
                "map/current",
                rr.Points2D([poses[cur, :2]], colors=[[255, 60, 0]], radii=0.15, labels=["now"]),
            )
        traj = np.asarray(self._traj, dtype=np.float64)
        ok = np.all(np.isfinite(traj), axis=1)
        rec.log("map/trajectory", rr.LineStrips2D([traj[ok]], colors=[[0, 120, 255]], radii=0.03))
        has_gt = np.array([g is not None for g in self._gt])
        both = ok & has_gt
        if both.sum() >= 2:
            from torchratslam.eval.metrics import align_se2

            gt = np.asarray([g if g is not None else (math.nan, math.nan) for g in self._gt])
            moved = align_se2(gt[both], traj[both]).apply(gt[has_gt])
            rec.log("map/groundtruth", rr.LineStrips2D([moved], colors=[[0, 170, 0]], radii=0.03))

    def _log_timings(self) -> None:
        rr, rec = self.rr, self.rec
        timings = self.slam.timings
        for m in timings.modules:
            v = timings.ms_at(m, self._timing0.get(m, 0) + self._n)
            if math.isfinite(v):
                rec.log(f"timings/{m}", rr.Scalars(v))

    # ------------------------------------------------------------------ end
    def close(self, *, flush: bool = True) -> None:
        """Log the final map (relaxed, every experience) and flush the recording."""
        if self._last_step is not None and (self._n - 1) % self.map_every != 0:
            poses = np.asarray(self.slam.experience_map.poses, dtype=np.float64).reshape(-1, 3)
            self._log_map(poses, int(self._last_step.experience_id))
        self._last_step = None
        if flush:
            self.rec.flush()
            if hasattr(self.rec, "disconnect"):
                self.rec.disconnect()


class _Observed:
    """A dataset whose frames are remembered (image, ground truth) on the way through."""

    def __init__(self, data: Any, pending: collections.deque) -> None:
        self.data, self._pending = data, pending

    def frames(self) -> Iterator[Any]:
        it: Iterable[Any] = self.data.frames() if hasattr(self.data, "frames") else self.data
        for frame in it:
            self._pending.append((frame.image, frame.pose))
            yield frame

    def __iter__(self) -> Iterator[Any]:
        return self.frames()

    def __len__(self) -> int:
        return len(self.data)
