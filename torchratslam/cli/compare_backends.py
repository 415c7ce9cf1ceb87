"""``torchratslam compare-backends``: relax one pose graph with several backends."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

DESCRIPTION = """Relax one pose graph with several backends and print a table of time,
final error and (with ground truth) ATE per backend.

MAP is a g2o or TORO pose-graph file (read with ratslam_graph.io.read_posegraph), or a saved
RatSLAM state (a state directory, a run's OUT directory containing state/, or a
reference-format map): its experience map is turned into a pose graph (link
(d, heading, facing) -> dx = d cos(heading), dy = d sin(heading), dth = facing)."""

EPILOG = """examples:
  torchratslam compare-backends --map out/vt/state
  torchratslam compare-backends --map w100.graph --backends alpha,gtsam --json cmp.json
  torchratslam compare-backends --map city10000.g2o --groundtruth city10000_gt.txt
"""


def register(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "compare-backends",
        help="compare relaxation backends (alpha rule, GTSAM, iSAM2) on one map",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # the work is torchratslam.experiments.compare_backends
    p.add_argument(
        "--map",
        required=True,
        metavar="STATE_OR_GRAPH_FILE",
        help="a .g2o/.graph/TORO file or a saved state, e.g. --map out/vt/state",
    )
    p.add_argument(
        "--groundtruth",
        metavar="FILE",
        help="true node poses, one 'x y th' per line in node order (an index column is "
        "allowed), or for a saved state the project's groundtruth.csv (t,x,y,theta, as run "
        "and simulate write it) or a dataset, taken at each experience's creation time, "
        "e.g. --groundtruth gt_poses.txt or --groundtruth data/vt/groundtruth.csv",
    )
    p.add_argument(
        "--backends",
        default="alpha,gtsam,isam2",
        metavar="LIST",
        help="comma-separated backends (alpha, alpha_reference, gtsam, isam2), "
        "e.g. --backends alpha,gtsam",
    )
    p.add_argument(
        "--json",
        metavar="FILE",
        help="also write the rows (name, time_s, error, ate_rmse_m) as JSON, "
        "e.g. --json out/compare.json",
    )
    p.add_argument(
        "--passes",
        type=int,
        default=1000,
        metavar="N",
        help="relaxation passes of the alpha backends (least-squares backends optimise to "
        "convergence), e.g. --passes 250",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an existing --json file (never another command's file or an input), "
        "e.g. --overwrite",
    )
    p.set_defaults(func=main)
    return p


def main(args: argparse.Namespace) -> int:
    from ratslam_graph.out_checks import check_out_file
    from torchratslam.experiments.compare_backends import (
        format_table,
        run_comparison,
        write_rows_json,
    )

    inputs = [args.map] + ([args.groundtruth] if args.groundtruth else [])
    check_out_file(args.json, inputs=inputs, flag=("--json", "json"), overwrite=args.overwrite)
    names = tuple(s.strip() for s in args.backends.split(",") if s.strip())
    pg, rows = run_comparison(args.map, names, groundtruth=args.groundtruth, passes=args.passes)
    print(
        f"{args.map}: {np.asarray(pg.poses).shape[0]} nodes, {np.asarray(pg.edges).shape[0]} edges"
    )
    print(format_table(rows))
    ate = next((r for r in rows if r.get("ate_rmse_m") is not None), None)
    if ate is not None:
        print(
            f"ATE: {ate['ate_alignment']}-aligned, over {ate['ate_poses']} of "
            f"{np.asarray(pg.poses).shape[0]} nodes with ground truth ({ate['ate_over']})"
        )
    if args.json:
        write_rows_json(rows, args.json, inputs=inputs, overwrite=args.overwrite)
    return 0
