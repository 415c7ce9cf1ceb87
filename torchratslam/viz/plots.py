"""Figures of a run: the experience map (``map.png``) and the pose cells (``pose_cells.png``).

* :func:`plot_map` -- experiences and links of the experience map; with ground truth,
  the true path is rigidly aligned (SE(2), no scale) onto the map's per-frame
  trajectory and drawn underneath, so the picture shows the map's real error.
* :func:`plot_pose_cells` -- the pose-cell activity and the packet's path; uses the
  pose-cell module's own figure (``torchratslam.viz.pose_cells.plot_activity``), else
  three max-projections (x-y, x-theta, y-theta).

Both write a PNG with matplotlib's Agg backend (no display needed) atomically.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg", force=False)
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection

from torchratslam.eval.metrics import align_se2

__all__ = ["draw_icp_overlay", "plot_map", "plot_pose_cells", "save_figure"]


def save_figure(fig: Any, path: str | Path, dpi: int = 110, *, tight: bool = True) -> Path:
    """Save a matplotlib figure atomically (temp file + rename) and close it
    (``tight``: ``bbox_inches="tight"``)."""
    from ratslam_graph.atomic import atomic_write_with

    path = Path(path)
    fmt = (path.suffix or ".png").lstrip(".")
    try:
        atomic_write_with(
            path,
            lambda fh: fig.savefig(fh, dpi=dpi, bbox_inches="tight" if tight else None, format=fmt),
        )
    finally:
        plt.close(fig)
    return path


def _world_segments(world: Any) -> np.ndarray | None:
    """Wall segments ``(S, 2, 2)`` of a simulator world, if it exposes them."""
    for name in ("segments", "walls"):
        seg = getattr(world, name, None)
        if seg is None:
            continue
        try:
            arr = np.asarray(seg, dtype=np.float64)
        except (TypeError, ValueError):
            continue
        if arr.ndim == 2 and arr.shape[1] == 4:
            return arr.reshape(-1, 2, 2)
        if arr.ndim == 3 and arr.shape[1:] == (2, 2):
            return arr
    return None


def plot_map(
    path: str | Path,
    poses: np.ndarray,
    links: np.ndarray,
    *,
    trajectory_xy: np.ndarray | None = None,
    groundtruth_xy: np.ndarray | None = None,
    world: Any = None,
    title: str = "experience map",
) -> Path:
    """Draw the experience map and, when given, the aligned ground truth.

    Args:
        path: output PNG.
        poses: experience poses. Shape: ``(N, 3)`` ``[x, y, th]``.
        links: link endpoints as experience ids. Shape: ``(E, 2)``.
        trajectory_xy: the map position of each frame (its current experience).
            Shape: ``(F, 2)``.
        groundtruth_xy: the true position of each frame. Shape: ``(F, 2)``; aligned
            onto ``trajectory_xy`` with a rigid SE(2) fit and drawn in grey.
        world: a simulator world whose wall segments are drawn (aligned the same way).
        title: figure title.

    Returns:
        The written path.
    """
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    e = np.asarray(links, dtype=np.int64).reshape(-1, 2)
    fig, ax = plt.subplots(figsize=(7, 7))
    rot, t = np.eye(2), np.zeros(2)
    have_gt = (
        groundtruth_xy is not None
        and trajectory_xy is not None
        and len(groundtruth_xy) == len(trajectory_xy)
        and len(groundtruth_xy) >= 2
    )
    if have_gt:
        gt = np.asarray(groundtruth_xy, dtype=np.float64)[:, :2]
        tr = np.asarray(trajectory_xy, dtype=np.float64)[:, :2]
        ok = np.all(np.isfinite(gt), 1) & np.all(np.isfinite(tr), 1)
        if ok.sum() >= 2:
            fit = align_se2(gt[ok], tr[ok])
            rot, t = fit.rotation, fit.translation
            g = gt @ rot.T + t
            ax.plot(g[:, 0], g[:, 1], color="0.6", lw=1.0, label="ground truth (aligned)", zorder=1)
    segs = _world_segments(world) if world is not None else None
    if segs is not None and have_gt:
        moved = segs @ rot.T + t
        ax.add_collection(
            LineCollection(moved, colors="0.2", linewidths=1.5, zorder=0, label="walls (aligned)")
        )
    if e.size and p.size:
        ok = (e >= 0).all(1) & (e < p.shape[0]).all(1)
        ax.add_collection(
            LineCollection(
                p[e[ok]][:, :, :2],  # type: ignore[arg-type]
                colors="tab:blue",
                linewidths=0.8,
                zorder=2,
                label=f"{int(ok.sum())} links",
            )
        )
    if p.size:
        ax.scatter(p[:, 0], p[:, 1], s=6, color="tab:red", zorder=3, label=f"{len(p)} experiences")
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{title}: {len(p)} experiences, {len(e)} links")
    if p.size or have_gt:
        ax.legend(loc="best", fontsize=8)
    return save_figure(fig, path)


def plot_pose_cells(
    path: str | Path, activity: Any, *, centres: Any = None, title: str = "pose cells"
) -> Path:
    """Draw the pose-cell activity (and the packet centre's path when given).

    Args:
        path: output PNG.
        activity: the activity, a tensor or array. Shape: ``(TH, Y, X)``.
        centres: optional packet centres per frame, in cells. Shape: ``(T, 3)``.
        title: figure title.

    Returns:
        The written path.
    """
    try:  # the pose-cell module's own figure
        from torchratslam.viz.pose_cells import plot_activity
    except ImportError:
        plot_activity = None  # type: ignore[assignment]
    if plot_activity is not None:
        plot_activity(activity, path, centres=centres, title=title)
        return Path(path)
    a = activity.detach().cpu().numpy() if hasattr(activity, "detach") else np.asarray(activity)
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 3:
        a = a.reshape(1, *a.shape[-2:]) if a.ndim == 2 else a.reshape(-1, *a.shape[-2:])
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.6))
    views = (
        (a.max(axis=0), "x", "y", "max over theta"),
        (a.max(axis=1), "x", "theta", "max over y"),
        (a.max(axis=2), "y", "theta", "max over x"),
    )
    for ax, (img, xl, yl, name) in zip(axes, views):
        im = ax.imshow(img, origin="lower", cmap="viridis", aspect="auto")
        fig.colorbar(im, ax=ax, label="activity (largest cell; the network sums to 1)")
        ax.set_xlabel(f"{xl} (cells)")
        ax.set_ylabel(f"{yl} (cells)")
        ax.set_title(name, fontsize=9)
    fig.suptitle(f"{title} (TH, Y, X) = {tuple(a.shape)}")
    return save_figure(fig, path)


def draw_icp_overlay(
    ax: Any,
    fixed: np.ndarray,
    moved_aligned: np.ndarray,
    *,
    fixed_label: str,
    moved_label: str,
    mse_m2: float,
) -> None:
    """The paper's Fig. 10 on ``ax``: the fixed map (purple) and the ICP-aligned moved map
    (orange), axes in metres, legend, the LibICP residual in the title.

    Shape:
        fixed: ``(M, 2|3)``; moved_aligned: ``(N, 2|3)``.
    """
    ax.scatter(fixed[:, 0], fixed[:, 1], s=9, color="tab:purple", label=fixed_label)
    ax.scatter(moved_aligned[:, 0], moved_aligned[:, 1], s=4, color="tab:orange", label=moved_label)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize=8)
    ax.set_title(f"ICP comparison: LibICP residual {mse_m2:.6g} m$^2$", fontsize=9)
