"""The pose-cell demo: a packet driven along a scripted loop (``make demo`` until the
full pipeline demo replaces it).

A 31 x 31 x 36 network starts with its packet in the middle, heading along theta cell
18 (180 degrees), and receives the odometry of a rounded square: straight legs, then
quarter turns. The figure (``pose_cells.png``) shows the final activity, the path of
the decoded packet centre over the integrated odometry (both in cells), and the packet's
heading over time, so one sees the attractor carry the packet with the motion.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from torchratslam.config import PoseCellParams
from torchratslam.pose_cells.network import PoseCellNetwork
from torchratslam.viz.pose_cells import plot_activity

__all__ = ["drive_packet", "run_pose_cell_demo", "scripted_odometry"]


def scripted_odometry(legs: int = 4, straight: int = 12, turn: int = 6) -> np.ndarray:
    """Odometry ``(T, 3)`` [vtrans m/s, vrot rad/s, dt s] of a rounded square."""
    rows = []
    for _ in range(legs):
        rows += [(0.8, 0.0, 1.0)] * straight
        rows += [(0.4, (math.pi / 2) / turn, 1.0)] * turn
    return np.asarray(rows, dtype=np.float64)


def drive_packet(
    params: PoseCellParams, odometry: np.ndarray
) -> tuple[np.ndarray, np.ndarray, PoseCellNetwork]:
    """Drive a fresh network with ``odometry`` and integrate the same odometry exactly.

    Args:
        params: pose-cell parameters.
        odometry: ``(T, 3)`` [vtrans, vrot, dt].

    Returns:
        Packet centres ``(T + 1, 3)`` (x, y, th cells), the integrated odometry
        ``(T + 1, 2)`` (x, y cells, wrapped like the network) and the network.
    """
    net = PoseCellNetwork(params, dtype=torch.float64)
    n_x, _, n_th = net.dims
    centres = [net.centre()[0].numpy()]
    x, y = centres[0][0], centres[0][1]
    heading = centres[0][2] * 2 * math.pi / n_th
    reference = [(x, y)]
    for vtrans, vrot, dt in odometry:
        centres.append(net.step(vtrans, vrot, dt)[0].numpy())
        # the network moves along the heading, then turns: integrate the same way
        d = vtrans * dt / params.pc_cell_x_size
        dx, dy = math.cos(heading), math.sin(heading)
        if params.pc_axis == "openratslam":  # layer k moves along (sin, cos)
            dx, dy = dy, dx
        x, y = (x + d * dx) % n_x, (y + d * dy) % n_x
        heading += vrot * dt
        reference.append((x, y))
    return np.asarray(centres), np.asarray(reference), net


def run_pose_cell_demo(out_dir: Path) -> Path:
    """Run the demo and write ``out_dir/pose_cells.png``.

    Args:
        out_dir: output folder (created if missing).

    Returns:
        The path of the written figure.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    params = PoseCellParams(pc_dim_xy=31, pc_dim_th=36)
    odo = scripted_odometry()
    centres, reference, net = drive_packet(params, odo)
    n_x, _, n_th = net.dims
    return plot_activity(
        net.activity[0],
        out_dir / "pose_cells.png",
        centres=centres,
        reference=reference,
        title=f"pose cells {n_x}x{n_x}x{n_th}: packet along a scripted loop ({len(odo)} steps)",
    )
