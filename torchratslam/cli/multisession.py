"""``torchratslam multisession``: multisession versus single-session mapping of a
simulated tour (the multisession paper's experiments, Section 5).

Every session of the tour is mapped in turn, each saved and loaded by the next, and
merged when it meets a stored map. The reference (``single`` in report.json) is the
paper's single mapping session: one continuous run through every session, joined by
drives along the tour's roads (``Tour.continuous()``); the sessions concatenated with a
kidnap between them (``single_concatenated``) and the last session alone
(``single_last_session``) are reported too. Writes under OUT: ``report.json``
(templates, experiences, links, ATE, ICP RMSE between the maps, the merges, optional
ablation and backend comparison), ``report.md`` (the same as tables), figures like the
paper's Fig. 9 (``fig9_*.png``: single map, first session, before merge, after merge,
final, ICP overlay) and the session maps (``multi/<session>/state``).
"""
# The experiment is torchratslam.experiments.multisession_tour; this module parses
# the arguments and calls it.

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def register(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "multisession",
        help="map a simulated tour session by session, merging maps, vs single-session",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--config",
        default=None,
        help="config file or shipped name (default: the tour's own config)",
    )
    p.add_argument("--tour", required=True, help="sim:NAME (virtual_tour, lab_tour, irat_like)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument(
        "--ablation",
        action="store_true",
        help="also map without the pose-cell shift (the paper's Fig. 12)",
    )
    p.add_argument(
        "--exp-pc-shift",
        choices=("experiences", "templates"),
        default="experiences",
        help="merge: shift of the experiences' pose-cell coordinates (default experiences: "
        "the authors' code; templates: the paper's single shift), e.g. --exp-pc-shift templates",
    )
    p.add_argument(
        "--match-exp",
        choices=("first", "nearest"),
        default="first",
        help="merge: loaded experience merged at (default first: the authors' code; "
        "nearest: nearest in pose cells), e.g. --match-exp nearest",
    )
    p.add_argument(
        "--backends",
        default="",
        help="comma-separated relaxation backends to compare, e.g. alpha,gtsam",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a config key (repeatable)",
    )
    p.add_argument("--seed", type=int, default=0, help="simulator seed (default 0)")
    p.add_argument(
        "--max-frames",
        type=int,
        default=None,
        help="at most this many frames per session (quick checks)",
    )
    p.add_argument("--no-figures", action="store_true", help="write report.json only")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=main)
    return p


def main(args: argparse.Namespace) -> int:
    from torchratslam.experiments.multisession_tour import report_markdown, run_experiment
    from torchratslam.graph.errors import ConfigError

    backends = tuple(b.strip() for b in args.backends.split(",") if b.strip())
    overrides = {}
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep:
            raise ConfigError(f"--set {item!r}: expected KEY=VALUE")
        overrides[key.strip()] = value.strip()
    result = run_experiment(
        args.config,
        args.tour,
        args.out,
        ablation=args.ablation,
        backends=backends,
        seed=args.seed,
        max_frames=args.max_frames,
        figures=not args.no_figures,
        progress=not args.quiet,
        overrides=overrides,
        merge_options={
            k: v
            for k, v in (("exp_pc_shift", args.exp_pc_shift), ("match_exp", args.match_exp))
            if v != {"exp_pc_shift": "experiences", "match_exp": "first"}[k]
        },
    )
    print(report_markdown(result["report"]))
    print(f"wrote {Path(args.out) / 'report.json'}")
    return 0
