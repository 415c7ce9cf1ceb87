"""``make bench``: the speed report side by side with OpenRatSLAM's C++, or other benchmarks.

Usage:
    python -m benchmarks                 the speed report (``benchmarks/speed.py``): four
                                         sequences, per stage, peak memory, import cost,
                                         the long-run configuration (about 10 minutes on
                                         a quiet 2-core machine)
    python -m benchmarks --quick         the same on fewer frames, one round (1-2 minutes)
    python -m benchmarks --sequences suburb --suburb-frames 5000
                                         some sequences only
    python -m benchmarks --profile       where the time goes: cProfile of each stage on a
                                         2-lap loop (``benchmarks/profile_stages.py``)
    python -m benchmarks --only scale,pipeline
                                         those ``bench_*`` modules (``BENCH_ONLY`` too)
    python -m benchmarks --all           every ``bench_*`` module

``BENCH_QUICK=1`` is ``--quick``; ``make bench BENCH_ARGS=--quick`` passes options.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import platform
import sys
import time
from pathlib import Path

import torch


def machine() -> str:
    """CPU model name and core count (``/proc/cpuinfo``), Python and torch versions."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    py = platform.python_version()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return (
        f"{cpu}, {os.cpu_count()} cores, Python {py}, torch {torch.__version__}; "
        f"load average {load:.1f}"
    )


def bench_modules(only: set[str]) -> list[str]:
    """The ``bench_*`` module names (all, or those named in ``only`` without the prefix)."""
    here = Path(__file__).resolve().parent
    return [
        m.name
        for m in sorted(pkgutil.iter_modules([str(here)]), key=lambda m: m.name)
        if m.name.startswith("bench_") and (not only or m.name.removeprefix("bench_") in only)
    ]


def run_modules(names: list[str]) -> None:
    """Run each ``bench_*`` module's ``main()`` with a heading and its time."""
    for k, name in enumerate(names, start=1):
        print(f"[benchmark {k}/{len(names)}] {name.removeprefix('bench_')}", file=sys.stderr)
        module = importlib.import_module(f"benchmarks.{name}")
        t0 = time.perf_counter()
        print(f"## {name.removeprefix('bench_')}\n", flush=True)
        module.main()
        print(f"\n({name}: {time.perf_counter() - t0:.1f} s)\n", flush=True)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer frames, one round")
    ap.add_argument("--rounds", type=int, default=None, help="alternated rounds on the loops")
    ap.add_argument("--out", type=Path, default=None, help="datasets and runs (out/bench)")
    ap.add_argument(
        "--sequences",
        default="loop,loop30,heldout,suburb",
        help="some of loop, loop30, heldout, suburb",
    )
    ap.add_argument("--suburb-frames", type=int, default=None, help="default 20000 (quick 2000)")
    what = ap.add_mutually_exclusive_group()
    what.add_argument("--profile", action="store_true", help="cProfile per stage, 2-lap loop")
    what.add_argument("--only", default=os.environ.get("BENCH_ONLY", ""), help="bench_* modules")
    what.add_argument("--all", action="store_true", help="every bench_* module")
    a = ap.parse_args(argv)
    quick = a.quick or os.environ.get("BENCH_QUICK", "") not in ("", "0")
    if quick:
        os.environ["BENCH_QUICK"] = "1"  # the bench_* modules read it
    print(f"# torchratslam benchmarks\nmachine: {machine()}\n", flush=True)
    only = {s.strip() for s in a.only.split(",") if s.strip()}
    if a.all or only:
        run_modules(bench_modules(only))
    elif a.profile:
        from benchmarks import profile_stages

        profile_stages.main(quick=quick)
    else:
        from benchmarks import speed

        seqs = tuple(x.strip() for x in a.sequences.split(",") if x.strip())
        unknown = set(seqs) - set(speed.SEQUENCES)
        if unknown:
            ap.error(f"unknown sequences {sorted(unknown)}; choose from {speed.SEQUENCES}")
        speed.main(quick, a.out, a.rounds, seqs, a.suburb_frames)


if __name__ == "__main__":
    main()
