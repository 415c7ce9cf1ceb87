"""The ``torchratslam`` command line.

Each subcommand lives in its own module of this package and exposes
``register(subparsers) -> argparse.ArgumentParser``; the parser it returns must set
``func`` (a callable taking the parsed args and returning an exit code) with
``set_defaults``. Modules are discovered automatically, so adding a subcommand touches
no other file.

Every command runs torch with one intra-op thread unless ``TORCHRATSLAM_THREADS`` says
otherwise (RatSLAM's per-frame work is small; on a 2-core machine the default thread
pool made runs several times slower). ``run --threads N`` overrides it for that command.

Errors raised deliberately (:class:`~torchratslam.graph.errors.RatSLAMError`) and OS errors end the
command with a one-line message and exit code 2; ``--debug`` shows the traceback.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys
import traceback
from collections.abc import Sequence

from torchratslam.graph.errors import ConfigError, RatSLAMError

EPILOG = """examples:
  torchratslam simulate virtual_tour --out data/vt --sessions
  torchratslam run --config configs/virtual_tour.yaml --data sim:virtual_tour --out out/vt
  torchratslam compare-backends --map out/vt/state --backends alpha,gtsam,isam2
  torchratslam multisession --config configs/virtual_tour.yaml --tour sim:virtual_tour --out out/ms

environment:
  TORCHRATSLAM_THREADS   torch intra-op threads for every command (default 1)
"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="torchratslam",
        description="RatSLAM in PyTorch: mapping, map merging and backend comparison.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--debug", action="store_true", help="show full tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        if hasattr(module, "register"):
            module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 1
    try:
        _set_threads(os.environ.get("TORCHRATSLAM_THREADS", "1"))
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("torchratslam: interrupted", file=sys.stderr)
        return 130
    except (RatSLAMError, OSError) as exc:
        if args.debug:
            traceback.print_exc()
        name = type(exc).__name__
        print(f"torchratslam {args.command}: error: {exc} [{name}]", file=sys.stderr)
        if not args.debug:
            print("  (run with --debug for the full traceback)", file=sys.stderr)
        return 2


def _set_threads(value: str) -> None:
    try:
        n = int(value)
    except ValueError:
        n = 0
    if n < 1:
        raise ConfigError(f"TORCHRATSLAM_THREADS must be a positive integer, got {value!r}")
    import torch

    torch.set_num_threads(n)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
