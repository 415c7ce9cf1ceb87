"""``torchratslam mbaram``: MBARAM topological mapping on a simulated laser tour.

Example:
    torchratslam mbaram --data sim:loop --out out/mbaram --laps 5 --loc-laps 5
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from torchratslam.errors import ConfigError
from torchratslam.experiments.mbaram_tour import PRESETS

# The experiment is torchratslam.experiments.mbaram_tour; this module parses the
# arguments and calls it.


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Defaults shown, examples kept as written."""


def register(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``mbaram`` subcommand."""
    p = subparsers.add_parser(
        "mbaram",
        help="MBARAM topological map from laser scans and odometry (simulated tours)",
        description=(
            "Learn an MBARAM topological map (Chin et al. 2015) over the first LAPS laps "
            "of a simulated tour with front and rear lasers, then localise on the next "
            "LOC_LAPS laps with and without the odometry channel. Writes OUT/metrics.json, "
            "OUT/map.png, OUT/nodes_per_lap.png, OUT/localisation.png and OUT/state.npz."
        ),
        epilog="examples:\n"
        "  torchratslam mbaram --data sim:irat_like --out out/mbaram\n"
        "  torchratslam mbaram --data sim:lab_tour --out out/mb --laps 3 --loc-laps 2 "
        "--odometry integrated",
        formatter_class=_HelpFormatter,
    )
    p.add_argument(
        "--data",
        required=True,
        help="simulator spec sim:NAME[/SESSION][?key=value], e.g. --data sim:irat_like",
    )
    p.add_argument(
        "--out", required=True, type=Path, help="output directory, e.g. --out out/mbaram"
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an earlier MBARAM run's outputs in OUT, e.g. --overwrite",
    )
    p.add_argument("--laps", type=int, default=5, help="mapping laps, e.g. --laps 3")
    p.add_argument(
        "--loc-laps",
        type=int,
        default=5,
        help="localisation laps after the mapping, e.g. --loc-laps 2",
    )
    p.add_argument("--seed", type=int, default=0, help="simulator seed, e.g. --seed 1")
    p.add_argument(
        "--moving-obstacles",
        type=int,
        default=2,
        help="pedestrians walking along the path, e.g. --moving-obstacles 0",
    )
    p.add_argument(
        "--moved-obstacles",
        type=int,
        default=2,
        help="boxes that move between laps, e.g. --moved-obstacles 0",
    )
    p.add_argument(
        "--odometry",
        choices=("groundtruth", "integrated"),
        default="groundtruth",
        help="odometry channel: ground-truth pose (the paper assumes accurate odometry) "
        "or dead reckoning of the noisy odometry, e.g. --odometry integrated",
    )
    p.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        default="sim",
        help="parameter preset: paper (Table 3 as printed) or sim (paper values with laser "
        "units and the odometry channel's S_MAX,k set for the simulated tours), "
        "e.g. --preset paper",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="an MBARAM parameter over the preset, e.g. --set laser_scale=5 (repeatable)",
    )
    p.add_argument("--no-plots", action="store_true", help="skip the figures, e.g. --no-plots")
    p.add_argument(
        "--no-progress", action="store_true", help="no progress bars, e.g. --no-progress"
    )
    p.add_argument(
        "--mapper",
        default="mbaram",
        help="range-sensor mapper, a name in torchratslam.registry.RANGE_MAPPERS, e.g. "
        "--mapper mbaram",
    )
    p.set_defaults(func=main)
    return p


def _parse_sets(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise ConfigError(f"--set expects KEY=VALUE, got {item!r}")
        out[key.strip()] = value.strip()
    return out


def main(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    from torchratslam.experiments.mbaram_tour import (
        MBARAMTourOptions,
        run_experiment,
        summary_line,
    )

    # run_experiment checks OUT first: new, empty, or an earlier MBARAM run's (--overwrite)
    tour = run_experiment(
        args.data,
        args.out,
        MBARAMTourOptions(
            laps=args.laps,
            loc_laps=args.loc_laps,
            seed=args.seed,
            moving_obstacles=args.moving_obstacles,
            moved_obstacles=args.moved_obstacles,
            odometry=args.odometry,
            preset=args.preset,
            overrides=_parse_sets(args.set),
            plots=not args.no_plots,
            progress=not args.no_progress,
            mapper=args.mapper,
        ),
        overwrite=args.overwrite,
    )
    print(summary_line(args.data, tour.metrics, Path(args.out)))
    return 0
