"""The speed report of ``make bench``: torchratslam side by side with OpenRatSLAM's C++.

Five simulated sequences, each rendered once into a dataset folder under ``OUT`` (default
``out/bench``, reused by later runs) and run by both systems on the same frames:

* ``loop``: the corridor loop, 6 laps (``sim:loop``, 1781 panoramic 256x64 frames, seed 0),
  with the OpenRatSLAM comparison's config (about 270 templates);
* ``loop, 30 laps``: the same loop driven 30 times (``sim:loop?laps=30``, 8901 frames);
* ``held-out``: two loops nothing in the project was run or tuned on before the default
  became double (other seeds, lengths and frame rates: ``sim:loop?seed=23&laps=3&hz=4``,
  ``sim:loop?seed=31&laps=12&hz=6``), to show the default's map is the C++'s on data it
  never saw;
* ``suburb``: the city-scale street grid (``sim:suburb?frames=20000``, 20000 forward
  128x64 frames, about 16000 experiences) with the config ``torchratslam simulate``
  writes beside it.

On the loops the runs alternate in one process: OpenRatSLAM's C++ (``ratslam_driver``,
images decoded before its loop), then torchratslam's default profile (one torch thread,
the default precision: double, as the C++; frames decoded before the loop), ``rounds``
times; the speed ratio is C++
ms/frame over torchratslam ms/frame of the same round, and the table gives the median of
the per-round ratios. Milliseconds per frame are module time (local view + pose cells +
experience map, torchratslam's odometry source included); "loop wall" is the whole frame
loop per frame (torchratslam's orchestration included, reading excluded on both sides)
and "loop CPU time" its process CPU time, which the load of a shared machine inflates
less than wall time (the ratio of CPU times is printed beside the wall-time ratio).

On the suburb every run is a fresh process, so each peak memory (max RSS) is its own:
the C++ (under a small Python wrapper whose ``RUSAGE_CHILDREN`` is the driver's alone),
torchratslam's default profile and the long-run configuration (``exp_relax_budget`` +
``exp_correction``, see ``bench_scale``), each with its cost per tenth of the run. What
importing torchratslam costs is measured in separate processes too.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import bench_scale
from benchmarks.openratslam import (
    BUILD_HELP,
    LOOP_TXT,
    ROOT,
    Dataset,
    find_build,
    load_frames,
    read_csv,
    run_cpp,
    run_py,
    write_dataset_dir,
)

HELD_OUT = ("sim:loop?seed=23&laps=3&hz=4", "sim:loop?seed=31&laps=12&hz=6")
"""Loops first run when the default became double (seeds, lengths and rates never used)."""

LONG_RUN = ("behaviour=openratslam", "exp_relax_budget=20000", "exp_correction=0.95")
"""The long-run configuration on the suburb (``bench_scale``'s recommendation)."""


@dataclass(frozen=True)
class Plan:
    """What one report runs.

    Attributes:
        loops: the loop sequences (run in one process, alternated with the C++).
        rounds: alternated rounds on each loop sequence.
        suburb_frames: frames of the suburb (0: no suburb).
        out: where datasets and the suburb runs are kept.
    """

    loops: tuple[Dataset, ...]
    rounds: int
    suburb_frames: int
    out: Path


SEQUENCES = ("loop", "loop30", "heldout", "suburb")
"""Names of the report's sequences (``--sequences``)."""


def plan(
    quick: bool,
    out: Path | None = None,
    rounds: int | None = None,
    sequences: tuple[str, ...] = SEQUENCES,
    suburb_frames: int | None = None,
) -> Plan:
    """The full report (three sequences, 3 rounds) or the quick check (fewer frames, 1
    round); ``sequences`` picks some of :data:`SEQUENCES`."""
    cfg = LOOP_TXT.format(threshold=0.06)
    keyed = (
        ("loop", Dataset("loop", "sim:loop", cfg, 400 if quick else None, "6 laps")),
        ("loop30", Dataset("loop, 30 laps", "sim:loop?laps=30", cfg, 1200 if quick else None, "")),
        ("heldout", Dataset("held-out loop A", HELD_OUT[0], cfg, 600 if quick else None, "")),
        ("heldout", Dataset("held-out loop B", HELD_OUT[1], cfg, 600 if quick else None, "")),
    )
    loops = tuple(d for k, d in keyed if k in sequences)
    if suburb_frames is None:
        suburb_frames = 2000 if quick else 20000
    return Plan(
        loops=loops,
        rounds=rounds if rounds is not None else (1 if quick else 3),
        suburb_frames=suburb_frames if "suburb" in sequences else 0,
        out=out if out is not None else ROOT / "out" / "bench",
    )


def dataset_dir(ds: Dataset, root: Path) -> Path:
    """``ds`` rendered under ``root`` (reused when already complete)."""
    slug = ds.spec.removeprefix("sim:").replace("?", "-").replace("&", "-").replace("=", "")
    out = root / f"{slug}-{ds.frames or 'all'}"
    if not (out / "config.txt").exists():  # written last
        write_dataset_dir(ds, out)
    return out


# ----------------------------------------------------------------------------- loops
def loop_side_by_side(build: Path, ds: Dataset, root: Path, rounds: int) -> dict[str, Any]:
    """Alternated C++ / torchratslam runs on one loop sequence; per-round figures."""
    data = dataset_dir(ds, root)
    cfg = data / "config.txt"
    frames = load_frames(data)
    run_py(cfg, frames[:60], "openratslam")  # warm-up: imports, compiled kernels
    cpp_runs: list[dict] = []
    py_runs: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(rounds):
            cpp_runs.append(run_cpp(build, data, Path(tmp) / f"cpp{i}"))
            py_runs.append(run_py(cfg, frames, "openratslam"))
        same_map = compare_maps(Path(tmp) / "cpp0", data, py_runs[0]["slam"])
    for r in py_runs:
        r.pop("slam")
    return {
        "name": ds.name,
        "spec": ds.spec,
        "frames": len(frames),
        "cpp": cpp_runs,
        "py": py_runs,
        "ratios": [c["total_ms_mean"] / p["total"] for c, p in zip(cpp_runs, py_runs)],
        "cpu_ratios": [c["loop_cpu_s"] / p["cpu_s"] for c, p in zip(cpp_runs, py_runs)],
        "same_map": same_map,
    }


def compare_maps(cpp: Path, data: Path, slam: Any) -> dict[str, Any]:
    """torchratslam's map against the C++'s run in ``cpp``: experience and link counts,
    the largest distance between their final poses, and each ATE (the same code for both,
    frames >= 1 against ``data``'s ground truth); ``same`` when the counts are equal, the
    poses within 1e-9 m and the ATEs within 1e-9 m."""
    from benchmarks.bench_openratslam import _ate_cpp, _ate_py

    ex = read_csv(cpp / "experiences.csv")
    links = read_csv(cpp / "links.csv")
    g = read_csv(data / "groundtruth.csv")
    gt = np.stack([g["x"], g["y"]], 1)
    poses = np.asarray(slam.experience_map.poses)
    counts = (len(ex["x"]), len(links[next(iter(links))]), len(poses), int(slam.counts()[2]))
    err = None
    if counts[0] == counts[2]:
        err = float(np.hypot(poses[:, 0] - ex["x"], poses[:, 1] - ex["y"]).max(initial=0.0))
    ate = (_ate_cpp(cpp, gt), _ate_py(slam, gt))
    same = (
        counts[0] == counts[2]
        and counts[1] == counts[3]
        and err is not None
        and err < 1e-9
        and abs(ate[0] - ate[1]) < 1e-9
    )
    return {"counts": counts, "pose_err_m": err, "ate": ate, "same": same}


def same_map_text(m: dict[str, Any]) -> str:
    """The "same map as the C++" cell: yes/no, counts, poses, ATEs."""
    ce, cl, pe, pl = m["counts"]
    poses = "-" if m["pose_err_m"] is None else f"{m['pose_err_m']:.0e} m"
    return (
        f"{'**yes**' if m['same'] else '**no**'}: experiences {pe}/{ce}, links {pl}/{cl}, "
        f"final poses within {poses}, ATE {m['ate'][1]:.6f} / {m['ate'][0]:.6f} m"
    )


def _med(runs: list[dict], key: str) -> float:
    return float(np.median([r[key] for r in runs]))


def stage_rows(res: dict[str, Any]) -> list[tuple[str, float, float]]:
    """(stage, C++ ms/frame, torchratslam ms/frame), medians over the rounds."""
    cpp, py, n = res["cpp"], res["py"], res["frames"]
    return [
        ("local view", _med(cpp, "lv_ms_mean"), _med(py, "lv")),
        ("pose cells", _med(cpp, "pc_ms_mean"), _med(py, "pc")),
        ("experience map", _med(cpp, "em_ms_mean"), _med(py, "em")),
        ("odometry source", float("nan"), _med(py, "odo")),
        ("module total", _med(cpp, "total_ms_mean"), _med(py, "total")),
        (
            "loop wall",
            _med(cpp, "loop_wall_s") * 1000.0 / n,
            _med(py, "wall_s") * 1000.0 / n,
        ),
        (
            "loop CPU time",
            _med(cpp, "loop_cpu_s") * 1000.0 / n,
            _med(py, "cpu_s") * 1000.0 / n,
        ),
    ]


# ----------------------------------------------------------------------------- suburb
def suburb_side_by_side(build: Path, frames: int, root: Path) -> dict[str, Any]:
    """C++, torchratslam default and the long-run configuration on the suburb, each in
    a fresh process (peak memory, cost per tenth, ATE)."""
    data = bench_scale.dataset(frames, root)
    runs: dict[str, dict[str, Any]] = {}
    cpp_out = root / f"scale-cpp-{frames}"
    cpp = bench_scale.run_cpp(build, data, cpp_out)
    if cpp is not None:
        cpp["modules"] = _cpp_module_means(cpp_out)
        runs["OpenRatSLAM C++"] = cpp
    for label, sets, slug in (
        ("torchratslam (default)", ["behaviour=openratslam"], "default"),
        ("torchratslam, long runs (" + " + ".join(LONG_RUN[1:]) + ")", list(LONG_RUN), "long"),
    ):
        out = root / f"speed-py-{slug}-{frames}"
        r = bench_scale.run_py(data, sets, out)
        r["modules"] = _py_module_means(out)
        runs[label] = r
    images_mb = frames * _image_bytes(data) / 2**20
    return {
        "frames": frames,
        "data": data,
        "runs": runs,
        "images_mb": images_mb,
        "fixed_mb": _fixed_memory(data, root),
        "fixed_parts": _fixed_parts(data),
    }


def _fixed_memory(data: Path, root: Path) -> float:
    """Peak memory (MiB) of the default run's command on the first 3 frames: what every
    run costs before its map (the interpreter, torch, numba and the compiled kernels it
    loads, the figures it writes)."""
    out = root / "speed-py-fixed"
    cmd = [sys.executable, "-m", "torchratslam", "run", "--config", str(data / "config.txt")]
    cmd += ["--data", str(data), "--out", str(out), "--no-progress", "--overwrite"]
    cmd += ["--max-frames", "3", "--set", "behaviour=openratslam"]
    out.mkdir(parents=True, exist_ok=True)
    return bench_scale.run_peak(cmd, out / "stdout.log")[1]


def _fixed_parts(data: Path) -> list[tuple[str, float]]:
    """The 3-frame run's peak after each of its parts, in one fresh process
    (:func:`benchmarks.bench_memory.measure`): set up (torch, the readers), mapped
    (numba and the compiled kernels the frames load), figures written."""
    from benchmarks import bench_memory

    rows = bench_memory.measure(bench_memory.STEPS[:1], data, 3)["rows"]
    keep = {
        "run: set up": "when set up (Python, torch, the reader)",
        "run: 3 frames mapped": "after 3 frames (+ numba and its kernels)",
        "run: figures written": "after the figures (+ matplotlib)",
    }
    return [(keep[label], mb) for label, mb in rows if label in keep]


def _py_module_means(out: Path) -> dict[str, float]:
    import json

    m = json.loads((out / "metrics.json").read_text())["ms_per_frame"]
    return {k: float(v["mean_ms"]) for k, v in m.items()}


def _cpp_module_means(out: Path) -> dict[str, float]:
    s = dict(line.split("=", 1) for line in (out / "summary.txt").read_text().splitlines())
    return {
        "local_view": float(s["lv_ms_mean"]),
        "pose_cells": float(s["pc_ms_mean"]),
        "experience_map": float(s["em_ms_mean"]),
        "total": float(s["total_ms_mean"]),
    }


def _image_bytes(data: Path) -> int:
    import cv2

    first = min((data / "frames").glob("*.png"))
    img = cv2.imread(str(first), cv2.IMREAD_UNCHANGED)
    return 0 if img is None else int(img.nbytes)


# ----------------------------------------------------------------------------- imports
IMPORT_PROBES = (
    ("Python alone", "pass"),
    ("import torchratslam", "import torchratslam"),
    ("import torch", "import torch"),
    ("from torchratslam import RatSLAM", "from torchratslam import RatSLAM"),
)

_PROBE = (
    "import time\n"
    "t0 = time.perf_counter()\n"
    "{stmt}\n"
    "t = time.perf_counter() - t0\n"
    "import resource\n"
    "peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
    "try:\n"
    "    for line in open('/proc/self/status'):\n"
    "        if line.startswith('VmHWM:'):\n"
    "            peak = int(line.split()[1])\n"
    "except OSError:\n"
    "    pass\n"
    "print(t, peak)\n"
)
"""A fresh process importing ``stmt``: its import time and peak RSS (KiB). ``VmHWM``
(the peak of this process image) rather than ``ru_maxrss``, which Linux carries over
``exec`` from the process that started it."""


def import_cost(repeats: int = 3) -> list[tuple[str, float, float]]:
    """(probe, import ms, peak RSS MiB) of each :data:`IMPORT_PROBES` in a fresh process
    (median of ``repeats``; the first run is a warm-up of the file cache)."""
    rows = []
    for label, stmt in IMPORT_PROBES:
        cmd = [sys.executable, "-c", _PROBE.format(stmt=stmt)]
        subprocess.run(cmd, check=True, capture_output=True)
        ts, rss = [], []
        for _ in range(repeats):
            out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout.split()
            ts.append(float(out[0]) * 1000.0)
            rss.append(float(out[1]) / 1024.0)
        rows.append((label, statistics.median(ts), statistics.median(rss)))
    return rows


# ----------------------------------------------------------------------------- output
def _f(v: float | None, fmt: str = ".3f") -> str:
    return "-" if v is None or not np.isfinite(v) else format(v, fmt)


def print_loops(results: list[dict[str, Any]]) -> None:
    print("### Speed: both systems on the same frames\n")
    print(
        "| sequence | frames | templates / experiences / links (C++; torchratslam) | "
        "same map as the C++ (torchratslam / C++) | "
        "C++ ms/frame | torchratslam ms/frame | **ratio C++ / torchratslam** | per round | "
        "ratio of loop CPU times |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for r in results:
        c, p = r["cpp"][0], r["py"][0]
        counts = (
            f"{int(c['templates'])} / {int(c['experiences'])} / {int(c['links'])}; "
            f"{p['templates']} / {p['experiences']} / {p['links']}"
        )
        print(
            f"| {r['name']} (`{r['spec']}`) | {r['frames']} | {counts} | "
            f"{same_map_text(r['same_map'])} | "
            f"{_med(r['cpp'], 'total_ms_mean'):.3f} | {_med(r['py'], 'total'):.3f} | "
            f"**{np.median(r['ratios']):.2f}x** | {', '.join(f'{x:.2f}' for x in r['ratios'])} | "
            f"{np.median(r['cpu_ratios']):.2f}x |"
        )
    print("\n### Per stage (ms/frame, median of rounds)\n")
    print("| sequence | stage | C++ | torchratslam | C++ / torchratslam |")
    print("|---|---|---|---|---|")
    for r in results:
        for stage, c, p in stage_rows(r):
            ratio = c / p if np.isfinite(c) and p > 0 else float("nan")
            print(f"| {r['name']} | {stage} | {_f(c)} | {_f(p)} | {_f(ratio, '.2f')} |")
    print()


def print_suburb(
    res: dict[str, Any], imports: list[tuple[str, float, float]] | None = None
) -> None:
    from torchratslam.eval.scale import format_scale_table

    runs = res["runs"]
    cpp = runs.get("OpenRatSLAM C++")
    print(f"### Suburb, {res['frames']} frames, one fresh process each ({res['data']})\n")
    print(
        "| system | module time s (ms/frame) | local view | pose cells | experience map | "
        "last / first tenth (total; local view; experience map) | peak memory MiB | ATE m | "
        "**speed vs C++** |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for label, r in runs.items():
        rep, m = r["report"], r["modules"]
        lof = rep["last_over_first"]
        speed = cpp["total_ms"] / r["total_ms"] if cpp else float("nan")
        print(
            f"| {label} | {r['total_ms'] / 1000:.1f} ({r['total_ms'] / res['frames']:.2f}) | "
            f"{m['local_view']:.3f} | {m['pose_cells']:.3f} | {m['experience_map']:.3f} | "
            f"{lof['total']:.2f}x; {lof.get('local_view', float('nan')):.2f}x; "
            f"{lof.get('experience_map', float('nan')):.2f}x | {rep['peak_memory_mb']:.0f} | "
            f"{r['ate_m']:.2f} | **{speed:.2f}x** |"
        )
    print(
        f"\nThe C++'s peak holds every frame decoded before its loop "
        f"({res['images_mb']:.0f} MiB of images); torchratslam reads frames as it goes. "
        f"torchratslam's figures include its odometry source and the run's outputs.\n"
    )
    print_memory(res, imports or [])
    for label, r in runs.items():
        print(format_scale_table(r["report"], title=label) + "\n")


def memory_rows(
    res: dict[str, Any], imports: list[tuple[str, float, float]]
) -> list[tuple[str, float]]:
    """(what, peak MiB) of the suburb's memory table: each system's whole run, the C++'s
    peak plus what importing torch alone peaks at, the run command on 3 frames (the fixed
    cost) and its parts (``fixed_parts``: the peak after setting up, after the first
    frames, after the figures)."""
    rows: list[tuple[str, float]] = []
    runs = res["runs"]
    cpp = runs.get("OpenRatSLAM C++")
    torch_mb = dict((label, mb) for label, _, mb in imports).get("import torch")
    for label, r in runs.items():
        rows.append((f"{label}, {res['frames']} frames", float(r["report"]["peak_memory_mb"])))
    if torch_mb is not None:
        rows.append(("`import torch` alone (Python, numpy, torch)", float(torch_mb)))
        if cpp is not None:
            rows.append(
                ("the C++'s peak + torch's import", cpp["report"]["peak_memory_mb"] + torch_mb)
            )
    if res.get("fixed_mb") is not None:
        rows.append(
            ("torchratslam's run command on 3 frames (the fixed cost)", float(res["fixed_mb"]))
        )
    for label, mb in res.get("fixed_parts", []):
        rows.append((f"  of which, peak {label}", float(mb)))
    return rows


def print_memory(res: dict[str, Any], imports: list[tuple[str, float, float]]) -> None:
    print("### Memory on the suburb (peak RSS, one fresh process each)\n")
    print("| what | peak MiB |")
    print("|---|---|")
    for label, mb in memory_rows(res, imports):
        print(f"| {label} | {mb:.0f} |")
    print()


def print_imports(rows: list[tuple[str, float, float]]) -> None:
    print("### What importing costs (fresh process each, median of 3)\n")
    print("| import | time ms | peak RSS MiB |")
    print("|---|---|---|")
    for label, ms, mb in rows:
        print(f"| {label} | {ms:.0f} | {mb:.0f} |")
    print()


def main(
    quick: bool = False,
    out: Path | None = None,
    rounds: int | None = None,
    sequences: tuple[str, ...] = SEQUENCES,
    suburb_frames: int | None = None,
) -> None:
    """Run the report of :func:`plan` and print it (Markdown)."""
    p = plan(quick, out, rounds, sequences, suburb_frames)
    build = find_build()
    if build is None:
        print(BUILD_HELP)
        return
    p.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    print(f"OpenRatSLAM build: {build}; data and runs under {p.out}")
    print(f"{'quick check' if quick else 'full report'}: {p.rounds} alternated round(s)\n")
    import torch

    torch.set_num_threads(1)
    loops = []
    for ds in p.loops:
        print(f"[speed] {ds.name}", file=sys.stderr, flush=True)
        loops.append(loop_side_by_side(build, ds, p.out, p.rounds))
    if loops:
        print_loops(loops)
    imports = import_cost()
    if p.suburb_frames:
        print(f"[speed] suburb, {p.suburb_frames} frames", file=sys.stderr, flush=True)
        print_suburb(suburb_side_by_side(build, p.suburb_frames, p.out), imports)
    print_imports(imports)
    print("[speed] sweep, grouped against separate runs", file=sys.stderr, flush=True)
    from benchmarks import bench_sweep

    bench_sweep.print_cli_table(bench_sweep.measure_cli(p.out, quick))
    print(
        f"(speed report: {time.perf_counter() - t0:.0f} s; load average "
        f"{load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the end)"
    )


__all__ = ["Plan", "main", "plan"]
