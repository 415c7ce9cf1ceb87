"""End-to-end pipeline benchmark: the reference check on a simulated panoramic loop.

The C++ reference (OpenRatSLAM) on a panoramic 256x64 loop sequence (1781 frames, 6
laps) with template 64x16, vt_panoramic=1, vt_shift_match=4, vt_step_match=1,
vt_match_threshold=0.06, pc_dim_xy=21, pc_cell_x_size=0.25, pc_vt_inject_energy=0.1,
exp_delta_pc_threshold=2, exp_loops=20 needed 4.9 ms per frame (LV 4.25, PC 0.61,
EM 0.06), with 0.45 m ATE, 271 templates and 347 experiences; dead reckoning 1.76 m.

Here the simulator's ``loop`` tour (a 12 x 8 m corridor loop driven 6 times, 1781
panoramic 256x64 frames, noisy odometry) is run with the same parameters, single
thread. Frames are rendered before timing; module times exclude reading. The
pipelined mode (one thread per module) is run too and checked to give the same map.
``BENCH_QUICK=1`` runs the first 400 frames only.
"""

from __future__ import annotations

import os
import time

import numpy as np
import torch

REFERENCE = {
    "local_view": 4.25,
    "pose_cells": 0.61,
    "experience_map": 0.06,
    "total": 4.9,
    "ate_m": 0.45,
    "templates": 271,
    "experiences": 347,
    "dead_reckoning_m": 1.76,
}

PARAMS = {
    "template_x_size": 64,
    "template_y_size": 16,
    "vt_panoramic": 1,
    "vt_shift_match": 4,
    "vt_step_match": 1,
    "vt_match_threshold": 0.06,
    "pc_dim_xy": 21,
    "pc_cell_x_size": 0.25,
    "pc_vt_inject_energy": 0.1,
    "exp_delta_pc_threshold": 2,
    "exp_loops": 20,
}


def _frames(quick: bool) -> tuple[list, object]:
    from torchratslam.sim import get_tour

    session = get_tour("loop", seed=0).full()
    n = 400 if quick else len(session)
    return list(session.frames(0, n)), session


def run_once(frames: list, *, pipelined: bool = False, backend: str = "alpha") -> tuple:
    from torchratslam.config import load_config
    from torchratslam.pipeline import RatSLAM

    cfg = load_config(None, **PARAMS, exp_backend=backend)
    slam = RatSLAM(cfg, pipelined=pipelined)
    t0 = time.perf_counter()
    result = slam.run(frames, progress=False)
    wall = time.perf_counter() - t0
    return slam, result, wall


def main() -> None:
    torch.set_num_threads(1)
    quick = os.environ.get("BENCH_QUICK", "") not in ("", "0")
    frames, _ = _frames(quick)
    slam, res, wall = run_once(frames)
    s = res.timings
    ate = slam.ate()
    dr = slam.dead_reckoning_ate()
    print(
        f"simulated loop: {len(frames)} panoramic 256x64 frames, reference parameters, 1 thread\n"
    )
    print("| | torchratslam | C++ reference |")
    print("|---|---|---|")
    for name in ("local_view", "pose_cells", "experience_map"):
        print(
            f"| {name} ms/frame (mean / median) | {s[name]['mean_ms']:.3f} / "
            f"{s[name]['median_ms']:.3f} | {REFERENCE[name]} |"
        )
    print(f"| odometry ms/frame (mean) | {s['odometry']['mean_ms']:.3f} | - |")
    print(f"| total ms/frame (mean) | {s['total']['mean_ms']:.3f} | {REFERENCE['total']} |")
    print(f"| wall time (s) | {wall:.2f} | - |")
    print(f"| templates | {res.templates} | {REFERENCE['templates']} |")
    print(f"| experiences | {res.experiences} | {REFERENCE['experiences']} |")
    print(f"| links | {res.links} | - |")
    print(f"| ATE (m) | {ate:.3f} | {REFERENCE['ate_m']} |")
    print(f"| dead reckoning ATE (m) | {dr:.3f} | {REFERENCE['dead_reckoning_m']} |")
    speedup = REFERENCE["total"] / max(s["total"]["mean_ms"], 1e-9)
    print(f"\nspeed vs the reference: {speedup:.2f}x per frame (timings noisy on a shared machine)")

    slam_p, _, wall_p = run_once(frames, pipelined=True)
    same = np.array_equal(
        slam.experience_map.poses, slam_p.experience_map.poses
    ) and np.array_equal(slam.trajectory(), slam_p.trajectory(), equal_nan=True)
    print(
        f"pipelined mode: wall {wall_p:.2f} s vs sequential {wall:.2f} s "
        f"({'faster' if wall_p < wall else 'not faster'} here); same map: {same}"
    )


if __name__ == "__main__":
    main()
