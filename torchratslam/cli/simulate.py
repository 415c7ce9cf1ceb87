"""``torchratslam simulate``: write a simulated tour as dataset directories."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import yaml

from torchratslam.errors import InputError

HELP = "write a simulated tour (sim:NAME) as a dataset directory (frames/, odometry.csv, ...)"


def _option(text: str) -> tuple[str, object]:
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"{text!r}: write KEY=VALUE, e.g. moving_obstacles=4")
    return key.strip(), yaml.safe_load(value)


def register(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``simulate`` subcommand."""
    from torchratslam.sim.tours import TOURS

    p = subparsers.add_parser(
        "simulate",
        help=HELP,
        description=HELP + ". Tours: " + ", ".join(TOURS) + ". Without --sessions the whole tour "
        "(sessions concatenated) is written to OUT; with it, one directory per session "
        "(OUT/session1, OUT/session2, ...).",
        epilog="examples:\n"
        "  torchratslam simulate virtual_tour --out data/vt --sessions --seed 1 "
        "--option illumination=0.2\n"
        "  torchratslam simulate loop --out data/loop --max-frames 200",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("name", help="tour name (or sim:NAME[/SESSION][?k=v&...]), e.g. virtual_tour")
    p.add_argument("--out", required=True, help="output directory, e.g. --out data/vt")
    p.add_argument(
        "--sessions", action="store_true", help="one dataset directory per session, e.g. --sessions"
    )
    p.add_argument(
        "--seed",
        type=int,
        default=None,
        help="seed of textures, noise and obstacles (0), e.g. --seed 1",
    )
    p.add_argument(
        "--option",
        "-o",
        action="append",
        type=_option,
        default=[],
        metavar="KEY=VALUE",
        help="tour option, repeatable, e.g. -o lasers=1 (also moving_obstacles=4, "
        "exact_odometry=1)",
    )
    p.add_argument(
        "--max-frames",
        type=int,
        default=None,
        help="write at most this many frames per dataset, e.g. --max-frames 200",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace existing output directories, e.g. --overwrite",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars, e.g. --quiet")
    p.set_defaults(func=run)
    return p


def run(args: argparse.Namespace) -> int:
    """Build the tour and write its dataset(s); prints a JSON summary."""
    from torchratslam.sim import get_tour, write_dataset
    from torchratslam.sim.dataset import parse_sim_spec
    from torchratslam.sim.tours import TOUR_PRESETS

    spec = args.name if args.name.startswith("sim:") else f"sim:{args.name}"
    name, session, options = parse_sim_spec(spec)
    options.update(dict(args.option))
    seed = int(options.pop("seed", 0) if args.seed is None else args.seed)
    tour = get_tour(name, seed=seed, **options)
    if args.max_frames is not None and args.max_frames < 1:
        raise InputError(f"--max-frames {args.max_frames}: give a positive number")
    out = Path(args.out)
    if session is not None:
        jobs = [(tour.session(int(session) if session.isdigit() else session), out)]
    elif args.sessions:
        jobs = [(s, out / s.name) for s in tour.sessions]
    else:
        jobs = [(tour.full(), out)]
    written = []
    for s, d in jobs:
        if args.max_frames is not None:
            s = s.subset(0, args.max_frames)
        write_dataset(s, d, overwrite=args.overwrite, progress=not args.quiet)
        entry = {"session": s.name, "frames": len(s), "dir": str(d)}
        if name in TOUR_PRESETS:  # OpenRatSLAM runs on the data as it is with this config
            entry["config"] = str(_write_config_txt(TOUR_PRESETS[name], Path(d)))
        written.append(entry)
    print(json.dumps({"tour": name, "seed": seed, "datasets": written}, indent=2))
    return 0


def _write_config_txt(preset: str, directory: Path) -> Path:
    """Write the preset as ``directory/config.txt`` in OpenRatSLAM's ini format."""
    from ratslam_graph.io import atomic_write_text
    from torchratslam.config import load_config, to_openratslam_txt

    path = directory / "config.txt"
    text = to_openratslam_txt(load_config(preset), comment=f"torchratslam preset {preset!r}")
    atomic_write_text(path, text)
    return path
