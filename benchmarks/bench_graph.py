"""Pose-graph backends on the gtsam example graphs (w10000, city10000).

For each graph: time per pass of the fast alpha rule, graph error after 20, 100 and
1000 passes, wall time (and passes) to reach the error that the compiled
reference-order loop reaches after 1000 passes, Levenberg-Marquardt time and error,
and iSAM2 time per added pose (graph fed pose by pose: all of city10000, the first 3000
poses of w10000). Initial estimate: composed odometry, as for the reference
figures. ``BENCH_QUICK=1`` shortens the iSAM2 runs and caps the alpha search.
"""

from __future__ import annotations

import os
import time

import numpy as np

from ratslam_graph.backends import GraphErrorEvaluator, make_backend
from ratslam_graph.geometry import ate_rmse
from ratslam_graph.io import example_file, read_posegraph, read_poses
from ratslam_graph.posegraph import PoseGraph

# the compiled reference-order alpha loop, 1000 passes (error, seconds)
COMPILED_1000 = {"w10000": (571.0, 2.19), "city10000": (1.01e5, 0.79)}
FILES = {"w10000": "w10000.graph", "city10000": "T1_city10000_04.txt"}


def _alpha(pg, ev, target: float, max_passes: int) -> dict:
    backend = make_backend("alpha")
    backend.relax(pg, passes=1)  # build the colouring outside the timings
    t0 = time.perf_counter()
    backend.relax(pg, passes=50)
    per_pass = (time.perf_counter() - t0) / 50
    out = {"ms_per_pass": 1e3 * per_pass, "classes": backend.num_classes}
    poses, done, wall, reached = pg.poses, 0, 0.0, None
    chunk = 10
    while done < max(1000, max_passes):
        t0 = time.perf_counter()
        poses = backend.relax(pg.with_poses(poses), passes=chunk)
        wall += time.perf_counter() - t0
        done += chunk
        err = ev(poses)
        if done in (20, 100, 1000):
            out[f"error_{done}"] = err
        if reached is None and err <= target:
            reached = (done, wall)
        if done >= 1000 and (reached is not None or done >= max_passes):
            break
        chunk = 10 if done < 100 else 50
    out["reached"] = reached
    out["final_passes"] = done
    return out


def _isam2(pg, max_poses: int) -> tuple[float, int, int]:
    """Feed the graph pose by pose; time only the backend calls."""
    backend = make_backend("isam2")
    n = min(max_poses, pg.num_poses)
    # edges in file order; the graph of the first k poses holds the edges among them
    reach = np.max(pg.edges, axis=1)
    wall = 0.0
    for k in range(2, n + 1):
        keep = reach < k
        sub = PoseGraph(
            pg.poses[:k], pg.edges[keep], pg.measurements[keep], None, pg.information[keep]
        )
        t0 = time.perf_counter()
        backend.relax(sub, passes=0)
        wall += time.perf_counter() - t0
    return wall / (n - 1), n, backend.rebuilds


def main() -> None:
    quick = os.environ.get("BENCH_QUICK", "") not in ("", "0")
    # iSAM2 pose by pose costs seconds per thousand poses: all of city10000, part of w10000
    isam_poses = (
        {"w10000": 1000, "city10000": 1000} if quick else {"w10000": 3000, "city10000": 10000}
    )
    rows = []
    for name, fname in FILES.items():
        pg = read_posegraph(example_file(fname), initial="odometry")
        ev = GraphErrorEvaluator(pg)
        target, compiled_s = COMPILED_1000[name]
        alpha = _alpha(pg, ev, target, max_passes=2000 if quick else 5000)
        t0 = time.perf_counter()
        lm = make_backend("gtsam").relax(pg, passes=0)
        lm_s = time.perf_counter() - t0
        lm_err = ev(lm)
        ate = ""
        if name == "city10000":
            gt = read_poses(example_file("ISAM2_GT_city10000.txt"))
            ate = f" (ATE {ate_rmse(lm, gt):.3f} m)"
        isam_ms, isam_n, rebuilds = _isam2(pg, isam_poses[name])
        reached = alpha["reached"]
        reach = (
            f"{reached[1]:.2f} s ({reached[0]} passes)"
            if reached
            else f"not within {alpha['final_passes']} passes"
        )
        rows.append(
            f"| {name} | {pg.num_poses}/{pg.num_edges} | {alpha['ms_per_pass']:.2f} "
            f"({alpha['classes']} classes) | {alpha['error_20']:.4g} | {alpha['error_100']:.4g} | "
            f"{alpha['error_1000']:.4g} | {target:.3g} in {compiled_s} s | {reach} | "
            f"{lm_s:.2f} s, {lm_err:.5g}{ate} | {1e3 * isam_ms:.1f} ms (first {isam_n}, "
            f"{rebuilds} build) |"
        )
        print(f"{name}: done", flush=True)
    print()
    print(
        "| graph | poses/edges | alpha ms/pass | error@20 | error@100 | error@1000 | "
        "compiled ref. @1000 | alpha reaches it | LM time, error | iSAM2 per pose |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(r)
    print(f"\n(numpy {np.__version__}; error = gtsam graph error, file noise model)")


if __name__ == "__main__":
    main()
