"""Sweeps: B configurations that differ only in pose-cell module and experience-map
parameters (``pc_vt_inject_energy``, ``exp_delta_pc_threshold``, ``exp_correction``), run
as B separate runs against one group (frames, odometry and local view computed once; B
pose-cell modules and B experience maps), in the default behaviour (OpenRatSLAM's: each
run's network steps alone in numpy, as a separate run's does). With the torch step
(``pc_engine: torch``) and 21x21x36 pose cells (OpenRatSLAM's size, whole-network
dynamics) the group steps one PoseCellNetwork with B networks per frame.

Both sides run in this process, one after the other, on the same frames of two laps of
the loop tour with the virtual_tour config, single thread; the group's rows must equal
the separate runs' (checked here too). Throughput is run-frames per second of
wall-clock time (B x frames / seconds). ``BENCH_QUICK=1`` uses fewer frames and
smaller groups.

:func:`measure_cli` times the same 16 combinations from the command line
(``torchratslam sweep FILE --workers 1`` against ``--no-batch``, one fresh process each,
import and compilation cache included) on the whole loop (``sim:loop``, 1781 frames),
with the virtual_tour config and with the loop's OpenRatSLAM comparison config, and
says how many of the 16 results (experiences, links, ATE) differ.
"""

from __future__ import annotations

import csv
import os
import subprocess
import sys
import time
from pathlib import Path

import torch

from torchratslam.pose_cells.stage import PoseCells
from torchratslam.sweeps.runner import TIMING_COLUMNS, run_group, run_one, shares_network
from torchratslam.sweeps.spec import from_dict

DATA = "sim:loop?laps=2&frames={frames}&lasers=0"
ENERGIES = (0.02, 0.06, 0.15, 0.3)
THRESHOLDS = (2.0, 4.0)
CORRECTIONS = (0.5, 0.7)
TORCH_STEP = {"pc_engine": "torch", "skip_first_odometry": False}


def _runs(batch: int, frames: int, cells: tuple[int, int], behaviour: dict) -> list:
    combos = [(e, t, c) for c in CORRECTIONS for t in THRESHOLDS for e in ENERGIES][:batch]
    spec = from_dict(
        {
            "base": "virtual_tour",
            "set": {"pc_dim_xy": cells[0], "pc_dim_th": cells[1], **behaviour},
            "mode": "list",
            "parameters": {
                "pc_vt_inject_energy": [c[0] for c in combos],
                "exp_delta_pc_threshold": [c[1] for c in combos],
                "exp_correction": [c[2] for c in combos],
            },
            "datasets": [DATA.format(frames=frames)],
        }
    )
    return spec.runs()


def _strip(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in rows]


def measure(quick: bool = False, default_only: bool = False) -> list[dict]:
    """One row per case: wall seconds of B separate runs and of one group
    (``default_only``: the default behaviour's case only)."""
    frames = 120 if quick else 240
    out = []
    cases: list[tuple[tuple[int, int], dict, tuple[int, ...]]] = [
        ((21, 36), {}, (4,) if quick else (16,))
    ]
    if not (quick or default_only):
        cases.append(((21, 36), TORCH_STEP, (16,)))
        cases.append(((80, 35), {}, (8,)))
    run_one(_runs(1, 20, (21, 36), {})[0])  # warm up (first-call allocations, caches)
    for cells, behaviour, batches in cases:
        for batch in batches:
            runs = _runs(batch, frames, cells, behaviour)
            pc = runs[0].config().pose_cells
            t0 = time.perf_counter()
            separate = [run_one(r) for r in runs]
            t_sep = time.perf_counter() - t0
            t0 = time.perf_counter()
            grouped = run_group(runs)
            t_grp = time.perf_counter() - t0
            out.append(
                {
                    "cells": f"{cells[0]}x{cells[0]}x{cells[1]}",
                    "behaviour": "torch step" if behaviour else "default",
                    "shared": shares_network(PoseCells(pc).network, pc.pc_engine),
                    "B": batch,
                    "frames": frames,
                    "separate_s": t_sep,
                    "group_s": t_grp,
                    "pc_ms_separate": sum(r["ms_pose_cells"] for r in separate) / batch,
                    "pc_ms_group": grouped[0]["ms_pose_cells"],
                    "equal": _strip(separate) == _strip(grouped),
                }
            )
    return out


CLI_BASES = (
    ("virtual_tour", "virtual_tour", "exp_loops 250"),
    ("loop comparison", "loop.txt", "OpenRatSLAM's loop settings, exp_loops 20"),
)


def _combos() -> dict[str, list[float]]:
    combos = [(e, t, c) for c in CORRECTIONS for t in THRESHOLDS for e in ENERGIES]
    return {
        "pc_vt_inject_energy": [c[0] for c in combos],
        "exp_delta_pc_threshold": [c[1] for c in combos],
        "exp_correction": [c[2] for c in combos],
    }


