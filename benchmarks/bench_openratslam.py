"""Side by side with OpenRatSLAM's C++: same data, same run, both behaviour profiles.

For each dataset of :data:`benchmarks.openratslam.BENCH_SETS` (the simulated loop tour,
and the loop lit differently on each lap, which needs 1000+ templates) the frames are
rendered once into a temporary dataset folder; then runs alternate: OpenRatSLAM's C++
(``ratslam_driver``: its three classes, unmodified, ``-O3``, driven synchronously as its
ROS nodes drive them, images decoded before the loop), torchratslam with
``behaviour: openratslam``, torchratslam with ``behaviour: torchratslam`` (one thread,
the default precision: double, frames decoded before the loop), and again,
``BENCH_PAIRS`` times (default 3).
Per-frame times are each run's mean of the per-module times (local view + pose cells +
experience map; torchratslam also times its odometry source); a speed ratio is C++
ms/frame over torchratslam ms/frame of the same round, and the table gives the median of
those ratios. Accuracy figures (ATE over frames >= 1, where OpenRatSLAM has an
experience) are computed by the same code for both. "same map" compares torchratslam's
openratslam profile with the C++: every action and the final experience poses.

Needs the C++ build: ``make bench OPENRATSLAM_BUILD=/path/to/build`` (the folder holding
``ratslam_driver``); without it the table is skipped and the build instructions printed.
``BENCH_QUICK=1``: 400 frames of each, one round.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.openratslam import (
    BENCH_SETS,
    BUILD_HELP,
    find_build,
    load_frames,
    read_csv,
    run_cpp,
    run_py,
    write_dataset_dir,
)

PROFILES = ("openratslam", "torchratslam")


def _ate_cpp(cpp: Path, gt: np.ndarray) -> float:
    from torchratslam.eval.metrics import ate_rmse

    fr = read_csv(cpp / "frames.csv")
    ex = read_csv(cpp / "experiences.csv")
    cur = fr["em_current_id"].astype(int)
    ok = (cur >= 0) & (fr["frame"] >= 1)
    est = np.stack([ex["x"], ex["y"]], 1)[cur[ok]]
    return float(ate_rmse(est, gt[fr["frame"].astype(int)[ok]]))


def _ate_py(slam, gt: np.ndarray) -> float:
    from torchratslam.eval.metrics import ate_rmse

    traj = slam.trajectory()
    ok = np.isfinite(traj[:, 3]) & (traj[:, 0] >= 1)
    return float(ate_rmse(traj[ok, 3:5], gt[traj[ok, 0].astype(int)]))


def _same_map(cpp: Path, slam, actions: list[int]) -> str:
    fr = read_csv(cpp / "frames.csv")
    ex = read_csv(cpp / "experiences.csv")
    diff = int(np.sum(np.asarray(actions) != fr["action"].astype(int)))
    poses = np.asarray(slam.experience_map.poses)
    if diff or len(poses) != len(ex["x"]):
        return f"no: {diff} actions differ"
    d = float(np.hypot(poses[:, 0] - ex["x"], poses[:, 1] - ex["y"]).max())
    return f"yes: every action equal, poses within {d:.0e} m"


def _one_set(build: Path, ds, tmp: Path, rounds: int, quick: bool) -> None:
    import torch

    from torchratslam.config import load_config
    from torchratslam.pipeline import RatSLAM

    if quick:
        ds = type(ds)(ds.name, ds.spec, ds.config, 400, ds.about)
    data = write_dataset_dir(ds, tmp / "data")
    cfg = data / "config.txt"
    frames = load_frames(data)
    g = read_csv(data / "groundtruth.csv")
    gt = np.stack([g["x"], g["y"]], 1)
    for b in PROFILES:  # warm-up: first imports, numba's compiled sweep loaded
        run_py(cfg, frames[:60], b)
    cpp_runs: list[dict] = []
    py_runs: dict[str, list[dict]] = {b: [] for b in PROFILES}
    for i in range(rounds):
        cpp_runs.append(run_cpp(build, data, tmp / f"cpp{i}"))
        for b in PROFILES:
            py_runs[b].append(run_py(cfg, frames, b))
    cpp_dir = tmp / "cpp0"
    # the openratslam profile's actions, for the "same map" row (float64 and float32)
    torch.set_num_threads(1)
    acts: list[int] = []
    ref = RatSLAM(load_config(cfg, behaviour="openratslam"), dtype=torch.float64)
    ref.run(frames, progress=False, callback=lambda r: acts.append(int(r.action.kind)))
    acts32: list[int] = []
    s32 = RatSLAM(load_config(cfg, behaviour="openratslam"), dtype=torch.float32)
    s32.run(frames, progress=False, callback=lambda r: acts32.append(int(r.action.kind)))

    def med(runs: list[dict], key: str) -> float:
        return float(np.median([r[key] for r in runs]))

    c = cpp_runs[0]
    cm = {
        "lv": float(np.median([r["lv_ms_mean"] for r in cpp_runs])),
        "pc": float(np.median([r["pc_ms_mean"] for r in cpp_runs])),
        "em": float(np.median([r["em_ms_mean"] for r in cpp_runs])),
        "total": float(np.median([r["total_ms_mean"] for r in cpp_runs])),
    }
    ratios = {
        b: [cr["total_ms_mean"] / pr["total"] for cr, pr in zip(cpp_runs, py_runs[b])]
        for b in PROFILES
    }
    p0 = {b: py_runs[b][0] for b in PROFILES}
    print(f"### {ds.name}: {len(frames)} frames ({ds.spec}), {rounds} alternated rounds\n")
    print("| | OpenRatSLAM C++ | torchratslam, openratslam | torchratslam, torchratslam |")
    print("|---|---|---|---|")

    def row(label: str, cv, po, pt) -> None:
        print(f"| {label} | {cv} | {po} | {pt} |")

    row(
        "templates / experiences / links",
        f"{int(c['templates'])} / {int(c['experiences'])} / {int(c['links'])}",
        *(f"{p0[b]['templates']} / {p0[b]['experiences']} / {p0[b]['links']}" for b in PROFILES),
    )
    row(
        "ATE m (frames >= 1)",
        f"{_ate_cpp(cpp_dir, gt):.3f}",
        *(f"{_ate_py(p0[b]['slam'], gt):.3f}" for b in PROFILES),
    )
    for key, label in (("lv", "local view"), ("pc", "pose cells"), ("em", "experience map")):
        row(
            f"{label} ms/frame",
            f"{cm[key]:.3f}",
            *(f"{med(py_runs[b], key):.3f}" for b in PROFILES),
        )
    row(
        "total ms/frame",
        f"{cm['total']:.3f}",
        *(f"{med(py_runs[b], 'total'):.3f}" for b in PROFILES),
    )
    row(
        "speed ratio C++ / torchratslam (median of rounds)",
        "1",
        *(f"**{np.median(ratios[b]):.2f}x**" for b in PROFILES),
    )
    row(
        "ratio per round",
        "-",
        *(", ".join(f"{r:.2f}" for r in ratios[b]) for b in PROFILES),
    )
    row(
        "same map as the C++ (float64)",
        "-",
        _same_map(cpp_dir, ref, acts),
        "- (its own behaviour)",
    )
    same32 = int(np.sum(np.asarray(acts32) != read_csv(cpp_dir / "frames.csv")["action"]))
    row("actions differing in float32", "-", str(same32), "-")
    print()


def main() -> None:
    build = find_build()
    if build is None:
        print(BUILD_HELP)
        return
    quick = os.environ.get("BENCH_QUICK", "") not in ("", "0")
    rounds = 1 if quick else int(os.environ.get("BENCH_PAIRS", "3"))
    print(f"OpenRatSLAM build: {build}\n")
    for ds in BENCH_SETS:
        with tempfile.TemporaryDirectory() as tmp:
            _one_set(build, ds, Path(tmp), rounds, quick)


if __name__ == "__main__":
    main()
