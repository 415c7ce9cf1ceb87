"""``torchratslam sweep``: run every combination of a sweep file; one results table."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

DESCRIPTION = """Run a parameter sweep: every combination of the sweep file's parameter
values x datasets x seeds x backends, one RatSLAM run each.

OUT receives results.csv (one row per run: every swept parameter, status, error, frames,
templates, experiences, links, ate_m, dead_reckoning_ate_m, ate_frames, wall_s, fps, ms per frame
per module; also results.parquet when pyarrow is installed), rewritten atomically after
every finished run, and figures/ (each metric against each parameter, speed against
accuracy). A failed run records its error and the sweep goes on. A stopped sweep (Ctrl-C,
a crash) keeps its finished runs in results.csv: a new sweep into that OUT is refused;
continue it with --resume, or start again with --overwrite.

Sweep file (YAML):
  base: virtual_tour
  parameters:
    vt_match_threshold: [0.03, 0.05]
    pc_vt_inject_energy: {start: 0.05, stop: 0.2, num: 4}
  datasets: [{data: "sim:loop?laps=1", max_frames: 300}]
  seeds: [0, 1]
  backends: [alpha, gtsam]"""

EPILOG = """examples:
  torchratslam sweep examples/sweep_loop.yaml --out out/sweep
  torchratslam sweep examples/sweep_loop.yaml --out out/sweep --resume
  torchratslam sweep examples/sweep_loop.yaml --out out/sweep --ray
  torchratslam sweep examples/sweep_loop.yaml --out out/sweep --ray-address auto
"""


def register(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "sweep",
        help="run a grid of configurations, datasets, seeds and backends (results table)",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("file", metavar="FILE", help="sweep YAML, e.g. examples/sweep_loop.yaml")
    p.add_argument(
        "--out", required=True, metavar="OUT", help="output folder, e.g. --out out/sweep"
    )
    add_execution_args(p)
    p.add_argument(
        "--resume",
        action="store_true",
        help="keep the finished runs of OUT/results.csv and run only the others, e.g. --resume",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="start again in an OUT whose results.csv holds a stopped or another sweep "
        "(replacing results.csv), e.g. --overwrite",
    )
    p.add_argument(
        "--retry-failed",
        action="store_true",
        help="with --resume, run failed runs again too, e.g. --resume --retry-failed",
    )
    p.add_argument(
        "--no-batch",
        action="store_true",
        help="run every run alone (no shared frames, views or batched pose cells), e.g. --no-batch",
    )
    p.add_argument(
        "--no-figures", action="store_true", help="write the table only, e.g. --no-figures"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar, e.g. --no-progress")
    p.set_defaults(func=main)
    return p


def add_execution_args(p: argparse.ArgumentParser) -> None:
    """--workers, --ray, --ray-address (shared with ``tune``)."""
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="runs at a time (default: every core locally, every CPU on Ray; 1: in this "
        "process), e.g. --workers 4",
    )
    p.add_argument(
        "--ray",
        action="store_true",
        help="run on Ray's own local cluster (pip install 'torchratslam[ray]'), e.g. --ray",
    )
    p.add_argument(
        "--ray-address",
        default=None,
        metavar="ADDR",
        help="run on this Ray cluster, e.g. --ray-address auto or ray://head:10001",
    )


def main(args: argparse.Namespace) -> int:
    from torchratslam.errors import InputError
    from torchratslam.sweeps import sweep

    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers must be >= 1, got {args.workers}")
    if args.resume and args.overwrite:
        raise InputError("--resume keeps OUT's runs and --overwrite replaces them; give one")
    out = Path(args.out)  # new, empty, or a sweep's own folder: sweep() checks it first
    table = sweep(
        args.file,
        out,
        workers=args.workers,
        ray=args.ray,
        ray_address=args.ray_address,
        resume=args.resume,
        retry_failed=args.retry_failed,
        batch=False if args.no_batch else None,
        figures=not args.no_figures,
        progress=not args.no_progress,
        overwrite=args.overwrite,
    )
    rows = table.to_dict("records") if hasattr(table, "to_dict") else list(table)
    ok = [r for r in rows if r.get("status") == "ok"]
    failed = len(rows) - len(ok)
    line = f"{len(rows)} runs ({failed} failed); wrote {out / 'results.csv'}"
    scored = [r for r in ok if isinstance(r.get("ate_m"), float) and r["ate_m"] == r["ate_m"]]
    if scored:
        best = min(scored, key=lambda r: r["ate_m"])
        line += (
            f"; best ATE {best['ate_m']:.3f} m (run {best['index']}; SE(2)-aligned, over the "
            "frames with ground truth, as each run's metrics.json)"
        )
    print(line)
    return 1 if rows and not ok else 0
