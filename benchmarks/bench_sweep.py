"""Sweeps: B configurations that differ only in pose-cell module parameters, run as B
separate runs against one batched group (frames, odometry and local view computed
once; one PoseCellNetwork with B networks stepped per frame; B experience maps).

Both sides run in this process, one after the other, on the same frames of the loop
tour with the virtual_tour config (80x80x35 pose cells), single thread; the rows of
the group must equal the separate runs' (checked here too). Throughput is run-frames
per second of wall-clock time (B x frames / seconds). ``BENCH_QUICK=1`` uses fewer
frames and smaller groups.
"""

from __future__ import annotations

import os
import time

import torch

from torchratslam.sweeps.runner import TIMING_COLUMNS, run_group, run_one
from torchratslam.sweeps.spec import from_dict

DATA = "sim:loop?laps=2&frames={frames}&lasers=0"
ENERGIES = (0.02, 0.04, 0.06, 0.1, 0.15, 0.2, 0.3, 0.4)
THRESHOLDS = (2.0, 4.0)


def _runs(batch: int, frames: int) -> list:
    combos = [(e, t) for t in THRESHOLDS for e in ENERGIES][:batch]
    spec = from_dict(
        {
            "base": "virtual_tour",
            "mode": "list",
            "parameters": {
                "pc_vt_inject_energy": [c[0] for c in combos],
                "exp_delta_pc_threshold": [c[1] for c in combos],
            },
            "datasets": [DATA.format(frames=frames)],
        }
    )
    return spec.runs()


def _strip(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in rows]


def measure(quick: bool = False) -> list[dict]:
    """One row per group size B: wall seconds of B separate runs and of one group."""
    frames = 120 if quick else 300
    out = []
    run_one(_runs(1, 20)[0])  # warm up (first-call allocations, caches)
    for batch in (2, 4) if quick else (4, 8, 16):
        runs = _runs(batch, frames)
        t0 = time.perf_counter()
        separate = [run_one(r) for r in runs]
        t_sep = time.perf_counter() - t0
        t0 = time.perf_counter()
        grouped = run_group(runs)
        t_grp = time.perf_counter() - t0
        pc_sep = sum(r["ms_pose_cells"] for r in separate) / batch
        out.append(
            {
                "B": batch,
                "frames": frames,
                "separate_s": t_sep,
                "group_s": t_grp,
                "pc_ms_separate": pc_sep,
                "pc_ms_group": grouped[0]["ms_pose_cells"],
                "equal": _strip(separate) == _strip(grouped),
            }
        )
    return out


def main() -> None:
    torch.set_num_threads(1)
    quick = os.environ.get("BENCH_QUICK", "") not in ("", "0")
    rows = measure(quick)
    print("B configurations differing in pc_vt_inject_energy / exp_delta_pc_threshold on")
    print(f"{rows[0]['frames']} frames of the loop tour (virtual_tour config, 80x80x35 pose")
    print("cells), 1 thread: B separate runs against one batched group.\n")
    print(
        "| B | separate (s) | batched group (s) | run-frames/s separate | run-frames/s batched "
        "| speed-up | pose cells ms/frame per run: separate / batched | same rows |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        n = r["B"] * r["frames"]
        print(
            f"| {r['B']} | {r['separate_s']:.2f} | {r['group_s']:.2f} | "
            f"{n / r['separate_s']:.0f} | {n / r['group_s']:.0f} | "
            f"{r['separate_s'] / r['group_s']:.1f}x | {r['pc_ms_separate']:.2f} / "
            f"{r['pc_ms_group']:.2f} | {'yes' if r['equal'] else 'NO'} |"
        )


if __name__ == "__main__":
    main()
