"""``torchratslam compare-maps A B``: ICP (the paper's and the project's figure), the
rigid transform, ATE and the overlay figure of two saved maps."""

from __future__ import annotations

import argparse
import json
from typing import Any

DESCRIPTION = """Compare two saved maps as the multisession paper does (its Figs. 10, 14,
16, 18). A and B may each be a native saved map, a run's OUT directory, or a map saved
by the paper's own implementation.

A is the template (fixed; the paper's single-session map), B the model (moved onto A;
the paper's multisession map). Printed:
  - the paper's figure: LibICP point-to-point residual, the MEAN SQUARED
    nearest-neighbour distance in m^2 (compare with the paper's 0.00773327, 0.00883269,
    0.0126932, 85.4687);
  - the project's ICP RMSE in m, both ways round (ICP is not symmetric);
  - the rigid transform ICP applied to B;
  - ATE (m) of each map against ground truth when there is one (--groundtruth, or the
    dataset a run's OUT directory names)."""

EPILOG = """examples:
  torchratslam compare-maps out/single out/multi/session2/state --figure fig10.png
  torchratslam compare-maps their_session3/ out/vt/state --config irat --json
  torchratslam compare-maps out/a out/b --groundtruth sim:virtual_tour
"""


def register(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "compare-maps",
        help="ICP (paper's and project's figure), transform, ATE and overlay of two maps",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("a", metavar="A", help="the fixed map (e.g. the single-session map)")
    p.add_argument("b", metavar="B", help="the moved map (e.g. the multisession map)")
    p.add_argument(
        "--config",
        help="config name or YAML (shapes the templates of a reference-format map)",
    )
    p.add_argument(
        "--groundtruth",
        metavar="CSV_OR_DATA",
        help="ground truth: a CSV with t,x,y,theta columns or a dataset spec (sim:NAME, ...)",
    )
    p.add_argument("--figure", metavar="PNG", help="write the overlay figure (Fig. 10) here")
    p.add_argument("--json", action="store_true", help="print the numbers as JSON")
    p.set_defaults(func=main)
    return p


def main(args: argparse.Namespace) -> int:
    from torchratslam.experiments.compare_maps import compare_maps, summary_text

    config = None
    if args.config:
        from torchratslam.config import load_config

        config = load_config(args.config)
    report = compare_maps(
        args.a, args.b, config=config, groundtruth=args.groundtruth, figure=args.figure
    )
    print(json.dumps(report, indent=1) if args.json else summary_text(report))
    return 0
