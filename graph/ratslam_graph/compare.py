"""Run several backends on the same pose graph and compare them.

For every backend: wall time, the final graph error under ONE common noise model
(gtsam's ``graph.error`` of the edges, see :mod:`ratslam_graph.backends.gtsam_backend`), and,
when ground truth is given, the position RMSE after rigid SE(2) alignment (ATE).
The alpha rule and least squares minimise different things: the alpha rule stops at
a fixed point of its sweep, above the least-squares optimum, and the comparison shows
by how much.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ratslam_graph.backends import GraphErrorEvaluator, make_backend
from ratslam_graph.errors import InputError
from ratslam_graph.geometry import ate_rmse
from ratslam_graph.posegraph import PoseGraph


def compare_backends(
    pg: PoseGraph,
    backends: Sequence[str] = ("alpha", "gtsam", "isam2"),
    groundtruth: np.ndarray | None = None,
    *,
    passes: int = 1000,
    correction: float = 0.5,
    sigmas: Sequence[float] | None = None,
    options: Mapping[str, Mapping[str, Any]] | None = None,
) -> list[dict]:
    """Relax ``pg`` with each backend from the same initial poses.

    Args:
        pg: the graph (its poses are the initial estimate for every backend).
        backends: backend names (see :func:`ratslam_graph.backends.make_backend`).
        groundtruth: optional (N, 2) or (N, 3) true ``x, y(, th)`` per node.
        passes: alpha passes (ignored by gtsam/isam2).
        correction: alpha's ``exp_correction``.
        sigmas: the common default noise model (x, y, th sigmas) used for the error of
            edges without information, and by gtsam/isam2 (default unit).
        options: extra constructor options per backend name.

    Returns:
        One dict per backend: ``name``, ``time_s`` (wall time of ``relax``), ``error``
        (common graph error after), ``initial_error``, ``ate_rmse_m`` (None without
        ground truth), ``passes`` (None for least-squares backends), ``poses`` (N, 3).
    """
    if groundtruth is not None:
        groundtruth = np.asarray(groundtruth, dtype=np.float64)
        if (
            groundtruth.ndim != 2
            or groundtruth.shape[0] != pg.num_poses
            or groundtruth.shape[1] < 2
        ):
            raise InputError(
                f"groundtruth must be ({pg.num_poses}, 2) or ({pg.num_poses}, 3); "
                f"got {groundtruth.shape}"
            )
    evaluate = GraphErrorEvaluator(pg, sigmas=sigmas)
    initial = evaluate(pg.poses)
    options = dict(options or {})
    results = []
    for name in backends:
        opts = dict(options.get(name, {}))
        if name in ("gtsam", "isam2") and sigmas is not None:
            opts.setdefault("sigmas", sigmas)
        backend = make_backend(name, **opts)
        t0 = time.perf_counter()
        poses = backend.relax(pg, passes=passes, correction=correction)
        elapsed = time.perf_counter() - t0
        results.append(
            {
                "name": name,
                "time_s": elapsed,
                "error": evaluate(poses),
                "initial_error": initial,
                "ate_rmse_m": None if groundtruth is None else ate_rmse(poses, groundtruth),
                "passes": passes if name.startswith("alpha") else None,
                "poses": poses,
            }
        )
    return results


def format_table(results: Sequence[Mapping[str, Any]]) -> str:
    """A Markdown table of :func:`compare_backends` results."""
    lines = [
        "| backend | passes | time (s) | graph error | ATE RMSE (m) |",
        "|---|---|---|---|---|",
    ]
    for r in results:
        ate = "-" if r["ate_rmse_m"] is None else f"{r['ate_rmse_m']:.4g}"
        passes = "-" if r["passes"] is None else str(r["passes"])
        lines.append(f"| {r['name']} | {passes} | {r['time_s']:.3f} | {r['error']:.6g} | {ate} |")
    return "\n".join(lines)


def alpha_error_curve(
    pg: PoseGraph,
    *,
    passes: int = 1000,
    chunk: int = 50,
    correction: float = 0.5,
    backend: str = "alpha",
    sigmas: Sequence[float] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Graph error of an alpha backend against passes and wall time.

    The error is evaluated every ``chunk`` passes (evaluation time is not counted).

    Returns:
        ``(passes, seconds, errors)``, each (K+1,), starting with the initial graph.
    """
    if chunk < 1 or passes < 0:
        raise InputError(f"need chunk >= 1 and passes >= 0, got chunk={chunk}, passes={passes}")
    evaluate = GraphErrorEvaluator(pg, sigmas=sigmas)
    b = make_backend(backend)
    b.relax(pg, passes=1)  # warm-up: builds the colouring of the fast alpha
    done, wall, poses = [0], [0.0], pg.poses
    errors = [evaluate(poses)]
    while done[-1] < passes:
        n = min(chunk, passes - done[-1])
        t0 = time.perf_counter()
        poses = b.relax(pg.with_poses(poses), passes=n, correction=correction)
        wall.append(wall[-1] + time.perf_counter() - t0)
        done.append(done[-1] + n)
        errors.append(evaluate(poses))
    return np.array(done), np.array(wall), np.array(errors)


def lm_error_curve(
    pg: PoseGraph, *, max_iterations: int = 100, sigmas: Sequence[float] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Graph error of Levenberg-Marquardt after each iteration, against wall time.

    Returns:
        ``(iterations, seconds, errors)`` starting with the initial graph; the time
        includes building the factor graph.
    """
    import gtsam

    from ratslam_graph.backends.gtsam_backend import _values, factor_graph

    evaluate = GraphErrorEvaluator(pg, sigmas=sigmas)
    t0 = time.perf_counter()
    graph = factor_graph(pg, sigmas=sigmas)
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-10)
    params.setAbsoluteErrorTol(0.0)
    opt = gtsam.LevenbergMarquardtOptimizer(graph, _values(pg.poses), params)
    wall = [0.0]
    errors = [evaluate(pg.poses)]
    elapsed = time.perf_counter() - t0
    for _ in range(max_iterations):
        before = opt.error()
        t0 = time.perf_counter()
        opt.iterate()
        elapsed += time.perf_counter() - t0
        values = opt.values()
        poses = np.asarray(gtsam.utilities.extractPose2(values)).reshape(-1, 3)
        wall.append(elapsed)
        errors.append(evaluate(poses))
        if before - opt.error() <= 1e-10 * before:
            break
    return np.arange(len(wall)), np.array(wall), np.array(errors)
