"""``torchratslam compare-maps A B``: ICP (the paper's and the project's figure), the
rigid transform, ATE and the overlay figure of two saved maps."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

DESCRIPTION = """Compare two saved maps as the multisession paper does (its Figs. 10, 14,
16, 18). A and B may each be a native saved map, a run's OUT directory, or a map saved
by the paper's own implementation.

Which map moves: A, the single-session map (LibICP's template), is moved onto B, the
multisession map (LibICP's model, fixed), as the paper's LibICP call does. Printed:
  - the paper's figure: LibICP point-to-point residual from the identity, the MEAN
    SQUARED nearest-neighbour distance in m^2 (compare with the paper's 0.00773327,
    0.00883269, 0.0126932, 85.4687; the authors' own Lab Tour saves give 0.00883269);
  - the same ICP from 4 start rotations of A (0, 90, 180, 270 deg): the best residual
    and the spread, and a warning when the identity start stopped in a worse minimum;
  - the project's ICP RMSE in m, both ways round (ICP is not symmetric);
  - the rigid transform ICP applied to A;
  - ATE (m) of each map against ground truth when there is one (--groundtruth, or the
    dataset a run's OUT directory names)."""

EPILOG = """examples:
  torchratslam compare-maps out/single out/multi/session2/state --figure fig10.png
  torchratslam compare-maps their_complete/ their_merged/ --json out/icp.json
  torchratslam compare-maps out/a out/b --groundtruth sim:virtual_tour
"""


def register(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "compare-maps",
        help="ICP (paper's and project's figure; A moved onto B), transform, ATE and overlay",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "a",
        metavar="A",
        help="the single-session map, moved onto B (LibICP's template), e.g. out/single",
    )
    p.add_argument(
        "b",
        metavar="B",
        help="the multisession map, fixed (LibICP's model), e.g. out/multi/session2/state",
    )
    p.add_argument(
        "--config",
        help="config name or YAML (shapes the templates of a reference-format map), "
        "e.g. --config irat",
    )
    p.add_argument(
        "--groundtruth",
        metavar="CSV_OR_DATA",
        help="ground truth: a CSV with t,x,y,theta columns or a dataset spec (sim:NAME, ...), "
        "e.g. --groundtruth sim:virtual_tour",
    )
    p.add_argument(
        "--figure",
        metavar="PNG",
        help="write the overlay figure (Fig. 10) here, e.g. --figure fig10.png",
    )
    p.add_argument(
        "--json",
        metavar="FILE",
        help="also write the report (every number, the roles, the paths) as JSON, "
        "e.g. --json out/compare_maps.json",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an existing --figure or --json file (never another command's file "
        "or one of the maps), e.g. --overwrite",
    )
    p.set_defaults(func=main)
    return p


def main(args: argparse.Namespace) -> int:
    from ratslam_graph.out_checks import check_out_file
    from torchratslam.errors import InputError
    from torchratslam.experiments.compare_maps import compare_maps, summary_text, write_json

    if args.json and args.figure and Path(args.json).resolve() == Path(args.figure).resolve():
        raise InputError(f"--json and --figure are the same file {args.json}; give two paths")
    for flag, target in (("--json", args.json), ("--figure", args.figure)):
        check_out_file(
            target, inputs=(args.a, args.b), flag=(flag, flag[2:]), overwrite=args.overwrite
        )
    config = None
    if args.config:
        from torchratslam.config import load_config

        config = load_config(args.config)
    report = compare_maps(
        args.a,
        args.b,
        config=config,
        groundtruth=args.groundtruth,
        figure=args.figure,
        overwrite=args.overwrite,
    )
    print(summary_text(report))
    if args.json:
        print(f"json: {write_json(report, args.json, overwrite=args.overwrite)}")
    return 0
