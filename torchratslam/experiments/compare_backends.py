"""Relaxing one pose graph with several backends (the runner behind ``torchratslam
compare-backends``): load a graph file or a saved map's experience graph, relax it with
each backend, and tabulate time, error and ATE.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from ratslam_graph.atomic import atomic_write_text
from ratslam_graph.out_checks import check_out_file
from torchratslam.errors import InputError, option

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
        raise InputError(
            f"{option('--map', 'map_path')} {str(path)!r}: not found; give a .g2o/TORO file "
            "or a saved state"
        )
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


def _is_timed(path: Path) -> bool:
    """A ground truth of the project's own format (``groundtruth.csv``: a header
    ``t,x,y,theta``, one timed pose per frame), or a dataset (directory or ``sim:``)."""
    if str(path).startswith("sim:") or path.is_dir():
        return True
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            head = fh.readline().strip().lower().replace(" ", "")
    except OSError:
        return False
    return head.startswith("t,x,y")


def _groundtruth(path: str | Path | None, n: int) -> np.ndarray | None:
    """True node poses from ``path`` (None without one), checked against ``n`` nodes."""
    if not path:
        return None
    from ratslam_graph.io import read_poses

    gt = read_poses(path)
    if gt.shape[0] != n:
        raise InputError(
            f"{option('--groundtruth', 'groundtruth')} {path}: {gt.shape[0]} poses but the map "
            f"has {n} nodes"
        )
    return gt


def _timed_rows(rows: list[dict[str, Any]], exp_t: np.ndarray, gt: np.ndarray) -> None:
    """Each row's ATE over the experiences whose creation time the timed ground truth
    covers (SE(2)-aligned; undefined under 3)."""
    from torchratslam.eval.metrics import ATE_ALIGNMENT, ate_at_times

    for r in rows:
        r["ate_rmse_m"], r["ate_poses"] = ate_at_times(np.asarray(r["poses"]), exp_t, gt)
        r["ate_alignment"] = ATE_ALIGNMENT
        r["ate_over"] = "experiences at their creation times"


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
        groundtruth: true node poses (a file of ``x y th`` per node, in node order), or
            for a saved state also a timed ground truth: the project's ``groundtruth.csv``
            (``t,x,y,theta``, what ``run`` and ``simulate`` write) or a dataset, taken at
            each experience's creation time; None: no ATE.
        passes: passes of the alpha backends.

    Returns:
        The pose graph and one row per backend (``name``, ``time_s``, ``error``,
        ``ate_rmse_m`` with ``ate_alignment`` and ``ate_poses``, ...).

    Raises:
        InputError: no backends, a missing map, mismatched ground truth, passes < 1.
    """
    from ratslam_graph.compare import compare_backends

    if not backends:
        example = option("--backends alpha,gtsam,isam2", "backends=('alpha', 'gtsam')")
        raise InputError(f"{option('--backends', 'backends')} is empty; e.g. {example}")
    if passes < 1:
        raise InputError(f"{option('--passes', 'passes')} must be >= 1, got {passes}")
    timed = groundtruth is not None and bool(str(groundtruth)) and _is_timed(Path(groundtruth))
    state = _state(map_path) if timed else None
    pg = posegraph_from_state(state) if state is not None else load_posegraph(map_path)
    n = int(np.asarray(pg.poses).shape[0])
    if state is not None and groundtruth is not None:
        from torchratslam.experiments.compare_maps import load_groundtruth

        gt_t = load_groundtruth(groundtruth)
        rows = compare_backends(pg, backends=backends, groundtruth=None, passes=passes)
        _timed_rows(rows, np.asarray(state.exp_t, np.float64), gt_t)
        return pg, rows
    gt = _groundtruth(groundtruth, n)
    rows = compare_backends(pg, backends=backends, groundtruth=gt, passes=passes)
    if gt is not None:
        from torchratslam.eval.metrics import ATE_ALIGNMENT, MIN_ATE_POSES

        for r in rows:
            r.update(ate_alignment=ATE_ALIGNMENT, ate_poses=n, ate_over="nodes, in order")
            if n < MIN_ATE_POSES:  # an SE(2) alignment of fewer poses says nothing
                r["ate_rmse_m"] = None
    return pg, rows


def _state(map_path: str | Path) -> Any:
    """The saved map at ``map_path`` (a timed ground truth needs its creation times)."""
    p = Path(map_path)
    if not p.exists():
        load_posegraph(p)  # the one line for a missing map
    if p.is_file():
        raise InputError(
            f"{option('--groundtruth', 'groundtruth')}: a timed ground truth (t,x,y,theta) "
            f"needs a saved map with its experiences' creation times; {p} is a graph file: "
            "give a file of 'x y th' per node instead"
        )
    from torchratslam.maps.io import load_state

    state = load_state(p)
    if state.n_experiences > 1 and np.ptp(state.exp_t) == 0:
        raise InputError(
            f"{p} holds no experience creation times (a reference-format map), so a timed "
            "ground truth cannot be matched to its nodes; give a file of 'x y th' per node"
        )
    return state


def write_rows_json(
    rows: list[dict[str, Any]],
    path: str | Path,
    *,
    inputs: Iterable[str | Path] = (),
    overwrite: bool = False,
) -> None:
    """The rows (without arrays) as JSON at ``path``, written atomically; an existing file
    is replaced only with ``overwrite`` (never another command's file or one of
    ``inputs``)."""
    check_out_file(path, inputs=inputs, flag=("--json", "json"), overwrite=overwrite)
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
