"""MBARAM's evaluation measures: quantisation error (Eq. 14), compression ratio (Eq. 15)
and localisation success (Eqs. 16-17)."""

from __future__ import annotations

import numpy as np

from torchratslam.errors import InputError

__all__ = ["compression_ratio", "localisation_success", "quantisation_error"]


def quantisation_error(points: np.ndarray, nodes: np.ndarray) -> float:
    """Eq. 14: mean of ``||x_i - m_{x_i}|| / ||x||_max`` over the data vectors.

    Args:
        points: the data vectors (robot positions). Shape: (T, D).
        nodes: the best-matching node of each. Shape: (T, D).

    Returns:
        The QE; the normaliser ``x_(max)`` is the largest data-vector norm.
    """
    points, nodes = np.asarray(points, float), np.asarray(nodes, float)
    if points.shape != nodes.shape or points.size == 0:
        raise InputError(
            f"QE needs two equal non-empty (T, D) arrays, got {points.shape}, {nodes.shape}"
        )
    scale = float(np.linalg.norm(points, axis=1).max()) or 1.0
    return float(np.linalg.norm(points - nodes, axis=1).mean() / scale)


def compression_ratio(path_size: int, map_size: int) -> float:
    """Eq. 15: original path size (data vectors) over topological map size (nodes)."""
    if map_size <= 0:
        raise InputError("compression ratio of an empty map is undefined")
    return float(path_size) / float(map_size)


def localisation_success(
    node_xy: np.ndarray, true_xy: np.ndarray, threshold: float = 1.0
) -> np.ndarray:
    """Eqs. 16-17: success where the node is closer than ``threshold`` to the robot.

    Args:
        node_xy: the localised node's position per step, NaN where none passed. Shape: (T, 2).
        true_xy: the robot's position. Shape: (T, 2).
        threshold: the distance bound (1 m in the paper).

    Returns:
        Boolean array of shape (T,) (False where no node was found).
    """
    d = np.linalg.norm(np.asarray(node_xy, float) - np.asarray(true_xy, float), axis=1)
    return np.nan_to_num(d, nan=np.inf) < threshold
