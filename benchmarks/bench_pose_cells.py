"""Pose-cell network: milliseconds per full step, three ways to compute the dynamics.

A full step is OpenRatSLAM's ``on_odo``: excite, inhibit, global inhibition, normalise,
path integration, packet centre. Networks 11x11x36, 21x21x36, 30x30x36, 80x80x36 with
B=1 and B=32 (one batched network object), float32, single thread, median over many
steps with a realistic single packet per network (settled, then moving with odometry;
the B=32 networks each get their own position and odometry).

Methods (``PoseCellNetwork(method=...)``):

* ``conv3d``: circular 3D convolution (``F.pad(mode="circular")`` + ``F.conv3d``);
* ``separable``: three 1D circular convolutions per kernel, as small matrix products;
* ``crop``: ``separable`` on a box around the packet plus a halo, exact because every
  cell outside it is zero; falls back to ``separable`` when the box is not small;
* ``numpy`` (the default for one CPU network): the crop in numpy, with a smaller halo
  (the excitation's reach) and no tensor wrapping.

With ``OPENRATSLAM_BUILD`` set to a build of ``shared/tools/openratslam`` (holding
``ratslam_driver``), it also runs OpenRatSLAM's C++ side by side on the same data: the
project's simulated loop tour with a 21x21x36 network, C++ and torchratslam alternated,
per-frame pose-cell milliseconds (C++: the driver's own ``pc_ms``, on_view_template +
on_odo + get_action; torchratslam: ``on_view_template`` + ``on_odometry``), and the
median of the per-pair ratios of the means.

The C++ reference (OpenRatSLAM) needs about 0.61 ms per step for 21x21x36 (B=1).
``BENCH_QUICK=1`` takes fewer steps and skips ``conv3d`` for the largest cases. The
default, ``method="auto"``, picks ``crop`` or ``separable`` per network size and batch.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from torchratslam.config import PoseCellParams
from torchratslam.messages import ViewMatch
from torchratslam.pose_cells.network import PoseCellNetwork
from torchratslam.pose_cells.stage import PoseCells

SIZES = (11, 21, 30, 80)
BATCHES = (1, 32)
METHODS = ("conv3d", "separable", "crop", "numpy")
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
            auto_net = PoseCellNetwork(PoseCellParams(pc_dim_xy=xy, pc_dim_th=36), batch)
            auto = "numpy" if auto_net.uses_numpy else auto_net.method
            for method in METHODS:
                if method == "numpy" and batch > 1:
                    continue
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


def _openratslam_txt(cfg: Any, path: Path) -> None:
    """An OpenRatSLAM ``[ratslam]`` config from a torchratslam config (numbers only;
    OpenRatSLAM reads the kernel variances as int)."""
    lines = ["[ratslam]"]
    for k, v in cfg.to_flat().items():
        if isinstance(v, str):
            continue
        if k in ("pc_w_e_var", "pc_w_i_var"):
            v = int(v)
        lines.append(f"{k}={int(v) if isinstance(v, bool) else v}")
    path.write_text("\n".join(lines) + "\n")


def _replay_ms(cfg: Any, frames: dict[str, np.ndarray], odo: np.ndarray, dtype: Any):
    """torchratslam's pose cells on the C++ run's (template, angle) sequence: per-frame
    ms (frames >= 1) and the actions."""
    pc = PoseCells(cfg.pose_cells, dtype=dtype)
    ms, acts = [], []
    t = odo[:, 0]
    for k in range(len(frames["vt_id"])):
        match = ViewMatch(
            template_id=int(frames["vt_id"][k]), relative_rad=float(frames["vt_rad"][k])
        )
        t0 = time.perf_counter()
        pc.on_view_template(match)
        act = 0
        if k > 0:
            act = int(
                pc.on_odometry(float(odo[k, 1]), float(odo[k, 2]), float(t[k] - t[k - 1])).kind
            )
        ms.append((time.perf_counter() - t0) * 1e3)
        acts.append(act)
    return np.array(ms[1:]), np.array(acts)


def side_by_side(build: Path, pairs: int = 3, frames_n: int = 700) -> None:
    """OpenRatSLAM's pose cells (its driver's pc_ms) against torchratslam's, same data."""
    from torchratslam.config import load_config

    driver = build / "ratslam_driver"
    cfg = load_config(
        "lab_tour",
        pc_dim_xy=21,
        pc_dim_th=36,
        pc_cell_x_size=0.25,
        pc_vt_inject_energy=0.15,
        exp_delta_pc_threshold=2.0,
    )
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        subprocess.run(
            [
                sys.executable,
                "-m",
                "torchratslam",
                "simulate",
                "loop",
                "--out",
                str(root / "data"),
                "--max-frames",
                str(frames_n),
                "--quiet",
            ],
            check=True,
            capture_output=True,
        )
        _openratslam_txt(cfg, root / "config.txt")
        odo = np.loadtxt(root / "data" / "odometry.csv", delimiter=",", skiprows=1, ndmin=2)
        rows = []
        for i in range(pairs):
            out = root / f"cpp{i}"
            out.mkdir()
            with open(out / "stdout.log", "w") as log:
                subprocess.run(
                    [str(driver), str(root / "config.txt"), str(root / "data"), str(out)],
                    check=True,
                    stdout=log,
                    stderr=subprocess.DEVNULL,
                )
            with open(out / "frames.csv") as f:
                head = f.readline().strip().split(",")
            a = np.loadtxt(out / "frames.csv", delimiter=",", skiprows=1, ndmin=2)
            fr = {h: a[:, j] for j, h in enumerate(head)}
            cpp = fr["pc_ms"][1:]
            row = {"cpp": cpp}
            for name, dt in (("f64", torch.float64), ("f32", torch.float32)):
                ms, acts = _replay_ms(cfg, fr, odo, dt)
                row[name], row[name + "_same"] = ms, int((acts == fr["action"]).sum())
            rows.append(row)
    n = len(rows[0]["cpp"]) + 1
    print(
        f"\nside by side, pose cells only, 21x21x36, loop tour {n} frames, {pairs} alternated pairs"
    )
    print("(ms per frame, mean / median over frames >= 1; ratio = C++ mean / torchratslam mean)\n")
    print(
        "| run | OpenRatSLAM C++ | torchratslam f64 | ratio | torchratslam f32 | ratio "
        "| actions equal f64 / f32 |"
    )
    print("|---|---|---|---|---|---|---|")
    r64, r32, m64, m32 = [], [], [], []
    for i, r in enumerate(rows):
        r64.append(r["cpp"].mean() / r["f64"].mean())
        r32.append(r["cpp"].mean() / r["f32"].mean())
        m64.append(np.median(r["cpp"]) / np.median(r["f64"]))
        m32.append(np.median(r["cpp"]) / np.median(r["f32"]))
        print(
            f"| {i} | {r['cpp'].mean():.3f} / {np.median(r['cpp']):.3f} | "
            f"{r['f64'].mean():.3f} / {np.median(r['f64']):.3f} | {r64[-1]:.2f}x | "
            f"{r['f32'].mean():.3f} / {np.median(r['f32']):.3f} | {r32[-1]:.2f}x | "
            f"{r['f64_same']}/{n} / {r['f32_same']}/{n} |"
        )
    print(
        f"\nmedian of per-pair ratios: float64 {np.median(r64):.2f}x, "
        f"float32 {np.median(r32):.2f}x "
        "(> 1: torchratslam's pose cells are faster); of the per-frame medians: "
        f"float64 {np.median(m64):.2f}x, float32 {np.median(m32):.2f}x"
    )


def main() -> None:
    torch.set_num_threads(1)
    quick = os.environ.get("BENCH_QUICK", "") not in ("", "0")
    build = os.environ.get("OPENRATSLAM_BUILD", "")
    if build and (Path(build) / "ratslam_driver").exists():
        side_by_side(Path(build), pairs=2 if quick else 3)
    else:
        print(
            "(no OpenRatSLAM side by side: build it with shared/tools/openratslam/build.sh "
            "and set OPENRATSLAM_BUILD to the build directory)\n"
        )
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
