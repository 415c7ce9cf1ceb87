"""Route finding on the temporal map by gradient climbing (experience-map paper, IV B).

Starting at the goal, the climb steps to the linked experience ``i`` that minimises
``t_i + t_ij`` (the steepest descent of the temporal map towards the current experience:
the neighbour the goal's time stamp was proposed from, Eq. 10) until it reaches the
seeded experience. The route lists the experiences from the current one to the goal,
each with its time stamp, i.e. the estimated time to reach it.

:func:`dijkstra_route` is an independent check with networkx's Dijkstra.

Example:
    >>> import numpy as np
    >>> from ratslam_graph.navigation.route import climb_route
    >>> from ratslam_graph.navigation.temporal import adjacency, temporal_map
    >>> adj = adjacency(3, np.array([0, 1, 0]), np.array([1, 2, 2]), np.array([1.0, 1.0, 5.0]))
    >>> climb_route(temporal_map(3, start=0, adj=adj), adj, goal=2).ids
    [0, 1, 2]
"""

from __future__ import annotations

import itertools

import numpy as np

from ratslam_graph.errors import GraphError, InputError
from ratslam_graph.features import Route
from ratslam_graph.navigation.temporal import Adjacency, TemporalMap

__all__ = ["climb_route", "dijkstra_route", "joined_positions", "route_positions"]


def climb_route(tmap: TemporalMap, adj: Adjacency, goal: int) -> Route:
    """The fastest route to ``goal`` by gradient climbing on the temporal map.

    Args:
        tmap: the temporal map seeded at the current (peak) experience.
        adj: the adjacency it was computed on (for a directed one, its transpose: the
            links into each experience).
        goal: the goal experience.

    Returns:
        The route from ``tmap.start`` to ``goal``; ties between equally fast
        predecessors go to the lowest experience id.

    Raises:
        GraphError: if the goal has no finite time stamp (no chain of links).
    """
    n = adj.num_nodes
    if not 0 <= goal < n:
        raise InputError(f"goal experience {goal} is not in [0, {n})")
    t = tmap.times
    if not np.isfinite(t[goal]):
        raise GraphError(f"experience {goal} cannot be reached from {tmap.start}")
    path = [int(goal)]
    seen = np.zeros(n, dtype=bool)
    seen[goal] = True
    j = int(goal)
    while j != tmap.start:
        nbr, w = adj.neighbours(j)  # links of j, traversed towards j
        cost = np.where(seen[nbr], np.inf, t[nbr] + w)
        if len(cost) == 0 or not cost.min() <= t[j] + 1e-9 * max(1.0, t[j]):
            raise GraphError(f"the temporal map does not descend from experience {j}")
        i = int(nbr[cost <= cost.min()].min())
        seen[i] = True
        path.append(i)
        j = i
    path.reverse()
    return Route(ids=path, times=[float(t[i]) for i in path])


def dijkstra_route(
    num_nodes: int,
    src: np.ndarray,
    dst: np.ndarray,
    dt: np.ndarray,
    start: int,
    goal: int,
    *,
    directed: bool = False,
) -> Route:
    """The fastest route by networkx's Dijkstra (a check on :func:`climb_route`).

    Shape:
        src, dst, dt: (E,).

    Raises:
        GraphError: if the goal cannot be reached.
    """
    import networkx as nx  # only this check needs it

    g = nx.DiGraph() if directed else nx.Graph()
    g.add_nodes_from(range(num_nodes))
    for a, b, w in zip(np.asarray(src).tolist(), np.asarray(dst).tolist(), np.asarray(dt).tolist()):
        if not g.has_edge(a, b) or g.edges[a, b]["weight"] > w:
            g.add_edge(a, b, weight=float(w))
    try:
        _, path = nx.single_source_dijkstra(g, start, goal, weight="weight")
    except nx.NetworkXNoPath:
        raise GraphError(f"experience {goal} cannot be reached from {start}") from None
    w = [g.edges[a, b]["weight"] for a, b in itertools.pairwise(path)]
    return Route(ids=[int(i) for i in path], times=np.concatenate([[0.0], np.cumsum(w)]).tolist())


def route_positions(poses: np.ndarray, route: Route) -> np.ndarray:
    """The ``(x, y)`` of the route's experiences in the experience map.

    Shape:
        poses: (N, 3) ``[x, y, th]``. Returns (R, 2).
    """
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    return p[np.asarray(route.ids, dtype=np.int64), :2]


def joined_positions(
    poses: np.ndarray, ids: np.ndarray, src: np.ndarray, dst: np.ndarray
) -> np.ndarray:
    """The route's ``(x, y)`` with its steps between overlapping representations of one
    place closed up.

    A step ``i -> j`` that no link joins (either way) is a turn from one representation
    of a place onto another: the map may hold the two apart by up to the overlap
    radius, or further where no driven link ties them together. The rest of the route
    is shifted so that ``j`` lies on ``i``: past the step the route keeps the shape of
    the links it follows, not the offset between the two representations.

    Shape:
        poses: (N, 3); ids: (R,); src, dst: (E,) the links. Returns (R, 2).
    """
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)[:, :2]
    r = np.asarray(ids, dtype=np.int64).reshape(-1)
    xy = p[r]
    if len(r) < 2:
        return xy
    n = np.int64(len(p))
    s, d = np.asarray(src, dtype=np.int64), np.asarray(dst, dtype=np.int64)
    keys = np.concatenate([s * n + d, d * n + s])
    step = r[:-1] * n + r[1:]
    turn = ~np.isin(step, keys)
    jump = np.where(turn[:, None], xy[:-1] - xy[1:], 0.0)
    return xy + np.vstack([np.zeros((1, 2)), np.cumsum(jump, axis=0)])
