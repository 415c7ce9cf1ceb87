"""The compiled nearest experience cell against numpy's pc_distance and argmin."""

from __future__ import annotations

import math

import numpy as np

from ratslam_graph.geometry import pc_distance
from torchratslam.pose_cells._nearest import nearest_cell


def brute(cells, ids, skip, centre, dims):
    """What PoseCells did with numpy: drop ``skip``, distances, the first argmin."""
    ids = np.asarray(ids, np.int64)
    ids = ids[ids != skip]
    if not ids.size:
        return -1, math.inf
    d = pc_distance(cells[ids], np.array(centre), dims)
    k = int(np.argmin(d))
    return int(ids[k]), float(d[k])


def test_nearest_cell_is_numpys_choice_and_distance_bit_for_bit():
    rng = np.random.default_rng(11)
    dims = (21, 13, 36)
    dims_f = tuple(float(v) for v in dims)
    checked = 0
    for _ in range(400):
        m = int(rng.integers(1, 40))
        cells = rng.random((m, 3)) * np.array(dims) * rng.choice([1.0, 2.5])  # some past the wrap
        ids = rng.choice(m, size=int(rng.integers(1, m + 1)), replace=False)
        skip = int(rng.choice(ids)) if rng.random() < 0.5 else -1
        centre = tuple(float(v) for v in rng.random(3) * np.array(dims))
        want = brute(cells, ids, skip, centre, dims)
        got = nearest_cell(cells, ids.astype(np.int64), skip, centre, dims_f)
        assert (int(got[0]), got[1]) == want  # exact: the same operations
        checked += want[0] >= 0
    assert checked > 300


def test_nearest_cell_with_nothing_left_or_a_nan():
    cells = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [np.nan, 1.0, 1.0]])
    dims = (10.0, 10.0, 36.0)
    k, d = nearest_cell(cells, np.array([1], np.int64), 1, (0.0, 0.0, 0.0), dims)
    assert k == -1 and d == math.inf
    k, d = nearest_cell(cells, np.array([0, 2, 1], np.int64), -1, (1.0, 2.0, 3.0), dims)
    want = brute(cells, [0, 2, 1], -1, (1.0, 2.0, 3.0), dims)
    assert k == want[0] == 2 and math.isnan(d) and math.isnan(want[1])  # argmin's NaN
