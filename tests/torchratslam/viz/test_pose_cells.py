"""Pose-cell figures and the demo."""

from __future__ import annotations

import matplotlib.image as mpimg
import numpy as np
import torch

from torchratslam.config import PoseCellParams
from torchratslam.experiments.pose_cell_demo import (
    drive_packet,
    run_pose_cell_demo,
    scripted_odometry,
)
from torchratslam.viz.pose_cells import plot_activity, projections, split_at_wraps


def test_split_at_wraps_cuts_only_at_ring_jumps():
    path = np.array([[18.0, 5.0], [19.5, 5.2], [0.4, 5.3], [1.2, 5.5], [1.0, 20.5], [1.1, 0.2]])
    pieces = split_at_wraps(path, (21, 21))
    assert [len(p) for p in pieces] == [2, 2, 1, 1]
    np.testing.assert_array_equal(np.concatenate(pieces), path)


def test_projections_sum_over_the_right_axes():
    a = np.random.default_rng(0).random((6, 5, 4))
    xy, th = projections(torch.from_numpy(a))
    np.testing.assert_allclose(xy, a.sum(axis=0))
    np.testing.assert_allclose(th, a.sum(axis=(1, 2)))


def test_plot_activity_writes_a_png(tmp_path):
    a = np.zeros((36, 21, 21))
    a[18, 10, 10] = 1.0
    centres = np.array([[10.0, 10.0, 18.0], [20.5, 10.0, 18.0], [0.3, 10.0, 19.0]])
    out = plot_activity(a, tmp_path / "pc.png", centres=centres, reference=centres[:, :2])
    img = mpimg.imread(out)
    assert img.ndim == 3 and img.shape[0] > 100 and img.std() > 0


def test_demo_writes_pose_cells_png(tmp_path):
    out = run_pose_cell_demo(tmp_path / "demo")
    assert out == tmp_path / "demo" / "pose_cells.png"
    img = mpimg.imread(out)
    assert img.shape[1] > img.shape[0] > 100


def test_demo_packet_follows_the_odometry_round_the_loop():
    odo = scripted_odometry()
    assert np.isclose((odo[:, 1] * odo[:, 2]).sum(), 2 * np.pi)  # one full turn
    centres, reference, _ = drive_packet(PoseCellParams(pc_dim_xy=31, pc_dim_th=36), odo)
    d = (centres[:, :2] - reference + 15.5) % 31 - 15.5
    assert np.abs(d).max() < 0.6
    dth = (centres[-1, 2] - centres[0, 2] + 18) % 36 - 18
    assert abs(dth) < 0.2  # the heading came round to the start


def test_the_activity_panel_has_a_labelled_colour_bar_over_its_values():
    from torchratslam.viz.pose_cells import COLOUR_LABEL

    a = np.zeros((36, 21, 21))
    a[18, 10, 10], a[3, 4, 5] = 0.75, 0.25  # the network's activity sums to 1
    fig = plot_activity(a)
    bars = [ax for ax in fig.axes if ax.get_ylabel() == COLOUR_LABEL]
    assert len(bars) == 1
    lo, hi = bars[0].get_ylim()
    assert lo == 0.0 and hi == 0.75  # the colour scale spans the summed activity
    assert "fraction" in COLOUR_LABEL
