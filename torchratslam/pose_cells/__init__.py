"""Pose cells: the 3D continuous attractor network (stage 2 of the data flow)."""

from torchratslam.pose_cells.network import (
    METHODS,
    PoseCellNetwork,
    PoseCells,
    gaussian_kernel_1d,
    pc_distance,
)

__all__ = ["METHODS", "PoseCellNetwork", "PoseCells", "gaussian_kernel_1d", "pc_distance"]
