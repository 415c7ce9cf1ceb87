"""Pose-cell network: milliseconds per full step, three ways to compute the dynamics.

A full step is OpenRatSLAM's ``on_odo``: excite, inhibit, global inhibition, normalise,
path integration, packet centre. Networks 11x11x36, 21x21x36, 30x30x36, 80x80x36 with
B=1 and B=32 (one batched network object), float32, single thread, median over many
steps with a realistic single packet per network (settled, then moving with odometry;
the B=32 networks each get their own position and odometry).

Methods (``PoseCellNetwork(method=...)``):

* ``conv3d``: circular 3D convolution (``F.pad(mode="circular")`` + ``F.conv3d``);
* ``separable``: three 1D circular convolutions per kernel, as small matrix products;
* ``crop`` (the default): ``separable`` on a box around the packet plus a halo, exact
  because every cell outside it is zero; falls back to ``separable`` when the box is
  not small.

The C++ reference (OpenRatSLAM) needs about 0.61 ms per step for 21x21x36 (B=1).
``BENCH_QUICK=1`` takes fewer steps and skips ``conv3d`` for the largest cases. The
default, ``method="auto"``, picks ``crop`` or ``separable`` per network size and batch.
"""

from __future__ import annotations

import os
import time

import numpy as np
import torch

from torchratslam.config import PoseCellParams
from torchratslam.pose_cells.network import PoseCellNetwork

SIZES = (11, 21, 30, 80)
BATCHES = (1, 32)
METHODS = ("conv3d", "separable", "crop")
REFERENCE_MS_21 = 0.61


def _network(xy: int, batch: int, method: str, seed: int = 0) -> tuple[PoseCellNetwork, np.ndarray]:
    """A network with settled packets at random cells and per-network odometry."""
    rng = np.random.default_rng(seed)
    net = PoseCellNetwork(PoseCellParams(pc_dim_xy=xy, pc_dim_th=36), batch, method=method)
    if batch > 1:
        a = torch.zeros_like(net.activity)
        cells = rng.integers(0, [36, xy, xy], (batch, 3))
        a[torch.arange(batch), cells[:, 0], cells[:, 1], cells[:, 2]] = 1.0
        net.set_activity(a)
    odo = np.stack(
        [rng.uniform(0.2, 1.0, batch), rng.uniform(-0.05, 0.05, batch), np.ones(batch)], axis=1
    )
    if batch == 1:
        odo[0] = (0.5, 0.02, 1.0)
    for _ in range(20):
        net.step(0.0, 0.0, 1.0)
    for _ in range(10):
        net.step(odo[:, 0], odo[:, 1], odo[:, 2])
    return net, odo


def time_steps(
    net: PoseCellNetwork, odo: np.ndarray, budget_s: float, max_steps: int
) -> tuple[float, float]:
    """Median wall-clock and median process-CPU milliseconds per step."""
    wall, cpu = [], []
    start = time.perf_counter()
    if len(odo) > 1:
        v, w, dt = odo[:, 0], odo[:, 1], odo[:, 2]
    else:
        v, w, dt = float(odo[0, 0]), float(odo[0, 1]), float(odo[0, 2])
    while len(wall) < max_steps and (len(wall) < 3 or time.perf_counter() - start < budget_s):
        t0, c0 = time.perf_counter(), time.process_time()
        net.step(v, w, dt)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return float(np.median(wall)) * 1e3, float(np.median(cpu)) * 1e3


def measure(quick: bool = False) -> list[dict]:
    """One row per (size, batch, method): wall and CPU ms per step, the box, and the
    method that ``"auto"`` (the default) picks for that network."""
    rows = []
    for xy in SIZES:
        for batch in BATCHES:
            auto = PoseCellNetwork(PoseCellParams(pc_dim_xy=xy, pc_dim_th=36), batch).method
            for method in METHODS:
                if quick and method == "conv3d" and xy * batch > 30 * 32:
                    continue
                net, odo = _network(xy, batch, method)
                budget = 0.5 if quick else 1.5
                wall, cpu = time_steps(net, odo, budget, 100 if quick else 400)
                rows.append(
                    {
                        "size": f"{xy}x{xy}x36",
                        "B": batch,
                        "method": method,
                        "ms": wall,
                        "cpu_ms": cpu,
                        "box": net.last_crop,
                        "auto": auto,
                    }
                )
    return rows


def main() -> None:
    torch.set_num_threads(1)
    quick = os.environ.get("BENCH_QUICK", "") not in ("", "0")
    rows = measure(quick)
    by = {(r["size"], r["B"], r["method"]): r for r in rows}
    print("ms per full pose-cell step: median wall clock (median process CPU); float32;")
    print("1 thread; B networks per call; default = method 'auto' [its pick]\n")
    head = (
        "| network | B | " + " | ".join(METHODS) + " | default | default per network | B=32/B=1 |"
    )
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    for xy in SIZES:
        size = f"{xy}x{xy}x36"
        for batch in BATCHES:
            cells = [by.get((size, batch, m)) for m in METHODS]
            txt = [f"{c['ms']:.3f} ({c['cpu_ms']:.3f})" if c else "-" for c in cells]
            auto = next(c["auto"] for c in cells if c)
            d = by[(size, batch, auto)]
            ratio = ""
            if batch > 1:
                one = by[(size, 1, by[(size, 1, "crop")]["auto"])]
                ratio = f"{d['ms'] / one['ms']:.1f}x ({d['cpu_ms'] / one['cpu_ms']:.1f}x)"
            print(
                f"| {size} | {batch} | "
                + " | ".join(txt)
                + f" | {d['ms']:.3f} [{auto}] | {d['ms'] / batch:.3f} | {ratio} |"
            )
    d21 = by[("21x21x36", 1, by[("21x21x36", 1, "crop")]["auto"])]
    print(
        f"\n21x21x36, B=1, default: {d21['ms']:.3f} ms per step ({d21['cpu_ms']:.3f} ms CPU); "
        f"OpenRatSLAM (C++): about {REFERENCE_MS_21} ms."
    )
    boxes = {r["size"]: r["box"] for r in rows if r["method"] == "crop" and r["B"] == 1}
    print("crop box (theta, y, x) at B=1: " + ", ".join(f"{k}: {v}" for k, v in boxes.items()))
    print("(a shared machine's load changes timings: compare columns within one run)")


if __name__ == "__main__":
    main()
