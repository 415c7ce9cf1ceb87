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

While it works, OUT holds ``running.json`` (the command, its start); a run that stopped
(Ctrl-C, a crash) leaves it behind, and a new run into that OUT is refused: a
multisession experiment cannot be resumed, so start it again with ``--overwrite``.
"""
# The experiment is torchratslam.experiments.multisession_tour (seeds: multisession_seeds);
# this module parses the arguments and calls it.

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def register(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "multisession",
        help="map a simulated tour session by session, merging maps, vs single-session",
        description=(__doc__ or "").replace("``", ""),
        epilog="examples:\n"
        "  torchratslam multisession --tour sim:virtual_tour --out out/ms --ablation\n"
        "  torchratslam multisession --tour sim:irat_like --out out/irat --backends alpha,gtsam\n"
        "  torchratslam multisession --tour sim:virtual_tour --out out/ms --rerun",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--config",
        default=None,
        help="config file or shipped name (default: the tour's own config), "
        "e.g. --config virtual_tour",
    )
    p.add_argument(
        "--tour",
        required=True,
        help="sim:NAME (virtual_tour, lab_tour, irat_like), e.g. --tour sim:lab_tour; the "
        "simulator's options after '?', e.g. 'sim:virtual_tour?session2_start=0.82&fog=20'",
    )
    p.add_argument("--out", required=True, help="output directory, e.g. --out out/ms")
    p.add_argument(
        "--ablation",
        action="store_true",
        help="also map without the pose-cell shift (the paper's Fig. 12), e.g. --ablation",
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
        help="override a config key (repeatable), e.g. --set exp_loops=50",
    )
    p.add_argument("--seed", type=int, default=0, help="simulator seed (default 0), e.g. --seed 2")
    p.add_argument(
        "--seeds",
        default=None,
        help="per-seed check instead of one report: seeds as A-B or a,b,c (e.g. 0-9); "
        "prints and writes OUT/seeds.json and OUT/seeds.md (experiences multisession / "
        "continuous single session / no pose-cell shift, merge distances)",
    )
    p.add_argument(
        "--pc-shift-rotate",
        action="store_true",
        help="merge: rotate the partial map's pose-cell offsets by the heading shift "
        "(default off: the paper's translation, Eq. 10); a deviation, e.g. --pc-shift-rotate",
    )
    p.add_argument(
        "--merge-threshold",
        type=float,
        default=None,
        help="match error for a merge with a stored map (default: vt_match_threshold, "
        "the paper's); a deviation when set, e.g. --merge-threshold 0.03",
    )
    p.add_argument(
        "--merge-persist",
        type=int,
        default=1,
        help="merge only after this many consecutive new templates match the same "
        "stored map (default 1: the paper's first match); a deviation when > 1, e.g. "
        "--merge-persist 2",
    )
    p.add_argument(
        "--merge-absorb",
        action="store_true",
        help="at a delayed merge (--merge-persist > 1), merge the templates that already "
        "matched the stored map into their matches too; a deviation, e.g. --merge-absorb",
    )
    p.add_argument(
        "--merge-anchor",
        choices=("template", "view"),
        default=None,
        help="where a merge joins the maps (default template: the partial template that "
        "matched, the paper's; view, the default with --recommended-merge: the frame whose "
        "view matches the stored template best); a deviation when view, e.g. "
        "--merge-anchor view",
    )
    p.add_argument(
        "--recommended-merge",
        action="store_true",
        help="the merge measured best across seeds: --pc-shift-rotate --merge-persist 2 "
        "--merge-absorb --merge-anchor view (docs/multisession.md), e.g. --recommended-merge",
    )
    p.add_argument(
        "--max-frames",
        type=int,
        default=None,
        help="at most this many frames per session (quick checks), e.g. --max-frames 50",
    )
    p.add_argument(
        "--no-figures", action="store_true", help="write report.json only, e.g. --no-figures"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars, e.g. --quiet")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="start again in an OUT that holds a multisession run that did not finish, "
        "e.g. --overwrite",
    )
    p.add_argument(
        "--rerun",
        action="store_true",
        help="watch the multisession mapping live in a rerun viewer (torchratslam[viewer]), "
        "e.g. --rerun",
    )
    p.add_argument(
        "--rerun-save",
        metavar="FILE",
        default=None,
        help="record the multisession mapping for rerun into FILE.rrd, e.g. --rerun-save ms.rrd",
    )
    p.set_defaults(func=main)
    return p


class _Running:
    """OUT/running.json while the experiment works: a stopped one is never silently
    replaced (refused unless ``overwrite``)."""

    def __init__(self, out: Path, overwrite: bool) -> None:
        from torchratslam.errors import InputError
        from torchratslam.experiments.multisession_tour import RUNNING, check_out

        self.path = out / RUNNING
        check_out(out, overwrite)
        if self.path.exists() and not overwrite:
            raise InputError(
                f"{out} holds a multisession run that did not finish ({RUNNING}); it cannot "
                "be resumed: start it again with --overwrite, or choose another --out"
            )

    def __enter__(self) -> _Running:
        import json
        import sys
        import time

        from ratslam_graph.io import atomic_write_text

        self.created = not self.path.parent.exists()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        started = time.strftime("%Y-%m-%d %H:%M:%S")
        record = {"command": ["torchratslam", *sys.argv[1:]], "started": started}
        atomic_write_text(self.path, json.dumps(record) + "\n")
        return self

    def __exit__(self, kind: Any, *rest: Any) -> None:
        from torchratslam.errors import ConfigError, InputError

        # A finished run, or one refused for a bad input (nothing of it to resume), leaves
        # no lock; a stopped or crashed run keeps it so the next command says so.
        if kind is None or issubclass(kind, (InputError, ConfigError)):
            self.path.unlink(missing_ok=True)
            if self.created and self.path.parent.is_dir():
                if not any(self.path.parent.iterdir()):
                    self.path.parent.rmdir()


def parse_seeds(spec: str) -> list[int]:
    """``"0-9"`` or ``"0,3,5"`` (or both, comma-separated) -> the seeds."""
    from torchratslam.errors import ConfigError

    seeds: list[int] = []
    backwards, lo, hi = False, 0, 0
    try:
        for part in spec.split(","):
            a, sep, b = part.strip().partition("-")
            lo, hi = int(a), int(b) if sep else int(a)
            backwards = hi < lo
            if backwards:
                break
            seeds += list(range(lo, hi + 1))
    except ValueError:
        raise ConfigError(f"--seeds {spec!r}: expected A-B or a,b,c (e.g. 0-9)") from None
    if backwards:
        raise ConfigError(f"--seeds {spec!r}: {lo}-{hi} runs backwards; give A-B with A <= B")
    if not seeds:
        raise ConfigError(f"--seeds {spec!r}: no seeds")
    return seeds


def _seeds_main(args: argparse.Namespace, overrides: dict[str, str], merge: dict[str, Any]) -> int:
    import json
    import sys

    from ratslam_graph.io import atomic_write_text
    from torchratslam.experiments.multisession_seeds import seed_table, seed_table_markdown

    seeds = parse_seeds(args.seeds)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    def on_row(seed: int, row: dict) -> None:
        if not args.quiet:
            print(
                f"seed {seed} ({seeds.index(seed) + 1}/{len(seeds)}): experiences "
                f"multisession {row['multi']}, single {row['single']}"
                + (f", no pose-cell shift {row['ablation']}" if "ablation" in row else "")
                + ", merge distances "
                + (", ".join(f"{m['distance_m']:.2f} m" for m in row["merges"]) or "none"),
                file=sys.stderr,
                flush=True,
            )

    table = seed_table(
        args.tour,
        seeds,
        config=args.config,
        ablation=args.ablation,
        max_frames=args.max_frames,
        overrides=overrides,
        merge_options=merge,
        on_row=on_row,
        merge_threshold=args.merge_threshold,
        merge_persist=args.merge_persist,
        merge_absorb=args.merge_absorb,
        merge_anchor=args.merge_anchor,
    )
    text = seed_table_markdown(table)
    atomic_write_text(out / "seeds.json", json.dumps(table, indent=1) + "\n")
    atomic_write_text(out / "seeds.md", text)
    print(text)
    print(f"wrote {out / 'seeds.json'}")
    return 0


def main(args: argparse.Namespace) -> int:
    from torchratslam.errors import ConfigError
    from torchratslam.experiments.multisession_report import report_markdown
    from torchratslam.experiments.multisession_seeds import RECOMMENDED_SESSION_OPTIONS

    backends = tuple(b.strip() for b in args.backends.split(",") if b.strip())
    overrides = {}
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep:
            raise ConfigError(f"--set {item!r}: expected KEY=VALUE")
        overrides[key.strip()] = value.strip()
    merge: dict[str, Any] = {
        k: v
        for k, v in (("exp_pc_shift", args.exp_pc_shift), ("match_exp", args.match_exp))
        if v != {"exp_pc_shift": "experiences", "match_exp": "first"}[k]
    }
    if args.recommended_merge:
        args.pc_shift_rotate, args.merge_absorb = True, True
        args.merge_persist = max(args.merge_persist, 2)
        if args.merge_anchor is None:
            args.merge_anchor = RECOMMENDED_SESSION_OPTIONS["merge_anchor"]
    if args.merge_anchor is None:
        args.merge_anchor = "template"
    if args.pc_shift_rotate:
        merge["pc_shift_rotate"] = True
    if args.seeds is not None:
        parse_seeds(args.seeds)  # a bad --seeds is refused before OUT is touched
    with _Running(Path(args.out), args.overwrite):
        if args.seeds is not None:
            return _seeds_main(args, overrides, merge)
        result = _experiment(args, backends, overrides, merge)
    print(report_markdown(result["report"]))
    print(f"wrote {Path(args.out) / 'report.json'}")
    return 0


def _experiment(
    args: argparse.Namespace,
    backends: tuple[str, ...],
    overrides: dict[str, str],
    merge: dict[str, Any],
) -> Any:
    from torchratslam.experiments.multisession_tour import MultisessionOptions, run_experiment

    return run_experiment(
        args.config,
        args.tour,
        args.out,
        MultisessionOptions(
            ablation=args.ablation,
            backends=backends,
            seed=args.seed,
            max_frames=args.max_frames,
            figures=not args.no_figures,
            progress=not args.quiet,
            overrides=overrides,
            merge_options=merge,
            merge_threshold=args.merge_threshold,
            merge_persist=args.merge_persist,
            merge_absorb=args.merge_absorb,
            merge_anchor=args.merge_anchor,
            rerun=args.rerun,
            rerun_save=args.rerun_save,
        ),
        overwrite=args.overwrite,
    )
