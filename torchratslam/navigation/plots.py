"""The experience-map paper's figures for a navigation run (matplotlib, Agg).

* :func:`plot_pc_path`: the dominant packet's path through the pose-cell matrix, its
  jumps (wraps and loop closures) dashed (Figs. 8-9);
* :func:`plot_experience_map`: experiences and links (Figs. 10-11);
* :func:`plot_temporal_map`: the temporal map with the planned route (Fig. 12) and, on
  the floor, the route's places and the path driven (Figs. 14-16).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from ratslam_graph.experience_map import ExperienceMap
from torchratslam.sim.office.builder import Office

__all__ = [
    "plot_experience_map",
    "plot_goal_memory",
    "plot_pc_path",
    "plot_temporal_map",
    "plot_trial_on_floor",
]


def _floor(ax: plt.Axes, office: Office) -> None:
    h, w = office.free.shape
    r = office.resolution
    x0, y0 = office.origin
    ax.imshow(
        office.free, origin="lower", cmap="Greys_r", alpha=0.25,
        extent=(x0, x0 + w * r, y0, y0 + h * r),
    )  # fmt: skip


def plot_pc_path(pc: np.ndarray, dims: int | tuple[int, int], title: str, path: Path) -> None:
    """The packet's ``(x', y')`` path; steps over 2 cells are drawn dashed.

    Args:
        dims: the matrix's ``(X, Y)`` cells (one number: square).

    Shape:
        pc: (F, 3) cells.
    """
    n_x, n_y = (dims, dims) if isinstance(dims, int) else dims
    fig, ax = plt.subplots(figsize=(5, max(2.5, 5 * n_y / n_x)) if n_x >= n_y else (5, 5))
    xy = np.asarray(pc, np.float64)[:, :2]
    jump = np.hypot(*np.diff(xy, axis=0).T) > 2.0
    cuts = np.flatnonzero(jump) + 1
    for seg in np.split(xy, cuts):
        ax.plot(seg[:, 0], seg[:, 1], "b-", lw=0.6)
    for k in cuts:
        ax.plot(xy[k - 1 : k + 1, 0], xy[k - 1 : k + 1, 1], "r--", lw=0.4)
    ax.plot([], [], "r--", label=f"jumps ({len(cuts)})")
    ax.plot(*xy[0], "go", label="start")
    ax.plot(*xy[-1], "ks", label="end")
    ax.set(xlim=(0, n_x), ylim=(0, n_y), xlabel="x' (cells)", ylabel="y' (cells)", title=title)
    ax.set_aspect("equal")
    ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_experience_map(em: ExperienceMap, title: str, path: Path) -> None:
    """Experiences (dots) and links (lines) in the map's frame."""
    fig, ax = plt.subplots(figsize=(6, 4.5))
    p = em.poses
    s = em.store
    e = s.e
    seg = np.stack([p[s.src[:e], :2], p[s.dst[:e], :2]], 1)
    ax.plot(seg[:, :, 0].T, seg[:, :, 1].T, "-", color="0.6", lw=0.4)
    ax.plot(p[:, 0], p[:, 1], ".", ms=1.5, color="C0", label=f"{len(p)} experiences")
    ax.set(xlabel="x (m, map)", ylabel="y (m, map)", title=title, aspect="equal")
    ax.legend(loc="best", fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_temporal_map(
    em: ExperienceMap, times: np.ndarray, route: list[int], title: str, path: Path
) -> None:
    """Experiences coloured by their time stamp (s) and the planned route (arrowed).

    Shape:
        times: (N,) (extra entries beyond the map's experiences are ignored).
    """
    fig, ax = plt.subplots(figsize=(6, 4.5))
    p = em.poses
    t = np.asarray(times, np.float64)[: len(p)]
    ok = np.isfinite(t)
    sc = ax.scatter(p[ok, 0], p[ok, 1], c=t[ok], s=3, cmap="viridis")
    fig.colorbar(sc, ax=ax, label="temporal distance (s)")
    if route:
        r = p[np.asarray(route, np.int64), :2]
        ax.plot(r[:, 0], r[:, 1], "r-", lw=1.5, label="planned route")
        ax.annotate("", xy=r[-1], xytext=r[max(len(r) - 4, 0)],
                    arrowprops={"arrowstyle": "->", "color": "r"})  # fmt: skip
        ax.legend(loc="best", fontsize=7)
    ax.set(xlabel="x (m, map)", ylabel="y (m, map)", title=title, aspect="equal")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_trial_on_floor(
    office: Office,
    route_xy: np.ndarray,
    path_xy: np.ndarray,
    title: str,
    path: Path,
    obstacle: tuple[float, float, float, float] | None = None,
) -> None:
    """A trial on the floor (ground truth): the planned route's places and the path driven.

    Shape:
        route_xy: (R, 2); path_xy: (T, 2).
    """
    fig, ax = plt.subplots(figsize=(7, 3.8))
    _floor(ax, office)
    if len(route_xy):
        ax.plot(route_xy[:, 0], route_xy[:, 1], "r.", ms=3, label="planned route (places)")
    ax.plot(path_xy[:, 0], path_xy[:, 1], "b-", lw=0.8, label="path driven")
    ax.plot(*path_xy[0], "go", label="start")
    if obstacle is not None:
        cx, cy, w, h = obstacle
        ax.add_patch(plt.Rectangle((cx - w / 2, cy - h / 2), w, h, color="k", label="obstacle"))
    ax.set(xlabel="x (m)", ylabel="y (m)", title=title, aspect="equal")
    ax.legend(loc="upper right", fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_goal_memory(
    times: np.ndarray, dims: tuple[int, int], title: str, path: Path, label: str = "time (s)"
) -> None:
    """Goal memory's temporal map over the ``(x', y')`` cells (Fig. 4); cells it cannot
    reach are left blank; ``label`` names the colour scale.

    Shape:
        times: (X * Y,) seconds, cell ``x + X y``.
    """
    n_x, n_y = dims
    grid = np.asarray(times, np.float64).reshape(n_y, n_x)
    grid = np.where(np.isfinite(grid), grid, np.nan)
    fig, ax = plt.subplots(figsize=(5, max(2.5, 5 * n_y / n_x)))
    im = ax.imshow(grid, origin="lower", cmap="viridis", extent=(0, n_x, 0, n_y))
    fig.colorbar(im, ax=ax, label=label, shrink=0.8)
    ax.set(xlabel="x' (cells)", ylabel="y' (cells)", title=title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
