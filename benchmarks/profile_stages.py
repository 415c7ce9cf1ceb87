"""Where the time goes: each stage of the pipeline under its own cProfile.

The corridor loop driven twice (``sim:loop?laps=2``, 594 frames; ``--quick``: its first
200), with the OpenRatSLAM comparison's config and torchratslam's default profile, one
torch thread, frames decoded before the loop. Three runs after a warm-up:

1. unprofiled: ms/frame of each stage and of the whole frame loop (what lies outside
   the stages is the pipeline's own bookkeeping);
2. each stage under its own profiler, counting process CPU time (which the load of a
   shared machine does not inflate as it does wall time); the pipeline's
   :class:`~torchratslam.timing.TimeLogger` is replaced by one that switches the
   stage's profiler on inside each timed section:
   calls per frame, self time split into project Python (``torchratslam``,
   ``ratslam_graph``), library Python (numpy / torch wrappers, the standard library)
   and C calls (numpy / torch kernels and builtins), and the top functions by self time;
3. the whole loop under one profiler: the functions outside every stage.

The profiler's own cost per call inflates Python-heavy code: compare the profiled
ms/frame with the unprofiled one. Numba-compiled kernels are not seen as calls; their
time is the self time of the Python function calling them.

``python -m benchmarks --profile`` or ``python -m benchmarks.profile_stages``.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from benchmarks.openratslam import LOOP_TXT, ROOT, Dataset, load_frames
from torchratslam.timing import MODULES, TimeLogger

TOP = 12
"""Functions listed per stage."""

Key = tuple[str, int, str]


class StageProfiler(TimeLogger):
    """A :class:`TimeLogger` that also profiles each timed section with the stage's own
    :class:`cProfile.Profile` (sections never nest, so one profiler runs at a time)."""

    def __init__(self) -> None:
        super().__init__()
        self.profiles: dict[str, cProfile.Profile] = {}

    @contextmanager
    def section(self, module: str) -> Iterator[None]:
        prof = self.profiles.setdefault(module, cProfile.Profile(time.process_time))
        t0 = time.perf_counter()
        prof.enable()
        try:
            yield
        finally:
            prof.disable()
            self.record(module, time.perf_counter() - t0)


def _kind(key: Key) -> str:
    path = key[0]
    if path == "~":
        return "C"
    if "/torchratslam/" in path or "/ratslam_graph/" in path:
        return "project"
    return "library"


def _where(key: Key) -> str:
    path, line, name = key
    if path == "~":
        return name
    p = Path(path)
    for top in ("torchratslam", "ratslam_graph", "numpy", "torch", "benchmarks"):
        if top in p.parts:
            rel = "/".join(p.parts[len(p.parts) - p.parts[::-1].index(top) - 1 :])
            return f"{rel}:{line} {name}"
    return f"{p.name}:{line} {name}"


def _stats(prof: cProfile.Profile) -> dict[Key, tuple]:
    return pstats.Stats(prof).stats  # type: ignore[attr-defined]


def stage_summary(prof: cProfile.Profile, frames: int) -> dict[str, Any]:
    """Calls per frame, self time per frame by kind (us), and the top functions."""
    st = _stats(prof)
    by_kind = {"project": 0.0, "library": 0.0, "C": 0.0}
    calls = {"project": 0, "library": 0, "C": 0}
    for key, (_cc, nc, tt, _ct, _callers) in st.items():
        by_kind[_kind(key)] += tt
        calls[_kind(key)] += nc
    top = sorted(st.items(), key=lambda kv: kv[1][2], reverse=True)[:TOP]
    return {
        "self_us": {k: v * 1e6 / frames for k, v in by_kind.items()},
        "calls": {k: v / frames for k, v in calls.items()},
        "top": [
            (_where(k), v[1] / frames, v[2] * 1e6 / frames, v[3] * 1e6 / frames) for k, v in top
        ],
    }


def _new_slam(cfg: Path) -> Any:
    from torchratslam.config import load_config
    from torchratslam.pipeline import RatSLAM

    return RatSLAM(load_config(cfg, behaviour="openratslam"))


def profile(quick: bool = False, out: Path | None = None) -> dict[str, Any]:
    """The three runs of the module docstring; their figures."""
    import torch

    from benchmarks.speed import dataset_dir

    torch.set_num_threads(1)
    ds = Dataset(
        "loop, 2 laps",
        "sim:loop?laps=2",
        LOOP_TXT.format(threshold=0.06),
        200 if quick else None,
        "profile",
    )
    data = dataset_dir(ds, out if out is not None else ROOT / "out" / "bench")
    cfg = data / "config.txt"
    frames = load_frames(data)
    n = len(frames)
    _new_slam(cfg).run(frames[:60], progress=False)  # warm-up
    plain = _new_slam(cfg)
    cpu0 = time.process_time()
    res = plain.run(frames, progress=False)
    cpu = time.process_time() - cpu0
    plain_ms = {m: res.timings[m]["mean_ms"] for m in (*MODULES, "total")}
    plain_ms["loop wall"] = res.wall_s * 1000.0 / n
    plain_ms["loop CPU"] = cpu * 1000.0 / n
    staged = _new_slam(cfg)
    staged.timings = StageProfiler()
    res_p = staged.run(frames, progress=False)
    stages = {
        m: {"profiled_ms": res_p.timings[m]["mean_ms"], **stage_summary(p, n)}
        for m, p in staged.timings.profiles.items()
    }
    whole = _new_slam(cfg)
    prof = cProfile.Profile(time.process_time)
    prof.enable()
    whole.run(frames, progress=False)
    prof.disable()
    inside: set[Key] = set()
    for p in staged.timings.profiles.values():
        inside |= set(_stats(p))
    outside = {k: v for k, v in _stats(prof).items() if k not in inside}
    top_out = sorted(outside.items(), key=lambda kv: kv[1][2], reverse=True)[:TOP]
    return {
        "frames": n,
        "spec": ds.spec,
        "counts": (res.templates, res.experiences, res.links),
        "plain_ms": plain_ms,
        "stages": stages,
        "outside": [(_where(k), v[1] / n, v[2] * 1e6 / n, v[3] * 1e6 / n) for k, v in top_out],
        "outside_self_us": sum(v[2] for v in outside.values()) * 1e6 / n,
    }


def print_profile(r: dict[str, Any]) -> None:
    t, e, li = r["counts"]
    print(
        f"### Where the time goes: `{r['spec']}`, {r['frames']} frames "
        f"({t} templates, {e} experiences, {li} links), default profile, one thread\n"
    )
    pm = r["plain_ms"]
    print(
        "| stage | ms/frame | profiled ms/frame (wall) | calls/frame (project / library / C) | "
        "self us/frame (project / library / C) |"
    )
    print("|---|---|---|---|---|")
    for m in MODULES:
        s = r["stages"].get(m)
        if s is None:
            continue
        c, u = s["calls"], s["self_us"]
        print(
            f"| {m} | {pm[m]:.3f} | {s['profiled_ms']:.3f} | "
            f"{c['project']:.0f} / {c['library']:.0f} / {c['C']:.0f} | "
            f"{u['project']:.0f} / {u['library']:.0f} / {u['C']:.0f} |"
        )
    print(f"| module total | {pm['total']:.3f} | | | |")
    print(f"| frame loop (wall) | {pm['loop wall']:.3f} | | | |")
    print(f"| frame loop (process CPU time) | {pm['loop CPU']:.3f} | | | |\n")
    print(
        "ms/frame: wall time of the unprofiled run (the load of the machine included); the "
        "profiles count process CPU time, so their us/frame hold under load.\n"
    )
    for m in MODULES:
        s = r["stages"].get(m)
        if s is None:
            continue
        print(f"**{m}**: top functions by self time\n")
        _print_top(s["top"])
    print(
        "**outside the stages** (the frame loop's bookkeeping; functions never called "
        f"inside a stage): {r['outside_self_us']:.0f} us/frame of self time\n"
    )
    _print_top(r["outside"])


def _print_top(rows: list[tuple[str, float, float, float]]) -> None:
    print("| function | calls/frame | self us/frame | cumulative us/frame |")
    print("|---|---|---|---|")
    for where, calls, tt, ct in rows:
        print(f"| `{where}` | {calls:.1f} | {tt:.1f} | {ct:.1f} |")
    print()


def main(quick: bool = False, out: Path | None = None) -> None:
    """Profile and print (Markdown)."""
    print(f"[profile] loop, 2 laps{' (quick)' if quick else ''}", file=sys.stderr, flush=True)
    print_profile(profile(quick, out))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(prog="python -m benchmarks.profile_stages")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args()
    main(a.quick, a.out)
