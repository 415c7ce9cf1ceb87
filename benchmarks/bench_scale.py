"""City scale: the suburb tour, cost per frame as the map grows, both systems.

The simulator's ``suburb`` tour (8 x 8 blocks, a forward camera, 20000 frames by
default) is written once as a dataset directory with its OpenRatSLAM ``config.txt``
(cached under ``out/bench/``). On that same data, in this order:

1. OpenRatSLAM's C++ (``ratslam_driver`` of ``$OPENRATSLAM_BUILD``, built by
   ``../shared/tools/openratslam/build.sh``), when present;
2. torchratslam, once per profile (``torchratslam run --scale-report`` in a fresh
   process each, so each peak memory is its own).

For each: per-module milliseconds per frame for each tenth of the run, templates and
experiences at each tenth, the last tenth's cost over the first's, peak memory and the
trajectory ATE (one code path for both systems: the final pose of the experience
current at every frame, aligned to ground truth). The figure of cost per frame against
map size is written to ``OUT/scale_suburb.png``.

Environment: ``BENCH_SCALE_FRAMES`` (default 20000; ``BENCH_QUICK=1``: 2000),
``OPENRATSLAM_BUILD`` (the C++ build directory; default ``build/openratslam``),
``BENCH_OUT`` (default ``out/bench`` under the repository root).
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.openratslam import ROOT, find_build
from torchratslam.config import RatSLAMConfig
from torchratslam.eval.metrics import ate_rmse
from torchratslam.eval.scale import format_scale_table, read_openratslam_trace

SHARED_TOOLS = Path(__file__).resolve().parents[1].parent / "shared" / "tools" / "openratslam"


def profiles() -> list[tuple[str, list[str]]]:
    """The torchratslam configurations measured: the reference behaviour, the
    recommended profile, the budgeted relaxation, and the budgeted relaxation
    over-relaxed (the recommendation for long runs), where this version has them."""
    keys = RatSLAMConfig.key_owner()
    if "exp_relax_budget" in keys:
        return [
            ("torchratslam (openratslam)", ["behaviour=openratslam"]),
            ("torchratslam (torchratslam, recommended)", ["behaviour=torchratslam"]),
            (
                "torchratslam (openratslam + exp_relax_budget=20000)",
                ["behaviour=openratslam", "exp_relax_budget=20000"],
            ),
            (
                "torchratslam, long runs (openratslam + exp_relax_budget=20000 + "
                "exp_correction=0.95)",
                ["behaviour=openratslam", "exp_relax_budget=20000", "exp_correction=0.95"],
            ),
        ]
    if "behaviour" in keys:
        return [
            ("torchratslam (openratslam)", ["behaviour=openratslam"]),
            (
                "torchratslam (openratslam + alpha_local)",
                ["behaviour=openratslam", "exp_backend=alpha_local"],
            ),
        ]
    return [
        ("torchratslam, alpha", ["exp_backend=alpha"]),
        ("torchratslam, alpha_local", ["exp_backend=alpha_local"]),
    ]


def dataset(frames: int, root: Path) -> Path:
    """The suburb dataset directory (written once, then reused)."""
    out = root / f"suburb-{frames}"
    if (out / "meta.json").exists() and (out / "config.txt").exists():
        return out
    cmd = [sys.executable, "-m", "torchratslam", "simulate", f"sim:suburb?frames={frames}"]
    subprocess.run(
        [*cmd, "--out", str(out), "--quiet", "--overwrite"], check=True, stdout=subprocess.DEVNULL
    )
    return out


def _groundtruth(data: Path) -> np.ndarray:
    return np.loadtxt(data / "groundtruth.csv", delimiter=",", skiprows=1)


def _ate_from_ids(data: Path, exp_ids: np.ndarray, exp_xy: dict[int, np.ndarray]) -> float:
    """ATE of the trajectory 'final pose of the experience current at each frame'."""
    gt = _groundtruth(data)[:, 1:3]
    ok = np.array([i in exp_xy for i in exp_ids.tolist()])
    est = np.array([exp_xy[i] for i in exp_ids[ok].tolist()])
    return float(ate_rmse(est, gt[: len(exp_ids)][ok]))


_PEAK_PROBE = (
    "import resource, subprocess, sys\n"
    "with open(sys.argv[1], 'w') as log:\n"
    "    rc = subprocess.run(sys.argv[2:], stdout=log).returncode\n"
    "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n"
    "sys.exit(rc)\n"
)


def run_peak(cmd: list[str], log: Path) -> tuple[float, float]:
    """Run ``cmd`` (stdout to ``log``); its wall time (s) and peak memory (MiB).

    A small Python process runs the command, so ``RUSAGE_CHILDREN`` is the command's
    alone. Linux keeps a process's ``ru_maxrss`` across ``exec``: a process started
    straight from this one (which may hold hundreds of MiB of frames) would report at
    least this one's size; started from the small wrapper, at least the wrapper's
    (about 10 MiB).
    """
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", _PEAK_PROBE, str(log), *cmd], capture_output=True, text=True
    )
    wall = time.perf_counter() - t0
    if done.returncode != 0:  # the command's own words on why
        said = [ln.strip() for ln in done.stderr.splitlines() if ln.strip()]
        why = next((ln for ln in said if "error:" in ln.lower()), said[-1] if said else "")
        raise RuntimeError(f"{' '.join(cmd[:4])} ... exited {done.returncode}: {why}")
    return wall, float(done.stdout.strip().splitlines()[-1]) / 1024.0


def run_cpp(build: Path, data: Path, out: Path) -> dict[str, Any] | None:
    """OpenRatSLAM on the data: its scale report, wall time, ATE and peak memory."""
    exe = build / "ratslam_driver"
    if not exe.exists():
        return None
    out.mkdir(parents=True, exist_ok=True)
    cmd = [str(exe), str(data / "config.txt"), str(data), str(out)]
    wall, peak = run_peak(cmd, out / "stdout.log")
    rep = read_openratslam_trace(out / "frames.csv")
    with (out / "frames.csv").open(newline="") as fh:
        ids = np.array([int(r["current_exp_id"]) for r in csv.DictReader(fh)])
    with (out / "experiences.csv").open(newline="") as fh:
        xy = {int(r["id"]): np.array([float(r["x"]), float(r["y"])]) for r in csv.DictReader(fh)}
    rep["peak_memory_mb"] = peak
    return {
        "report": rep,
        "wall_s": wall,
        "ate_m": _ate_from_ids(data, ids, xy),
        "total_ms": float(
            np.loadtxt(out / "frames.csv", delimiter=",", skiprows=1, usecols=4).sum()
        ),
    }


def run_py(data: Path, sets: list[str], out: Path) -> dict[str, Any]:
    """torchratslam on the data in a fresh process, with --scale-report."""
    cmd = [
        sys.executable,
        "-m",
        "torchratslam",
        "run",
        "--config",
        str(data / "config.txt"),
        "--data",
        str(data),
        "--out",
        str(out),
        "--no-progress",
        "--scale-report",
        "--overwrite",  # the bench's own run directory, replaced on every run
    ]
    for s in sets:
        cmd += ["--set", s]
    out.mkdir(parents=True, exist_ok=True)
    wall, peak = run_peak(cmd, out / "stdout.log")
    rep = json.loads((out / "scale.json").read_text())
    rep["peak_memory_mb"] = peak  # the run's own getrusage can include its parent's size
    metrics = json.loads((out / "metrics.json").read_text())
    with (out / "trajectory.csv").open(newline="") as fh:
        ids = np.array([int(r["experience_id"]) for r in csv.DictReader(fh)])
    with (out / "experiences.csv").open(newline="") as fh:
        xy = {int(r["id"]): np.array([float(r["x"]), float(r["y"])]) for r in csv.DictReader(fh)}
    return {
        "report": rep,
        "wall_s": wall,
        "ate_m": _ate_from_ids(data, ids, xy),
        "total_ms": metrics["ms_per_frame"]["total"]["mean_ms"] * metrics["frames"],
        "links": metrics["links"],
    }


def main() -> None:
    quick = os.environ.get("BENCH_QUICK") == "1"
    frames = int(os.environ.get("BENCH_SCALE_FRAMES", 2000 if quick else 20000))
    root = Path(os.environ.get("BENCH_OUT", str(ROOT / "out" / "bench")))
    data = dataset(frames, root)
    print(f"suburb tour, {frames} frames (dataset {data})\n")
    results: dict[str, dict[str, Any]] = {}
    build = find_build()
    if build is not None:
        cpp = run_cpp(build, data, root / f"scale-cpp-{frames}")
        if cpp:
            results["OpenRatSLAM C++"] = cpp
    else:
        print(
            "OpenRatSLAM's build not found (nor build/openratslam): set OPENRATSLAM_BUILD "
            "to the directory built by "
            f"{SHARED_TOOLS / 'build.sh'} SOURCE BUILD_DIR (see its README) to compare.\n"
        )
    for i, (label, sets) in enumerate(profiles()):
        results[label] = run_py(data, sets, root / f"scale-py{i}-{frames}")
    for label, r in results.items():
        print(format_scale_table(r["report"], title=label))
        print(
            f"\nwhole run: {r['total_ms'] / 1000:.1f} s of module time, "
            f"wall {r['wall_s']:.1f} s, ATE {r['ate_m']:.2f} m\n"
        )
    lines = [
        "| system | module time (s) | last/first tenth | peak memory (MiB) | ATE (m) |"
        + (" speed vs C++ |" if "OpenRatSLAM C++" in results else ""),
        "|---|---|---|---|---|" + ("---|" if "OpenRatSLAM C++" in results else ""),
    ]
    cpp_total = results.get("OpenRatSLAM C++", {}).get("total_ms")
    for label, r in results.items():
        rep = r["report"]
        row = (
            f"| {label} | {r['total_ms'] / 1000:.1f} | "
            f"{rep['last_over_first']['total']:.2f}x | {rep['peak_memory_mb']:.0f} | "
            f"{r['ate_m']:.2f} |"
        )
        if cpp_total:
            row += f" {cpp_total / r['total_ms']:.2f}x |"
        lines.append(row)
    print("\n".join(lines))
    from torchratslam.viz.scale import plot_scale

    fig = plot_scale(
        root / "scale_suburb.png",
        {k: v["report"] for k, v in results.items()},
        title=f"suburb, {frames} frames",
    )
    print(f"\nfigure: {fig}")


if __name__ == "__main__":
    main()
