"""Figures: maps, trajectories and pose-cell activity (matplotlib)."""

from torchratslam.viz.plots import (
    plot_map,
    plot_pose_cells,
    save_figure,
)
from torchratslam.viz.pose_cells import (
    plot_activity,
    plot_packet_path,
    projections,
    split_at_wraps,
)

__all__ = [
    "plot_activity",
    "plot_map",
    "plot_packet_path",
    "plot_pose_cells",
    "projections",
    "save_figure",
    "split_at_wraps",
]
