"""Run every benchmark module (``make bench``)."""

from __future__ import annotations

import importlib
import os
import pkgutil
import platform
import sys
import time
from pathlib import Path

import torch


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    py = platform.python_version()
    return f"{cpu}, {os.cpu_count()} cores, Python {py}, torch {torch.__version__}"


def main() -> None:
    only = {s.strip() for s in os.environ.get("BENCH_ONLY", "").split(",") if s.strip()}
    print(f"# torchratslam benchmarks\nmachine: {machine()}\n")
    here = Path(__file__).resolve().parent
    names = [
        m.name
        for m in sorted(pkgutil.iter_modules([str(here)]), key=lambda m: m.name)
        if m.name.startswith("bench_") and (not only or m.name.removeprefix("bench_") in only)
    ]
    for k, name in enumerate(names, start=1):
        print(f"[benchmark {k}/{len(names)}] {name.removeprefix('bench_')}", file=sys.stderr)
        module = importlib.import_module(f"benchmarks.{name}")
        t0 = time.perf_counter()
        print(f"## {name.removeprefix('bench_')}\n", flush=True)
        module.main()
        print(f"\n({name}: {time.perf_counter() - t0:.1f} s)\n", flush=True)


if __name__ == "__main__":
    main()
