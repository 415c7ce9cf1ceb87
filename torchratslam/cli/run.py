"""``torchratslam run``: map a dataset and write the map, metrics, figures and state."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from torchratslam.errors import ConfigError, InputError
from torchratslam.readers.limits import MAX_SPEED, MAX_TURN_RATE

DESCRIPTION = """Run RatSLAM on a dataset.

OUT receives: metrics.json (frames, templates, experiences, links, wall_s, per-module
mean/median ms per frame, ate_rmse_m when there is ground truth), experiences.csv
(id,x,y,th,created_frame; final poses), trajectory.csv (frame,t,experience_id,x,y,th:
the experience current after each frame, with its final pose), map.png,
pose_cells.png and the saved map state in OUT/state (load it with --load or
torchratslam.maps.native.load_state).

Everything that can be checked is checked before the first frame (OUT, the data's
counts, the device, the config's limits). One run writes to an OUT at a time (a lock).
A checkpoint (a loadable partial map in OUT/state) is saved every 1000 frames
(--checkpoint-every). When the run stops early (Ctrl-C, a bad frame, any error after
frame N), the map as of frame N is saved in OUT/state, marked partial (metrics.json
"partial": true, "stopped_at_frame": N), and the command exits non-zero; `run --resume
OUT` continues it (a run killed without a word, from its last checkpoint) and ends with
the map an uninterrupted run makes, bit for bit (a --load run keeps copies of its
loaded maps in OUT/loaded until it finishes, so the originals may move meanwhile). A
new run refuses an OUT that holds a stopped run (continue it with --resume, or start
again with --overwrite). torchratslam replaces only the files it wrote in OUT, never
others."""

EPILOG = """examples:
  torchratslam run --config configs/virtual_tour.yaml --data sim:virtual_tour --out out/vt
  torchratslam run --config irat --data irat_aus_28112011.bag --out out/irat --backend isam2
  torchratslam run --config irat --data my_ros2_bag/ --image-topic /camera/image_raw \
      --odom-topic /odom --out out/ros2 --tum
  torchratslam run --config lab_tour --data lab.mp4 --odometry lab_odometry.csv --out out/lab
  torchratslam run --config virtual_tour --data sim:virtual_tour/session2 --out out/s2 \\
      --load out/s1/state
  torchratslam run --resume out/s2          # continue a stopped or killed run
"""

USAGE = """torchratslam run --config CONFIG --data DATA --out OUT [options]
       torchratslam run --resume OUT [--no-progress] [--checkpoint-every K] [--device DEVICE]"""


def register(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "run",
        help="map a dataset (directory, video, ROS bag or sim:NAME)",
        description=DESCRIPTION,
        epilog=EPILOG,
        usage=USAGE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    need = p.add_argument_group("required (all three, unless --resume)")
    need.add_argument(
        "--config",
        metavar="CONFIG",
        help="a YAML of configs/ (path or name, e.g. 'virtual_tour') or an OpenRatSLAM "
        ".txt config, e.g. --config configs/irat.yaml",
    )
    need.add_argument(
        "--data",
        metavar="DATA",
        help="dataset: a directory (frames/, odometry.csv, groundtruth.csv), a video "
        "(with --odometry), a ROS 1 .bag, a ROS 2 bag directory (sqlite3 or MCAP), or "
        "sim:NAME[/sessionK], e.g. --data sim:virtual_tour",
    )
    need.add_argument(
        "--out",
        metavar="OUT",
        help="output directory (created; torchratslam replaces only the files it wrote "
        "there; an OUT holding a stopped run is refused), e.g. --out out/vt",
    )
    p.add_argument(
        "--backend",
        choices=("alpha", "alpha_reference", "gtsam", "isam2"),
        help="experience-map relaxation backend (overrides exp_backend), e.g. --backend isam2",
    )
    p.add_argument(
        "--max-frames",
        type=int,
        metavar="N",
        help="stop after N frames, e.g. --max-frames 500",
    )
    p.add_argument(
        "--odometry",
        metavar="FILE",
        help="odometry CSV (header t,vtrans,vrot; one row per frame) for a video, or to "
        "replace a directory's odometry.csv, e.g. --odometry lab_odometry.csv",
    )
    p.add_argument(
        "--groundtruth",
        metavar="FILE",
        help="ground-truth CSV (t,x,y,theta) for a video, or to replace a directory's "
        "groundtruth.csv, e.g. --groundtruth gt.csv",
    )
    p.add_argument(
        "--visual-odometry",
        action="store_true",
        help="estimate odometry from the images (OpenRatSLAM's intensity profiles) even "
        "when the data has wheel odometry; used automatically when it has none, "
        "e.g. --visual-odometry",
    )
    p.add_argument(
        "--load",
        action="append",
        metavar="MAP",
        default=[],
        help="a stored map to localise in and merge with (repeatable): a saved state "
        "directory, a run's OUT directory, or a reference-format map, e.g. --load out/s1/state",
    )
    p.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        default=[],
        help="override one config key (repeatable), e.g. --set exp_loops=50",
    )
    p.add_argument(
        "--pipelined",
        action="store_true",
        help="one worker thread per module with bounded queues (same map), e.g. --pipelined",
    )
    p.add_argument(
        "--image-topic",
        default=None,
        metavar="TOPIC",
        help="image topic of a ROS 1 or ROS 2 bag (CompressedImage or Image; default "
        "/<topic_root>/camera/image/compressed with the config's topic_root, else the "
        "iRat's /irat_red/camera/image/compressed), "
        "e.g. --image-topic /stlucia/camera/image/compressed",
    )
    p.add_argument(
        "--odom-topic",
        default=None,
        metavar="TOPIC",
        help="nav_msgs/Odometry topic of a ROS 1 or ROS 2 bag (default /<topic_root>/odom, else "
        "/irat_red/odom), e.g. --odom-topic /irat_red/odom",
    )
    p.add_argument(
        "--device",
        default=None,
        metavar="DEVICE",
        help="torch device of the local view and pose cells, e.g. --device cuda",
    )
    p.add_argument(
        "--threads",
        type=int,
        default=1,
        metavar="N",
        help="torch intra-op threads (default 1: the per-frame work is small and extra "
        "threads mostly add overhead), e.g. --threads 4",
    )
    p.add_argument(
        "--tum",
        action="store_true",
        help="also write TUM trajectories for evo: OUT/tum_experience.txt (the current "
        "experience, as OpenRatSLAM publishes), OUT/tum_frame.txt (experience + odometry "
        "since it) and OUT/tum_groundtruth.txt; then evo_ape tum OUT/tum_groundtruth.txt "
        "OUT/tum_frame.txt -a, e.g. --tum",
    )
    p.add_argument(
        "--rerun",
        action="store_true",
        help="watch the run live in a rerun viewer (needs torchratslam[viewer]), e.g. --rerun",
    )
    p.add_argument(
        "--rerun-save",
        metavar="FILE",
        default=None,
        help="record the run for the rerun viewer into FILE.rrd (open it with: rerun "
        "FILE.rrd), e.g. --rerun-save out/run.rrd",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar, e.g. --no-progress")
    p.add_argument(
        "--scale-report",
        action="store_true",
        help="record how the cost per frame grows with the map: OUT/scale.json, scale.md and "
        "scale.png (per-module ms per frame and map size for each tenth of the run, peak "
        "memory, last tenth / first tenth), e.g. --scale-report",
    )
    p.add_argument(
        "--checkpoint-every",
        type=int,
        default=None,
        metavar="K",
        help="save a loadable (partial) map in OUT/state every K frames (default 1000; "
        "0: none), e.g. --checkpoint-every 500",
    )
    p.add_argument(
        "--resume",
        default=None,
        metavar="OUT",
        help="continue a run that stopped early or was killed, with its recorded options; "
        "the final map is the one an uninterrupted run makes, e.g. --resume out/vt",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="start again in an OUT that holds a stopped run (replacing only torchratslam's "
        "own files there), e.g. --overwrite",
    )
    p.add_argument(
        "--max-speed",
        type=float,
        default=None,
        metavar="M_PER_S",
        help=f"odometry rows faster than this are an error (default {MAX_SPEED:g} m/s), "
        "e.g. --max-speed 30",
    )
    p.add_argument(
        "--max-turn-rate",
        type=float,
        default=None,
        metavar="RAD_PER_S",
        help=f"odometry rows turning faster than this are an error (default {MAX_TURN_RATE:g} "
        "rad/s), e.g. --max-turn-rate 10",
    )
    p.set_defaults(func=main)
    return p


def _check_limits(args: argparse.Namespace) -> None:
    """--max-speed / --max-turn-rate: a finite number above zero, or the flag is named."""
    import math

    for flag, value in (("--max-speed", args.max_speed), ("--max-turn-rate", args.max_turn_rate)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise InputError(f"{flag} {value:g}: a limit must be a finite number above 0")


def _topics(args: argparse.Namespace, config: Any) -> tuple[str, str]:
    """Bag topics: the options, else the config's ``topic_root``, else the iRat's."""
    from torchratslam.experiments.run_dataset import bag_topics

    return bag_topics(config, args.image_topic, args.odom_topic)


def _overrides(items: list[str]) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in items:
        if "=" not in item:
            raise ConfigError(f"--set {item!r}: expected KEY=VALUE, e.g. --set exp_loops=50")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def main(args: argparse.Namespace) -> int:
    _check_limits(args)
    from torchratslam.experiments.run_dataset import resume_run, run_dataset
    from torchratslam.experiments.run_options import RunOptions, RunSettings
    from torchratslam.experiments.run_outputs import summary_line
    from torchratslam.experiments.run_state import RUN_RECORD

    settings = RunSettings(
        device=args.device,
        progress=not args.no_progress,
        threads=args.threads,
        scale_report=args.scale_report,
        checkpoint_every=args.checkpoint_every,
        overwrite=args.overwrite,
    )
    if args.resume is not None:
        given = [
            f"--{k.replace('_', '-')}"
            for k in ("config", "data", "out", "backend", "max_frames", "odometry", "groundtruth")
            if getattr(args, k) is not None
        ]
        given += [f"--{k}" for k in ("set", "load", "overwrite") if getattr(args, k)]
        if given:
            raise InputError(
                f"--resume takes the stopped run's options from {RUN_RECORD}; "
                f"do not give {', '.join(given)}"
            )
        metrics = resume_run(args.resume, settings)
        print(summary_line(metrics, Path(args.resume)))
        if metrics.ate_note:
            print(f"note: {metrics.ate_note}")
        return 0
    missing = [f"--{k}" for k in ("config", "data", "out") if not getattr(args, k)]
    if missing:
        raise InputError(f"the following arguments are required: {', '.join(missing)}")
    overrides = _overrides(args.set)
    if args.backend:
        overrides["exp_backend"] = args.backend
    options = RunOptions(
        config=args.config,
        data=args.data,
        overrides=overrides,
        max_frames=args.max_frames,
        odometry=args.odometry,
        groundtruth=args.groundtruth,
        visual_odometry=args.visual_odometry,
        load=tuple(args.load),
        pipelined=args.pipelined,
        image_topic=args.image_topic,
        odom_topic=args.odom_topic,
        max_speed=args.max_speed,
        max_turn_rate=args.max_turn_rate,
        tum=args.tum,
        rerun=args.rerun,
        rerun_save=args.rerun_save,
    )
    metrics = run_dataset(options, args.out, settings)
    print(summary_line(metrics, Path(args.out)))
    if metrics.ate_note:
        print(f"note: {metrics.ate_note}")
    return 0
