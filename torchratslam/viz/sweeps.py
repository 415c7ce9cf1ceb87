"""Figures of a sweep or a study: each metric against each swept parameter, speed
against accuracy.

* :func:`plot_metrics_vs_param` -- one panel per metric (ATE, dead-reckoning ATE,
  templates, experiences, links, ms per frame); every successful run is a dot, the line
  joins the mean over the other parameters and seeds at each value; one colour per
  dataset.
* :func:`plot_speed_accuracy` -- ms per frame (all modules) against ATE, one dot per run.
* :func:`plot_sweep` -- both, for every swept parameter, into a folder.

Rows are the results table's (dicts with the columns of
:func:`torchratslam.sweeps.table.columns`); failed runs are left out.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg", force=False)
import matplotlib.pyplot as plt
import numpy as np

from torchratslam.viz.plots import save_figure

__all__ = ["METRIC_LABELS", "plot_metrics_vs_param", "plot_speed_accuracy", "plot_sweep"]

METRIC_LABELS: dict[str, str] = {
    "ate_m": "ATE (m)",
    "dead_reckoning_ate_m": "dead-reckoning ATE (m)",
    "templates": "templates (count)",
    "experiences": "experiences (count)",
    "links": "links (count)",
    "ms_per_frame": "time per frame, all modules (ms)",
}
MODULE_COLUMNS = ("ms_odometry", "ms_local_view", "ms_pose_cells", "ms_experience_map")


def _records(rows: Any) -> list[dict[str, Any]]:
    if hasattr(rows, "to_dict"):  # a pandas DataFrame
        rows = rows.to_dict("records")
    out = []
    for r in rows:
        if r.get("status") != "ok":
            continue
        r = dict(r)
        ms = [float(r.get(c, math.nan)) for c in MODULE_COLUMNS]
        r["ms_per_frame"] = float(np.nansum(ms)) if not all(math.isnan(v) for v in ms) else math.nan
        out.append(r)
    return out


def _numeric(values: Sequence[Any]) -> bool:
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)


def plot_metrics_vs_param(rows: Any, param: str, path: str | Path) -> Path:
    """Every metric against one swept parameter (see the module docstring).

    Args:
        rows: the results table (DataFrame or list of dicts).
        param: the swept parameter (a column of the table).
        path: the PNG to write.

    Returns:
        ``path``.
    """
    recs = [r for r in _records(rows) if param in r]
    metrics = list(METRIC_LABELS)
    fig, axes = plt.subplots(2, 3, figsize=(13, 7))
    values = sorted({r[param] for r in recs}, key=lambda v: (str(type(v)), v))
    numeric = _numeric(values)
    pos = {v: (float(v) if numeric else float(i)) for i, v in enumerate(values)}
    datasets = sorted({str(r.get("dataset", "")) for r in recs})
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, metric in zip(axes.ravel(), metrics):
        for k, ds in enumerate(datasets):
            sub = [r for r in recs if str(r.get("dataset", "")) == ds]
            xs = np.array([pos[r[param]] for r in sub], dtype=float)
            ys = np.array([float(r.get(metric, math.nan)) for r in sub], dtype=float)
            c = colours[k % len(colours)]
            ax.scatter(xs, ys, s=14, alpha=0.5, color=c)
            mx = sorted(set(xs.tolist()))
            my = [
                float(np.nanmean(ys[xs == x])) if np.isfinite(ys[xs == x]).any() else np.nan
                for x in mx
            ]
            ax.plot(mx, my, "-o", ms=4, color=c, label=ds)
        ax.set_xlabel(param)
        ax.set_ylabel(METRIC_LABELS[metric])
        if not numeric:
            ax.set_xticks([pos[v] for v in values], [str(v) for v in values])
        ax.grid(alpha=0.3)
    if datasets:
        axes.ravel()[0].legend(fontsize=8, title="dataset", title_fontsize=8)
    fig.suptitle(f"sweep: metrics against {param} (dots: runs; lines: mean)")
    fig.tight_layout()
    return save_figure(fig, path)


def plot_speed_accuracy(rows: Any, path: str | Path, *, colour_by: str | None = None) -> Path:
    """Time per frame (ms, all modules) against ATE (m), one dot per run.

    Args:
        rows: the results table (DataFrame or list of dicts).
        path: the PNG to write.
        colour_by: a column whose values colour the dots (default: the dataset).

    Returns:
        ``path``.
    """
    recs = _records(rows)
    key = colour_by or "dataset"
    groups = sorted({str(r.get(key, "")) for r in recs})
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for g in groups:
        sub = [r for r in recs if str(r.get(key, "")) == g]
        ax.scatter(
            [r["ms_per_frame"] for r in sub],
            [float(r.get("ate_m", math.nan)) for r in sub],
            s=18,
            alpha=0.7,
            label=f"{key}={g}",
        )
    ax.set_xlabel(METRIC_LABELS["ms_per_frame"])
    ax.set_ylabel(METRIC_LABELS["ate_m"])
    ax.set_title("speed against accuracy (lower left is better)")
    ax.grid(alpha=0.3)
    if groups:
        ax.legend(fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_sweep(rows: Any, params: Sequence[str], out_dir: str | Path) -> list[Path]:
    """``metrics_vs_<param>.png`` for every swept parameter and ``speed_vs_accuracy.png``
    into ``out_dir``.

    Returns:
        The files written.
    """
    out = Path(out_dir)
    written = [plot_metrics_vs_param(rows, p, out / f"metrics_vs_{p}.png") for p in params]
    colour = params[0] if len(params) == 1 else None
    written.append(plot_speed_accuracy(rows, out / "speed_vs_accuracy.png", colour_by=colour))
    return written
