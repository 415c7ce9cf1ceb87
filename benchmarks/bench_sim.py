"""Simulator speed: frames per second, one core (``make bench``, ``BENCH_ONLY=sim``)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable

import numpy as np


def _rate(fn: Callable[[int], object], n: int) -> float:
    fn(0)  # warm caches
    t0 = time.perf_counter()
    for k in range(n):
        fn(k)
    return n / (time.perf_counter() - t0)


def main() -> None:
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover
        pass
    from torchratslam.sim import get_tour

    quick = os.environ.get("BENCH_QUICK") == "1"
    n = 200 if quick else 1000
    rows = []
    loop = get_tour("loop").full()
    vt = get_tour("virtual_tour").full()
    lab = get_tour("lab_tour").full()
    irat = get_tour("irat_like").full()
    busy = get_tour("loop", moving_obstacles=6, moved_obstacles=4, pixel_noise=3.0).full()
    cases = [
        (
            "virtual_tour render",
            "panoramic 256x64",
            len(vt.world),
            lambda k: vt.render(k % len(vt)),
        ),
        ("loop render", "panoramic 256x64", len(loop.world), lambda k: loop.render(k % len(loop))),
        (
            "irat_like render",
            "forward 160x96",
            len(irat.world),
            lambda k: irat.render(k % len(irat)),
        ),
        ("lab_tour render", "forward 640x480", len(lab.world), lambda k: lab.render(k % len(lab))),
        ("loop lasers", "2 x 682 beams", len(loop.world), lambda k: loop.scans(k % len(loop))),
        ("loop Frame", "256x64 + lasers", len(loop.world), lambda k: loop.frame(k % len(loop))),
        (
            "loop Frame, 10 obstacles, noise",
            "256x64 + lasers",
            len(busy.world_at(0)),
            lambda k: busy.frame(k % len(busy)),
        ),
    ]
    for name, what, segs, fn in cases:
        m = n // 10 if "640x480" in what else n
        rate = _rate(fn, m)
        rows.append((name, what, segs, m, rate, 1e3 / rate))
    print("| case | output | wall segments | frames | frames/s | ms/frame |")
    print("|---|---|---|---|---|---|")
    for name, what, segs, m, rate, ms in rows:
        print(f"| {name} | {what} | {segs} | {m} | {rate:.0f} | {ms:.2f} |")
    sizes = np.array([loop.render(0).nbytes, lab.render(0).nbytes])
    print(f"\nimage bytes: panoramic {sizes[0]}, forward 640x480 {sizes[1]}")


if __name__ == "__main__":
    main()
