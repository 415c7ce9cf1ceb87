"""Gradient climbing on the temporal map gives the fastest route (networkx brute force)."""

import itertools

import networkx as nx
import numpy as np
import pytest

from ratslam_graph.errors import GraphError
from ratslam_graph.navigation.route import (
    climb_route,
    dijkstra_route,
    joined_positions,
    route_positions,
)
from ratslam_graph.navigation.temporal import adjacency, temporal_map


def _brute_fastest(n, src, dst, w, start, goal):
    """Every simple path, the fastest one (links both ways, parallel ones by min)."""
    g = nx.Graph()
    g.add_nodes_from(range(n))
    for a, b, c in zip(src.tolist(), dst.tolist(), w.tolist()):
        if not g.has_edge(a, b) or g.edges[a, b]["w"] > c:
            g.add_edge(a, b, w=c)
    best = None
    for p in nx.all_simple_paths(g, start, goal):
        t = sum(g.edges[a, b]["w"] for a, b in itertools.pairwise(p))
        if best is None or t < best[0]:
            best = (t, p)
    return best


@pytest.mark.parametrize("seed", range(12))
def test_gradient_climbing_gives_the_fastest_route(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 9))
    src, dst = rng.integers(0, n, 2 * n), rng.integers(0, n, 2 * n)
    keep = src != dst
    src, dst = src[keep], dst[keep]
    w = rng.uniform(0.5, 4.0, len(src))
    start, goal = (int(v) for v in rng.choice(n, 2, replace=False))
    adj = adjacency(n, src, dst, w)
    tm = temporal_map(n, start=start, adj=adj)
    best = _brute_fastest(n, src, dst, w, start, goal)
    if best is None:
        with pytest.raises(GraphError):
            climb_route(tm, adj, goal)
        with pytest.raises(GraphError):
            dijkstra_route(n, src, dst, w, start, goal)
        return
    r = climb_route(tm, adj, goal)
    assert r.ids == best[1]
    assert r.total_time == pytest.approx(best[0], rel=1e-12)
    assert r.times[0] == 0.0 and all(np.diff(r.times) > 0)
    d = dijkstra_route(n, src, dst, w, start, goal)
    assert d.ids == r.ids
    np.testing.assert_allclose(d.times, r.times, rtol=1e-12)


def test_the_climb_avoids_a_short_hop_over_a_slow_link():
    # 0 -1-> 1 -1-> 2 and 0 -5-> 2: the goal's lowest neighbour (0) is not the way
    src, dst, w = np.array([0, 1, 0]), np.array([1, 2, 2]), np.array([1.0, 1.0, 5.0])
    adj = adjacency(3, src, dst, w)
    r = climb_route(temporal_map(3, start=0, adj=adj), adj, 2)
    assert r.ids == [0, 1, 2] and r.times == [0.0, 1.0, 2.0]


def test_route_positions_follow_the_ids():
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 0.5], [3.0, 4.0, 1.0]])
    adj = adjacency(3, np.array([0, 1]), np.array([1, 2]), np.array([1.0, 1.0]))
    r = climb_route(temporal_map(3, start=2, adj=adj), adj, 0)
    assert r.ids == [2, 1, 0]
    np.testing.assert_array_equal(route_positions(poses, r), poses[[2, 1, 0], :2])


def test_joined_positions_close_up_the_steps_that_no_link_joins():
    poses = np.array(
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.5, 0.8, 1.6], [1.5, 1.8, 1.6], [1.5, 2.8, 1.6]]
    )
    src, dst = np.array([0, 3, 2]), np.array([1, 4, 3])  # 1 -> 2 is a turn, no link
    xy = joined_positions(poses, np.arange(5), src, dst)
    shift = poses[1, :2] - poses[2, :2]
    np.testing.assert_allclose(xy[:2], poses[:2, :2])
    np.testing.assert_allclose(xy[2:], poses[2:, :2] + shift)  # 2 lies on 1, the rest follows
    # a link either way is no turn: the positions are the map's
    both = joined_positions(poses, np.arange(5), np.array([0, 2, 2, 3]), np.array([1, 1, 3, 4]))
    np.testing.assert_allclose(both, poses[:, :2])
