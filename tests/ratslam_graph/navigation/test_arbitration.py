"""Behaviour arbitration (Fig. 7) against a brute-force distance."""

import math

import numpy as np
import pytest

from ratslam_graph.navigation.arbitration import choose_path, distance_to_polyline, route_ahead


def _point_segment(p, a, b):
    ab = (b[0] - a[0], b[1] - a[1])
    den = ab[0] ** 2 + ab[1] ** 2
    u = 0.0 if den == 0 else ((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / den
    u = min(1.0, max(0.0, u))
    return math.hypot(p[0] - a[0] - u * ab[0], p[1] - a[1] - u * ab[1])


def _brute(paths, route):
    out = []
    for path in paths:
        ds = []
        for p in path.tolist():
            if len(route) == 1:
                ds.append(math.hypot(p[0] - route[0][0], p[1] - route[0][1]))
            else:
                ds.append(
                    min(_point_segment(p, route[k], route[k + 1]) for k in range(len(route) - 1))
                )
        out.append(sum(ds) / len(ds))
    return out


@pytest.mark.parametrize("seed", range(10))
def test_the_closest_path_is_chosen(seed):
    rng = np.random.default_rng(seed)
    route = rng.uniform(-5, 5, (int(rng.integers(1, 8)), 2))
    paths = [
        rng.uniform(-5, 5, (int(rng.integers(1, 12)), 2)) for _ in range(int(rng.integers(1, 5)))
    ]
    a = choose_path(paths, route)
    want = _brute(paths, route.tolist())
    np.testing.assert_allclose(a.distances, want, rtol=1e-12, atol=1e-12)
    assert a.index == int(np.argmin(want))


def test_fig7_left_is_chosen_when_the_route_turns_left():
    route = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 3.0]])  # ahead, then left
    left = np.array([[1.0, 0.0], [2.0, 0.0], [2.0, 1.0], [2.0, 2.0]])
    right = np.array([[1.0, 0.0], [2.0, 0.0], [2.0, -1.0], [2.0, -2.0]])
    straight = np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0], [4.0, 0.0]])
    assert choose_path([straight, right, left], route).index == 2
    assert choose_path([], route).index == -1


def test_route_ahead_cuts_at_the_lookahead():
    r = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    np.testing.assert_allclose(route_ahead(r, 3.0), [[0, 0], [2, 0], [2, 1]])
    np.testing.assert_allclose(route_ahead(r, 10.0), r)
    assert distance_to_polyline(np.array([1.0, 1.0]), r) == pytest.approx(1.0)
