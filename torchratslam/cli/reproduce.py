"""``torchratslam reproduce``: run the papers' experiments, each beside the paper's numbers."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from torchratslam.errors import InputError

HELP = "run an experiment of the four papers and print the paper's numbers beside ours"

log = logging.getLogger("torchratslam")


def register(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``reproduce`` subcommand."""
    p = subparsers.add_parser(
        "reproduce",
        help=HELP,
        description=HELP + ". Writes OUT/report.json, OUT/report.md and the figures; "
        "'all' runs every experiment into OUT/<id>/ and writes OUT/index.md.",
        epilog="examples:\n"
        "  torchratslam reproduce --list\n"
        "  torchratslam reproduce multisession/virtual-tour --out out/vt --quick\n"
        "  torchratslam reproduce all --out out/papers",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "experiment", nargs="?", help="experiment id or 'all', e.g. multisession/virtual-tour"
    )
    p.add_argument("--list", action="store_true", help="list the experiments, e.g. --list")
    p.add_argument("--out", type=Path, help="output folder, e.g. --out out/vt")
    p.add_argument(
        "--quick", action="store_true", help="a small version (minutes, not hours), e.g. --quick"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (0), e.g. --seed 3")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a report already in OUT, e.g. --overwrite",
    )
    p.set_defaults(func=_run)
    return p


def _run(args: argparse.Namespace) -> int:
    from torchratslam.experiments.reproduce.catalogue import all_experiments
    from torchratslam.experiments.reproduce.report import report_markdown
    from torchratslam.experiments.reproduce.runner import run_all, run_one

    if args.list:
        for exp in all_experiments().values():
            print(f"{exp.id}\t{exp.title}")
        return 0
    if not args.experiment:
        raise InputError("name an experiment (see --list) or 'all'")
    if args.out is None:
        raise InputError("--out is required, e.g. --out out/papers")
    if args.experiment == "all":
        outcomes = run_all(args.out, quick=args.quick, seed=args.seed, overwrite=args.overwrite)
        failed = [o.experiment for o in outcomes if o.error]
        print(
            f"{len(outcomes) - len(failed)} of {len(outcomes)} experiments ran; "
            f"index: {args.out / 'index.md'}"
        )
        return 1 if failed else 0
    report = run_one(
        args.experiment, args.out, quick=args.quick, seed=args.seed, overwrite=args.overwrite
    )
    sys.stdout.write(report_markdown(report))
    return 0
