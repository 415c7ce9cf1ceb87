"""Figures of the pose-cell network: activity projections and the packet's path.

Used by the pose-cell demo and by the pipeline's ``pose_cells.png``
(:func:`torchratslam.viz.plots.plot_pose_cells` calls :func:`plot_activity`).

Example:
    >>> from torchratslam.pose_cells.network import PoseCellNetwork
    >>> from torchratslam.config import PoseCellParams
    >>> net = PoseCellNetwork(PoseCellParams())
    >>> fig = plot_activity(net.activity[0])  # doctest: +SKIP
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import matplotlib

if "MPLBACKEND" not in os.environ:
    matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from torchratslam.errors import InputError

__all__ = ["COLOUR_LABEL", "plot_activity", "plot_packet_path", "projections", "split_at_wraps"]

COLOUR_LABEL = "activity summed over theta (fraction of the network's total, which is 1)"
"""The x-y panel's colour bar: the activity is normalised to sum to 1 over the network
after every step (OpenRatSLAM's normalisation), so a cell's share is unitless."""


def _numpy(a: Any) -> np.ndarray:
    if hasattr(a, "detach"):
        a = a.detach().cpu().numpy()
    return np.asarray(a, dtype=np.float64)


def projections(activity: Any) -> tuple[np.ndarray, np.ndarray]:
    """Sum of the activity over theta (an ``(Y, X)`` image) and over x and y (``(TH,)``).

    Shape:
        activity: ``(TH, Y, X)`` (or ``(1, TH, Y, X)``).
    """
    a = _numpy(activity)
    if a.ndim == 4 and a.shape[0] == 1:
        a = a[0]
    if a.ndim != 3:
        raise InputError(f"pose-cell activity must be (TH, Y, X), got shape {a.shape}")
    return a.sum(axis=0), a.sum(axis=(1, 2))


def split_at_wraps(points: Any, dims: tuple[int, ...]) -> list[np.ndarray]:
    """Cut a path of wrapped coordinates where it jumps across a ring edge, so that
    plotting it draws no line across the whole network.

    Args:
        points: ``(T, D)`` coordinates in cells.
        dims: ring size of each of the ``D`` columns.

    Returns:
        Pieces of ``points`` (each ``(t, D)``).
    """
    p = np.asarray(points, dtype=np.float64)
    if len(p) < 2:
        return [p]
    jump = np.abs(np.diff(p, axis=0)) > np.asarray(dims, dtype=np.float64) / 2
    cuts = np.nonzero(jump.any(axis=1))[0] + 1
    return [piece for piece in np.split(p, cuts) if len(piece)]


def plot_packet_path(
    ax: Any, centres: Any, dims: tuple[int, int], *, label: str = "packet", **style: Any
) -> None:
    """Draw a path of packet centres ``(T, 2)`` (x, y cells) on ``ax``, cut at wraps."""
    pieces = split_at_wraps(np.asarray(centres, dtype=np.float64)[:, :2], dims)
    for i, piece in enumerate(pieces):
        ax.plot(piece[:, 0], piece[:, 1], label=label if i == 0 else None, **style)


def plot_activity(
    activity: Any,
    path: str | Path | None = None,
    *,
    centres: Any = None,
    reference: Any = None,
    title: str = "pose cells",
) -> Path | Any:
    """Activity projections, with the packet's path when given.

    Left: activity summed over theta (x right, y up; its colour bar in
    :data:`COLOUR_LABEL`'s unit) with the packet centres (and an optional reference
    path, e.g. integrated odometry). Middle: activity summed over x
    and y per theta cell. Right (when ``centres`` is given): the packet's theta against
    the step number.

    Args:
        activity: the activity to show.
        path: PNG to write; None returns the figure instead.
        centres: optional packet centres ``(T, 3)`` (x, y, th cells).
        reference: optional reference path ``(T, 2)`` or ``(T, 3)`` in cells.
        title: figure title.

    Shape:
        activity: ``(TH, Y, X)``.

    Returns:
        The written path, or the matplotlib figure when ``path`` is None.
    """
    xy, th = projections(activity)
    n_th, (n_y, n_x) = th.shape[0], xy.shape
    panels = 3 if centres is not None else 2
    fig, axes = plt.subplots(1, panels, figsize=(4.2 * panels, 4.0))
    ax = axes[0]
    im = ax.imshow(xy, origin="lower", cmap="viridis", extent=(-0.5, n_x - 0.5, -0.5, n_y - 0.5))
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label=COLOUR_LABEL)
    if reference is not None:
        plot_packet_path(ax, reference, (n_x, n_y), label="odometry", color="w", lw=1.0, ls="--")
    if centres is not None:
        plot_packet_path(ax, centres, (n_x, n_y), label="packet centre", color="tab:orange", lw=1.5)
        ax.legend(loc="upper right", fontsize=7)
    ax.set(
        xlabel="x (cells)",
        ylabel="y (cells)",
        title="x-y activity (summed over theta)",
        xlim=(-0.5, n_x - 0.5),
        ylim=(-0.5, n_y - 0.5),
    )
    ax = axes[1]
    ax.bar(np.arange(n_th), th, width=1.0, color="tab:blue")
    ax.set(
        xlabel="theta (cells)",
        ylabel="activity summed over x, y (fraction of the total)",
        title="theta activity (summed over x, y)",
        xlim=(-0.5, n_th - 0.5),
    )
    if centres is not None:
        c = np.asarray(centres, dtype=np.float64)
        ax = axes[2]
        steps = np.arange(len(c), dtype=np.float64)
        for piece in split_at_wraps(np.stack([steps, c[:, 2]], axis=1), (10**9, n_th)):
            ax.plot(piece[:, 0], piece[:, 1], color="tab:orange")
        ax.set(
            xlabel="step (frames)", ylabel="theta (cells)", title="packet heading", ylim=(0, n_th)
        )
    fig.suptitle(title)
    fig.tight_layout()
    if path is None:
        return fig
    from ratslam_graph.atomic import atomic_write_with

    out = Path(path)
    fmt = (out.suffix or ".png").lstrip(".")
    try:
        atomic_write_with(out, lambda fh: fig.savefig(fh, dpi=110, format=fmt))
    finally:
        plt.close(fig)
    return out
