"""``torchratslam convert SRC DST --to native|reference``: convert a saved map between
the native format and the multisession paper's own format, checking that nothing the
target format can hold is lost."""

from __future__ import annotations

import argparse
import json
from typing import Any

DESCRIPTION = """Convert a saved map between torchratslam's native format (state.json +
state.npz) and the format of the multisession paper's own implementation (plain-text
files their loader reads back). SRC may be a native map, a run's OUT directory or a
reference-format directory; DST must not exist (or be empty).

The map is written, read back and compared before DST appears: a value the target
format holds that did not survive is an error and nothing is written. What the target
format cannot hold (pose-cell activity, creation frames and times, the config,
module extras) is listed under "dropped". A list the source held stale (a template's
experience list or an experience's link list that disagrees with the map's ids, as the
authors' merge leaves some) is written derived from the ids and listed under "changed",
with both values."""

EPILOG = """examples:
  torchratslam convert out/vt/state their_format/ --to reference
  torchratslam convert their_session3/ session3_native/ --to native --config irat
"""


def register(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "convert",
        help="convert a map between the native and the paper authors' format",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("source", metavar="SRC", help="the map to convert, e.g. out/vt/state")
    p.add_argument("target", metavar="DST", help="the directory to write, e.g. their_format/")
    p.add_argument(
        "--to",
        required=True,
        choices=("native", "reference"),
        help="target format, e.g. --to reference",
    )
    p.add_argument(
        "--config",
        help="config name or YAML the map was made with (shapes reference-format "
        "templates), e.g. --config irat",
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON, e.g. --json")
    p.set_defaults(func=main)
    return p


def main(args: argparse.Namespace) -> int:
    from torchratslam.maps.io import convert_map

    config = None
    if args.config:
        from torchratslam.config import load_config

        config = load_config(args.config)
    rep = convert_map(args.source, args.target, to=args.to, config=config)
    if args.json:
        print(json.dumps(rep, indent=1))
        return 0
    templates = (
        f"no templates (the source has no {rep['templates_missing']}; only "
        f"{rep['templates']} template associations)"
        if rep["templates_missing"]
        else f"{rep['templates']} templates"
    )
    changed = rep["changed"]
    print(
        f"wrote {rep['target']} ({rep['format']}): {templates}, {rep['experiences']} "
        f"experiences, {rep['links']} links; "
        + (
            f"{len(changed)} value(s) written differently from the source (below), every "
            "other value the format holds read back unchanged"
            if changed
            else "every value the format holds read back unchanged"
        )
    )
    for item in changed:
        print(f"  changed (a stale list, derived from the map's ids): {item}")
    for item in rep["dropped"]:
        print(f"  not held by the {rep['format']} format (dropped): {item}")
    return 0
