"""The temporal map (Eqs. 10-11) against brute-force Dijkstra and the paper's iteration."""

import numpy as np
import pytest

from ratslam_graph.errors import InputError
from ratslam_graph.features import temporal_map as iterate_temporal_map
from ratslam_graph.navigation.temporal import adjacency, temporal_map


def _random_graph(rng, n, e):
    src = rng.integers(0, n, e)
    dst = rng.integers(0, n, e)
    ok = src != dst
    return src[ok], dst[ok], rng.uniform(0.1, 5.0, ok.sum())


def _brute_dijkstra(n, src, dst, w, start):
    """O(N^2) Dijkstra with plain lists, links both ways."""
    t = [float("inf")] * n
    t[start] = 0.0
    done = [False] * n
    for _ in range(n):
        i = min((k for k in range(n) if not done[k]), key=lambda k: t[k], default=None)
        if i is None or t[i] == float("inf"):
            break
        done[i] = True
        for a, b, c in zip(src.tolist(), dst.tolist(), w.tolist()):
            for p, q in ((a, b), (b, a)):
                if p == i and t[i] + c < t[q]:
                    t[q] = t[i] + c
    return np.array(t)


@pytest.mark.parametrize("seed", range(8))
def test_the_temporal_map_equals_brute_force_dijkstra(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 40))
    src, dst, w = _random_graph(rng, n, int(rng.integers(1, 3 * n)))
    start = int(rng.integers(n))
    tm = temporal_map(n, src, dst, w, start)
    np.testing.assert_allclose(tm.times, _brute_dijkstra(n, src, dst, w, start), rtol=1e-12)
    # the paper's synchronous iteration reaches the same fixed point
    edges = np.stack([src, dst], 1)
    np.testing.assert_allclose(tm.times, iterate_temporal_map(n, edges, w, start), rtol=1e-12)
    # every reached experience's time was proposed by its parent over a link (Eq. 10)
    for j in np.nonzero(np.isfinite(tm.times))[0]:
        i = tm.parent[j]
        if j == start:
            assert i == -1
            continue
        link = ((src == i) & (dst == j)) | ((src == j) & (dst == i))
        assert np.isclose(tm.times[j], tm.times[i] + w[link].min())
    assert np.all(tm.parent[~np.isfinite(tm.times)] == -1)


def test_directed_links_and_masks():
    src, dst, w = np.array([0, 1]), np.array([1, 2]), np.array([1.0, 2.0])
    assert temporal_map(3, src, dst, w, 2, directed=True).times.tolist() == [np.inf, np.inf, 0.0]
    assert temporal_map(3, src, dst, w, 2).times.tolist() == [3.0, 2.0, 0.0]
    adj = adjacency(3, src, dst, w, keep=np.array([True, False]))
    assert temporal_map(3, start=0, adj=adj).times.tolist() == [0.0, 1.0, np.inf]


def test_parallel_links_keep_the_fastest():
    tm = temporal_map(2, np.array([0, 1, 0]), np.array([1, 0, 1]), np.array([3.0, 1.0, 2.0]), 0)
    assert tm.times.tolist() == [0.0, 1.0]


def test_bad_inputs_raise():
    with pytest.raises(InputError):
        temporal_map(2, np.array([0]), np.array([1]), np.array([-1.0]), 0)
    with pytest.raises(InputError):
        temporal_map(2, np.array([0]), np.array([5]), np.array([1.0]), 0)
    with pytest.raises(InputError):
        temporal_map(2, np.array([0]), np.array([1]), np.array([1.0]), 3)
    with pytest.raises(InputError):
        temporal_map(2)
