"""Pose cells: the 3D continuous attractor network (stage 2 of the data flow)."""

from ratslam_graph.geometry import pc_distance
from torchratslam.pose_cells.functional import gaussian_kernel_1d
from torchratslam.pose_cells.network import METHODS, PoseCellNetwork
from torchratslam.pose_cells.stage import PoseCells

__all__ = ["METHODS", "PoseCellNetwork", "PoseCells", "gaussian_kernel_1d", "pc_distance"]
