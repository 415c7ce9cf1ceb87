"""Relaxing one pose graph with several backends (the runner behind ``torchratslam
compare-backends``): load a graph file or a saved map's experience graph, relax it with
each backend, and tabulate time, error and ATE.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ratslam_graph.atomic import atomic_write_text
from torchratslam.errors import InputError

__all__ = [
    "format_table",
    "load_posegraph",
    "posegraph_from_state",
    "run_comparison",
    "write_rows_json",
]


def posegraph_from_state(state: Any) -> Any:
    """The pose graph of a saved map's experience map (a ``MapState``)."""
    from ratslam_graph.posegraph import PoseGraph

    poses = np.asarray(state.exp_pose, dtype=np.float64).reshape(-1, 3)
    src = np.asarray(state.link_from, dtype=np.int64)
    dst = np.asarray(state.link_to, dtype=np.int64)
    d = np.asarray(state.link_d, dtype=np.float64)
    heading = np.asarray(state.link_heading, dtype=np.float64)
    facing = np.asarray(state.link_facing, dtype=np.float64)
    meas = np.stack([d * np.cos(heading), d * np.sin(heading), facing], axis=1).reshape(-1, 3)
    edges = np.stack([src, dst], axis=1).reshape(-1, 2)
    return PoseGraph(poses, edges, meas, np.arange(poses.shape[0], dtype=np.int64))


def load_posegraph(path: str | Path) -> Any:
    """A pose graph from a graph file or a saved RatSLAM state."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"--map {str(path)!r}: not found; give a .g2o/TORO file or a saved state")
    if p.is_file() and p.suffix.lower() in (".g2o", ".graph", ".txt", ".toro"):
        from ratslam_graph.io import read_posegraph

        return read_posegraph(p)
    from torchratslam.maps.io import load_state

    return posegraph_from_state(load_state(p))


def format_table(rows: list[dict[str, Any]]) -> str:
    """The comparison rows as a Markdown table."""
    has_ate = any(r.get("ate_rmse_m") is not None for r in rows)
    head = "| backend | time (s) | initial error | error |" + (" ATE (m) |" if has_ate else "")
    sep = "|---|---|---|---|" + ("---|" if has_ate else "")
    lines = [head, sep]
    for r in rows:
        init = r.get("initial_error")
        init_s = f"{init:.6g}" if init is not None else "-"
        line = f"| {r['name']} | {r['time_s']:.4f} | {init_s} | {r['error']:.6g} |"
        if has_ate:
            a = r.get("ate_rmse_m")
            line += f" {a:.4f} |" if a is not None else " - |"
        lines.append(line)
    return "\n".join(lines)


def _groundtruth(path: str | Path | None, n: int) -> np.ndarray | None:
    """True node poses from ``path`` (None without one), checked against ``n`` nodes."""
    if not path:
        return None
    from ratslam_graph.io import read_poses

    gt = read_poses(path)
    if gt.shape[0] != n:
        raise InputError(f"--groundtruth {path}: {gt.shape[0]} poses but the map has {n} nodes")
    return gt


def run_comparison(
    map_path: str | Path,
    backends: tuple[str, ...],
    *,
    groundtruth: str | Path | None = None,
    passes: int = 1000,
) -> tuple[Any, list[dict[str, Any]]]:
    """Relax the pose graph at ``map_path`` with each backend.

    Args:
        map_path: a g2o/TORO file or a saved state.
        backends: backend names.
        groundtruth: a file of true node poses (ATE per backend), or None.
        passes: passes of the alpha backends.

    Returns:
        The pose graph and one row per backend (``name``, ``time_s``, ``error``, ...).

    Raises:
        InputError: no backends, a missing map, mismatched ground truth, passes < 1.
    """
    from ratslam_graph.compare import compare_backends

    if not backends:
        raise InputError("--backends is empty; e.g. --backends alpha,gtsam,isam2")
    pg = load_posegraph(map_path)
    gt = _groundtruth(groundtruth, np.asarray(pg.poses).shape[0])
    if passes < 1:
        raise InputError(f"--passes must be >= 1, got {passes}")
    return pg, compare_backends(pg, backends=backends, groundtruth=gt, passes=passes)


def write_rows_json(rows: list[dict[str, Any]], path: str | Path) -> None:
    """The rows (without arrays) as JSON at ``path``, written atomically."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    payload = [
        {
            k: (v.item() if isinstance(v, np.generic) else v)
            for k, v in r.items()
            if not isinstance(v, np.ndarray)
        }
        for r in rows
    ]
    atomic_write_text(out, json.dumps(payload, indent=2, default=str))
