"""``torchratslam compare-backends``: relax one pose graph with several backends."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from torchratslam.graph.errors import InputError

DESCRIPTION = """Relax one pose graph with several backends and print a table of time,
final error and (with ground truth) ATE per backend.

MAP is a g2o or TORO pose-graph file (read with torchratslam.graph.io.read_posegraph), or a saved
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
    )
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
        "allowed), e.g. --groundtruth gt_poses.txt",
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
    p.set_defaults(func=main)
    return p


def posegraph_from_state(state: Any) -> Any:
    """The pose graph of a saved map's experience map (a ``MapState``)."""
    from torchratslam.graph.posegraph import PoseGraph

    poses = np.asarray(state.exp_pose, dtype=np.float64).reshape(-1, 3)
    src = np.asarray(state.link_from, dtype=np.int64)
    dst = np.asarray(state.link_to, dtype=np.int64)
    d = np.asarray(state.link_d, dtype=np.float64)
    heading = np.asarray(state.link_heading, dtype=np.float64)
    facing = np.asarray(state.link_facing, dtype=np.float64)
    meas = np.stack([d * np.cos(heading), d * np.sin(heading), facing], axis=1).reshape(-1, 3)
    edges = np.stack([src, dst], axis=1).reshape(-1, 2)
    return PoseGraph(poses, edges, meas, np.arange(poses.shape[0], dtype=np.int64))


def load_posegraph(path: str | Path) -> Any:
    """A pose graph from a graph file or a saved RatSLAM state."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"--map {str(path)!r}: not found; give a .g2o/TORO file or a saved state")
    if p.is_file() and p.suffix.lower() in (".g2o", ".graph", ".txt", ".toro"):
        from torchratslam.graph.io import read_posegraph

        return read_posegraph(p)
    from torchratslam.maps.state import load_state

    return posegraph_from_state(load_state(p))


def format_table(rows: list[dict[str, Any]]) -> str:
    """The comparison rows as a Markdown table."""
    has_ate = any(r.get("ate_rmse_m") is not None for r in rows)
    head = "| backend | time (s) | initial error | error |" + (" ATE (m) |" if has_ate else "")
    sep = "|---|---|---|---|" + ("---|" if has_ate else "")
    lines = [head, sep]
    for r in rows:
        init = r.get("initial_error")
        init_s = f"{init:.6g}" if init is not None else "-"
        line = f"| {r['name']} | {r['time_s']:.4f} | {init_s} | {r['error']:.6g} |"
        if has_ate:
            a = r.get("ate_rmse_m")
            line += f" {a:.4f} |" if a is not None else " - |"
        lines.append(line)
    return "\n".join(lines)


def main(args: argparse.Namespace) -> int:
    from torchratslam.graph.compare import compare_backends

    names = tuple(s.strip() for s in args.backends.split(",") if s.strip())
    if not names:
        raise InputError("--backends is empty; e.g. --backends alpha,gtsam,isam2")
    pg = load_posegraph(args.map)
    gt = None
    if args.groundtruth:
        from torchratslam.graph.io import read_poses

        gt = read_poses(args.groundtruth)
        n = np.asarray(pg.poses).shape[0]
        if gt.shape[0] != n:
            raise InputError(
                f"--groundtruth {args.groundtruth}: {gt.shape[0]} poses but the map has {n} nodes"
            )
    if args.passes < 1:
        raise InputError(f"--passes must be >= 1, got {args.passes}")
    rows = compare_backends(pg, backends=names, groundtruth=gt, passes=args.passes)
    print(
        f"{args.map}: {np.asarray(pg.poses).shape[0]} nodes, {np.asarray(pg.edges).shape[0]} edges"
    )
    print(format_table(rows))
    if args.json:
        out = Path(args.json)
        out.parent.mkdir(parents=True, exist_ok=True)
        payload = [
            {
                k: (v.item() if isinstance(v, np.generic) else v)
                for k, v in r.items()
                if not isinstance(v, np.ndarray)
            }
            for r in rows
        ]
        from torchratslam.graph.atomic import atomic_write_text

        atomic_write_text(out, json.dumps(payload, indent=2, default=str))
    return 0
