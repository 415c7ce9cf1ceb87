"""The ``torchratslam`` command line.

Each subcommand lives in its own module of this package and exposes
``register(subparsers) -> argparse.ArgumentParser``; the parser it returns must set
``func`` (a callable taking the parsed args and returning an exit code) with
``set_defaults``. Modules are discovered automatically, so adding a subcommand touches
no other file.

Every command runs torch with one intra-op thread unless ``TORCHRATSLAM_THREADS`` says
otherwise (RatSLAM's per-frame work is small; on a 2-core machine the default thread
pool made runs several times slower). ``run --threads N`` overrides it for that command.

Errors raised deliberately (:class:`~ratslam_graph.errors.RatSLAMError`) and OS errors end the
command with a one-line message and exit code 2; ``--debug`` shows the traceback.

Global options work anywhere on the command line (before or after the subcommand):
``--debug``, ``-v``/``--verbose`` (repeatable: INFO, then DEBUG messages of the
``torchratslam`` logger), ``-q`` (repeatable: errors only, then nothing but the final
error line) and ``--version``. A closed pipe (``torchratslam compare-backends | head``)
ends the command quietly.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import pkgutil
import re
import sys
import traceback
from collections.abc import Sequence
from typing import Any

from torchratslam.errors import ConfigError, RatSLAMError

EPILOG = """examples:
  torchratslam simulate virtual_tour --out data/vt --sessions
  torchratslam run --config configs/virtual_tour.yaml --data sim:virtual_tour --out out/vt
  torchratslam compare-backends --map out/vt/state --backends alpha,gtsam,isam2
  torchratslam multisession --config configs/virtual_tour.yaml --tour sim:virtual_tour --out out/ms

global options (anywhere on the command line):
  --debug                full tracebacks on errors
  -v, --verbose          more log messages (-vv: debug); -q fewer (-qq: none)
  --version              print the version and exit

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
    parser.add_argument(
        "-v", "--verbose", action="count", default=0, help="more log messages (-vv: debug)"
    )
    parser.add_argument("-q", action="count", default=0, help="fewer log messages (-qq: none)")
    parser.add_argument("--version", action="store_true", help="print the version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        if hasattr(module, "register"):
            module.register(sub)
    return parser


_GLOBAL_FLAGS = {"--debug", "--verbose", "--version"}
_COUNTED = re.compile(r"^-(v+|q+)$")


def split_global_options(argv: Sequence[str]) -> tuple[list[str], dict[str, int]]:
    """Take the global options out of ``argv`` wherever they are (up to a ``--``).

    Returns:
        The remaining arguments and ``{"debug": 0|1, "verbose": n, "quiet": n,
        "version": 0|1}``.
    """
    rest: list[str] = []
    found = {"debug": 0, "verbose": 0, "quiet": 0, "version": 0}
    tail = False
    for a in argv:
        if tail:
            rest.append(a)
        elif a == "--":
            tail = True
            rest.append(a)
        elif a in _GLOBAL_FLAGS:
            found[a[2:]] += 1
        elif _COUNTED.match(a):
            found["verbose" if a[1] == "v" else "quiet"] += len(a) - 1
        else:
            rest.append(a)
    return rest, found


class _StderrHandler(logging.StreamHandler):
    """Writes to whatever ``sys.stderr`` is when a record comes (tests replace it)."""

    @property
    def stream(self) -> Any:
        return sys.stderr

    @stream.setter
    def stream(self, value: Any) -> None:
        pass


def _setup_logging(verbose: int, quiet: int) -> None:
    level = {-2: logging.CRITICAL + 1, -1: logging.ERROR, 0: logging.WARNING, 1: logging.INFO}
    log = logging.getLogger("torchratslam")
    log.setLevel(level.get(max(-2, min(verbose - quiet, 2)), logging.DEBUG))
    if not any(getattr(h, "_torchratslam_cli", False) for h in log.handlers):
        handler = _StderrHandler()
        handler.setFormatter(logging.Formatter("torchratslam: %(message)s"))
        handler._torchratslam_cli = True  # type: ignore[attr-defined]
        log.addHandler(handler)


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("torchratslam")
    except Exception:  # not installed: the source tree's
        from torchratslam import __version__

        return __version__


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    try:
        code = _main(argv)
        sys.stdout.flush()  # a closed pipe shows here, not at interpreter exit
        return code
    except BrokenPipeError:
        # the reader of our output went away (``| head``): stop quietly, as cat does
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 141


def _main(argv: Sequence[str] | None) -> int:
    rest, opts = split_global_options(sys.argv[1:] if argv is None else list(argv))
    if opts["version"]:
        print(f"torchratslam {_version()}")
        return 0
    parser = build_parser()
    args = parser.parse_args(rest)
    args.debug = bool(opts["debug"])
    _setup_logging(opts["verbose"], opts["quiet"])
    if not getattr(args, "func", None):
        parser.print_help()
        return 1
    try:
        _set_threads(os.environ.get("TORCHRATSLAM_THREADS", "1"))
        return int(args.func(args) or 0)
    except BrokenPipeError:
        raise
    except KeyboardInterrupt:
        print("torchratslam: interrupted", file=sys.stderr)
        return 130
    except (RatSLAMError, OSError) as exc:
        if args.debug:
            traceback.print_exc()
        name = type(exc).__name__
        text = exc.cli_message() if isinstance(exc, RatSLAMError) else str(exc)
        msg = " ".join(text.split("\n"))  # options named by their flags, not as Python
        print(f"torchratslam {args.command}: error: {msg} [{name}]", file=sys.stderr)
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
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(n)
    else:  # torch reads these when it loads; not importing it keeps bad input fast
        os.environ["OMP_NUM_THREADS"] = os.environ["MKL_NUM_THREADS"] = str(n)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