def _sweep_file(folder: Path, base: str, frames: int | None) -> Path:
    import yaml

    data: dict = {"data": "sim:loop"}
    if frames is not None:
        data["max_frames"] = frames
    spec = {"base": base, "mode": "list", "parameters": _combos(), "datasets": [data]}
    path = folder / "sweep.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def _cli_sweep(spec: Path, out: Path, batch: bool) -> tuple[float, list[dict]]:
    cmd = [sys.executable, "-m", "torchratslam", "sweep", str(spec), "--out", str(out)]
    cmd += ["--workers", "1", "--no-figures", "--no-progress", "--overwrite"]
    if not batch:
        cmd.append("--no-batch")
    t0 = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        said = [ln.strip() for ln in done.stderr.splitlines() if ln.strip()]
        raise RuntimeError(f"torchratslam sweep exited {done.returncode}: {said[-1:]}")
    with (out / "results.csv").open(newline="") as fh:
        rows = [dict(r) for r in csv.DictReader(fh)]
    return wall, rows


def measure_cli(out: Path, quick: bool = False) -> list[dict]:
    """16 runs from the command line, separate (``--no-batch``) then grouped, for each
    base config of :data:`CLI_BASES`; one row each (wall seconds of both commands,
    whether the tables agree outside the timing columns, distinct results)."""
    from benchmarks.openratslam import LOOP_TXT

    frames = 300 if quick else None
    rows = []
    for name, base, what in CLI_BASES:
        folder = out / "sweep" / base.replace(".", "_")
        folder.mkdir(parents=True, exist_ok=True)
        if base.endswith(".txt"):
            (folder / base).write_text(LOOP_TXT.format(threshold=0.06))
            base = str(folder / base)
        spec = _sweep_file(folder, base, frames)
        t_sep, separate = _cli_sweep(spec, folder / "separate", batch=False)
        t_grp, grouped = _cli_sweep(spec, folder / "grouped", batch=True)
        results = {(r["experiences"], r["links"], r["ate_m"]) for r in separate}
        rows.append(
            {
                "config": f"{name} ({what})",
                "frames": int(separate[0]["frames"]),
                "runs": len(separate),
                "distinct": len(results),
                "separate_s": t_sep,
                "group_s": t_grp,
                "equal": _strip(separate) == _strip(grouped),
            }
        )
    return rows


def print_cli_table(rows: list[dict]) -> None:
    """The rows of :func:`measure_cli` as a Markdown table."""
    print(
        "16 runs (pc_vt_inject_energy x exp_delta_pc_threshold x exp_correction) from the "
        "command line,\n`torchratslam sweep FILE --workers 1` with `--no-batch` (separate) "
        "and without (grouped);\n'distinct results': different (experiences, links, ATE) "
        "among the 16.\n"
    )
    print(
        "| config | frames | runs | distinct results | separate (s) | grouped (s) | speed-up "
        "| same rows |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['config']} | {r['frames']} | {r['runs']} | {r['distinct']} | "
            f"{r['separate_s']:.1f} | {r['group_s']:.1f} | "
            f"{r['separate_s'] / r['group_s']:.2f}x | {'yes' if r['equal'] else 'NO'} |"
        )
    print()


def print_table(rows: list[dict]) -> None:
    """The rows of :func:`measure` as a Markdown table, with what they are."""
    print("B configurations differing in pc_vt_inject_energy / exp_delta_pc_threshold /")
    print(f"exp_correction on {rows[0]['frames']} frames of the loop tour (virtual_tour")
    print("config), 1 thread: B separate runs against one group.\n")
    print(
        "| behaviour | pose cells | one batched network | B | separate (s) | group (s) | "
        "run-frames/s separate | run-frames/s group | speed-up | pose cells ms/frame per "
        "run: separate / group | same rows |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        n = r["B"] * r["frames"]
        print(
            f"| {r['behaviour']} | {r['cells']} | {'yes' if r['shared'] else 'no'} | {r['B']} | "
            f"{r['separate_s']:.2f} | {r['group_s']:.2f} | "
            f"{n / r['separate_s']:.0f} | {n / r['group_s']:.0f} | "
            f"{r['separate_s'] / r['group_s']:.1f}x | {r['pc_ms_separate']:.2f} / "
            f"{r['pc_ms_group']:.2f} | {'yes' if r['equal'] else 'NO'} |"
        )
    print()


def main() -> None:
    torch.set_num_threads(1)
    quick = os.environ.get("BENCH_QUICK", "") not in ("", "0")
    print_table(measure(quick))
    print_cli_table(measure_cli(Path(os.environ.get("BENCH_OUT", "out/bench")), quick))


if __name__ == "__main__":
    main()
