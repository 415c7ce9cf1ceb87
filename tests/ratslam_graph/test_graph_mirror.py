"""The experience graph's networkx view: brought up to date when read, equal to a graph
built from the arrays by a plain loop after any sequence of changes."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from ratslam_graph.experience_graph import ExperienceGraph
from ratslam_graph.features import link_confidence
from ratslam_graph.link_learning import count_transition
from ratslam_graph.params import ExperienceMapParams

PARAMS = ExperienceMapParams()  # Eq. 9 counted, nothing deleted


def _built_from_scratch(s: ExperienceGraph) -> nx.DiGraph:
    g = nx.DiGraph()
    for i in range(s.n):
        x, y, th = (float(v) for v in s.pose[i])
        pc = tuple(float(v) for v in s.pc[i])
        g.add_node(
            i,
            x=x,
            y=y,
            th=th,
            pc=pc,
            template_id=int(s.vt[i]),
            frame=int(s.frame[i]),
            t=float(s.t[i]),
        )
    for k in range(s.e):
        d, heading, facing, dt = (float(v) for v in s.link[k])
        trav, succ, trials = (int(v) for v in s.counts[k])
        g.add_edge(
            int(s.src[k]),
            int(s.dst[k]),
            d=d,
            heading=heading,
            facing=facing,
            dt=dt,
            traversals=trav,
            successes=succ,
            trials=trials,
            behaviour=int(s.behaviour[k]),
            confidence=float(link_confidence(succ, trials)),
        )
    return g


def _same(a: nx.DiGraph, b: nx.DiGraph) -> None:
    assert list(a.nodes) == list(b.nodes)
    assert dict(a.nodes(data=True)) == dict(b.nodes(data=True))
    assert sorted(a.edges) == sorted(b.edges)
    for u, v in b.edges:
        assert a.edges[u, v] == b.edges[u, v], (u, v)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_view_read_at_random_moments_equals_the_arrays(seed: int) -> None:
    rng = np.random.default_rng(seed)
    s = ExperienceGraph()
    for _ in range(400):
        op = rng.integers(6)
        if op == 0 or s.n < 3:
            s.add_experience(
                *rng.normal(size=3),
                pc=rng.uniform(0, 10, 3),
                template_id=int(rng.integers(9)),
                frame=int(rng.integers(100)),
                t=float(rng.uniform()),
            )
        elif op == 1:
            a, b = (int(v) for v in rng.choice(s.n, 2, replace=False))
            s.add_link(a, b, *rng.uniform(0, 1, 4), behaviour=int(rng.integers(2)))
        elif op == 2 and s.e:
            k = int(rng.integers(s.e))
            s.set_link(k, *rng.uniform(0, 1, 4))
        elif op == 3 and s.e:
            k = int(rng.integers(s.e))
            s.remove_link(int(s.src[k]), int(s.dst[k]))
        elif op == 4 and s.e:
            k = int(rng.integers(s.e))
            count_transition(s, PARAMS, int(s.src[k]), int(s.dst[k]), int(s.behaviour[k]))
        else:
            s.pose[: s.n] += rng.normal(scale=0.1, size=(s.n, 3))
            s.poses_changed()
        if rng.uniform() < 0.15:
            _same(s.graph, _built_from_scratch(s))
    _same(s.graph, _built_from_scratch(s))


def test_a_loaded_graph_is_built_whole_and_then_follows_changes() -> None:
    rng = np.random.default_rng(7)
    s = ExperienceGraph()
    for _ in range(6):
        s.add_experience(*rng.normal(size=3))
    for a in range(5):
        s.add_link(a, a + 1, *rng.uniform(0, 1, 4))
    t = ExperienceGraph()
    t.load(
        {
            "poses": s.pose[: s.n].copy(),
            "pc": s.pc[: s.n].copy(),
            "template_id": s.vt[: s.n].copy(),
            "frame": s.frame[: s.n].copy(),
            "t": s.t[: s.n].copy(),
            "link_ends": np.stack([s.src[: s.e], s.dst[: s.e]], axis=1),
            "link_values": s.link[: s.e].copy(),
            "link_counts": s.counts[: s.e].copy(),
            "link_behaviour": s.behaviour[: s.e].copy(),
        }
    )
    _same(t.graph, _built_from_scratch(s))
    t.remove_link(2, 3)
    t.add_link(0, 5, 1.0, 0.5, 0.25, 2.0)
    _same(t.graph, _built_from_scratch(t))
    assert (2, 3) not in t.graph.edges and (0, 5) in t.graph.edges
