"""The options of a dataset run (:func:`torchratslam.experiments.run_dataset.run_dataset`).

:class:`RunOptions` is what a run records in OUT/run.json (a resumed run takes them from
there); :class:`RunSettings` is how this process runs it (device, threads, progress,
checkpoints), never recorded.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["RunOptions", "RunSettings"]


@dataclass(frozen=True)
class RunOptions:
    """What to map and how; recorded in OUT/run.json (field order is the record's key order).

    Attributes:
        config: a config path or shipped name.
        data: a directory, a video, a ROS bag or ``sim:NAME[/session]``.
        overrides: flat config keys.
        max_frames: stop after this many frames.
        odometry: an odometry CSV for a video (or replacing a directory's).
        groundtruth: a ground-truth CSV for a video (or replacing a directory's).
        visual_odometry: estimate odometry from the images even when the data has some.
        load: stored maps to localise in and merge with.
        pipelined: one worker thread per module.
        image_topic: a bag's image topic (default from the config).
        odom_topic: a bag's odometry topic (default from the config).
        max_speed: odometry rows faster than this (m/s) are an error (default
            :mod:`torchratslam.readers.limits`).
        max_turn_rate: odometry rows turning faster than this (rad/s) are an error.
        tum: also write TUM trajectories for evo (``tum_experience.txt``,
            ``tum_frame.txt``, ``tum_groundtruth.txt``; :mod:`torchratslam.eval.tum`)
            and the ATE of each estimate on them.
        rerun: watch the run live in a rerun viewer
            (:class:`torchratslam.viz.rerun_viewer.RerunObserver`; extra ``viewer``).
        rerun_save: record the run for rerun into this ``.rrd`` file.
    """

    config: str
    data: str
    overrides: Mapping[str, str] = field(default_factory=dict)
    max_frames: int | None = None
    odometry: str | None = None
    groundtruth: str | None = None
    visual_odometry: bool = False
    load: tuple[str, ...] = ()
    pipelined: bool = False
    image_topic: str | None = None
    odom_topic: str | None = None
    max_speed: float | None = None
    max_turn_rate: float | None = None
    tum: bool = False
    rerun: bool = False
    rerun_save: str | None = None

    @classmethod
    def from_record(cls, options: Mapping[str, Any]) -> RunOptions:
        """The options of a run.json record (keys it lacks take their defaults)."""
        return cls(
            config=options["config"],
            data=options["data"],
            overrides=dict(options.get("overrides") or {}),
            max_frames=options.get("max_frames"),
            odometry=options.get("odometry"),
            groundtruth=options.get("groundtruth"),
            visual_odometry=bool(options.get("visual_odometry", False)),
            load=tuple(options.get("load") or ()),
            pipelined=bool(options.get("pipelined", False)),
            image_topic=options.get("image_topic"),
            odom_topic=options.get("odom_topic"),
            max_speed=options.get("max_speed"),
            max_turn_rate=options.get("max_turn_rate"),
            tum=bool(options.get("tum", False)),
            rerun=bool(options.get("rerun", False)),
            rerun_save=options.get("rerun_save"),
        )


@dataclass(frozen=True)
class RunSettings:
    """How this process runs (not recorded: a resumed run may choose them anew).

    Attributes:
        device: the torch device of the local view and pose cells (None: the default).
        progress: a progress bar.
        threads: torch intra-op threads.
        scale_report: record the cost per frame as the map grows (OUT/scale.json,
            scale.md, scale.png; :mod:`torchratslam.eval.scale`).
        checkpoint_every: save a loadable partial map in OUT/state every this many frames
            (None: every ``run_dataset.DEFAULT_CHECKPOINT_EVERY`` frames in the
            sequential mode; 0: never).
        overwrite: start a new run in an OUT that holds a stopped one (otherwise
            refused); only torchratslam's own files are replaced.
    """

    device: str | None = None
    progress: bool = True
    threads: int = 1
    scale_report: bool = False
    checkpoint_every: int | None = None
    overwrite: bool = False
