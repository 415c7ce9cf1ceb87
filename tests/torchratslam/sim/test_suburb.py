"""The suburb tour: a street grid driven by a car, in a small version."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from torchratslam.errors import InputError
from torchratslam.sim import get_tour
from torchratslam.sim.roads import grid_drive


def test_grid_drive_drives_every_street_both_ways_before_repeating_one():
    n_nodes, pitch = 5, 10.0
    n_directed = 2 * 2 * n_nodes * (n_nodes - 1)
    path = grid_drive(np.random.default_rng(0), n_nodes, 3 * n_directed * pitch, pitch)
    steps = list(itertools.pairwise(path))
    for a, b in steps:  # moves between neighbouring intersections inside the grid
        assert abs(a[0] - b[0]) + abs(a[1] - b[1]) == 1
        assert all(0 <= v < n_nodes for v in (*a, *b))
    counts: dict = {}
    for e in steps:
        counts[e] = counts.get(e, 0) + 1
    # a long drive covers nearly every directed street, several times, with no U-turns
    assert len(counts) >= 0.9 * n_directed
    assert np.mean(list(counts.values())) > 2
    for (a, _), (_, c) in itertools.pairwise(steps):
        assert c != a, "U-turn on a full grid"


def test_small_suburb_tour_has_ground_truth_odometry_and_forward_frames():
    tour = get_tour("suburb", frames=300, seed=1)
    s = tour.full()
    assert len(s) == 300
    img = s.render(10)
    assert img.shape == (64, 128) and img.dtype == np.uint8
    assert img.std() > 5  # facades, not a blank frame
    gt = s.groundtruth()
    step = np.hypot(*np.diff(gt[:, 1:3], axis=0).T)
    np.testing.assert_allclose(step, 1.0, atol=0.01)  # 10 m/s at 10 Hz (chords at corners)
    # the positions stay on the streets: a multiple of the pitch in x or in y
    pitch = 52.0
    xy = gt[:, 1:3]
    off = np.minimum(np.abs(xy / pitch - np.round(xy / pitch)) * pitch, 99).min(axis=1)
    assert off.max() < 4.5  # the rounded corners leave the centre line by < radius
    # noisy odometry: dead reckoning drifts, but not wildly over 300 m
    dr = s.dead_reckoning()
    err = np.hypot(*(dr[:, :2] - gt[:, 1:3]).T)
    assert 0 < err[-1] < 30


def test_suburb_is_deterministic_and_rejects_bad_options():
    a, b = (
        get_tour("suburb", frames=50, seed=3).full(),
        get_tour("suburb", frames=50, seed=3).full(),
    )
    np.testing.assert_array_equal(a.render(20), b.render(20))
    np.testing.assert_array_equal(a.odometry, b.odometry)
    with pytest.raises(InputError):
        get_tour("suburb", blocks=0)
