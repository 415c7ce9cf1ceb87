"""The node filter of MBARAM's localisation over consecutive frames."""

from __future__ import annotations

import math

import networkx as nx
import numpy as np
import pytest
import torch

from torchratslam.mbaram.tracking import filter_step, transition_matrix


@pytest.mark.parametrize("hops", [0, 1, 3])
def test_transition_is_uniform_over_the_hop_neighbourhood(hops):
    g = nx.gnm_random_graph(12, 14, seed=3, directed=True)
    edges = torch.tensor(list(g.edges), dtype=torch.long)
    t = transition_matrix(edges, 12, hops, dtype=torch.float64, device=torch.device("cpu"))
    und = g.to_undirected()
    for i in range(12):
        near = nx.single_source_shortest_path_length(und, i, cutoff=hops)
        want = np.zeros(12)
        want[list(near)] = 1.0 / len(near)
        np.testing.assert_allclose(t[i].numpy(), want, atol=1e-12)


def test_filter_step_by_hand():
    t = transition_matrix(
        torch.tensor([[0, 1], [1, 2]]), 3, 1, dtype=torch.float64, device=torch.device("cpu")
    )
    log_m = torch.tensor([-1.0, -2.0, -0.5], dtype=torch.float64)
    first = filter_step(None, log_m, t, 0.1)
    m = np.exp(log_m.numpy())
    np.testing.assert_allclose(first.exp().numpy(), m / m.sum())
    # a belief all on node 0 predicts node 0 and 1 (half each of 0.9) plus 0.1 / 3 jumps
    b = torch.log(torch.tensor([1.0, 1e-300, 1e-300], dtype=torch.float64))
    got = filter_step(b, log_m, t, 0.1).exp().numpy()
    prior = np.array([0.45, 0.45, 0.0]) + 0.1 / 3
    want = np.exp(log_m.numpy()) * prior
    np.testing.assert_allclose(got, want / want.sum(), rtol=1e-9)
    assert math.isclose(got.sum(), 1.0)
    # jump = 1 forgets the past: the belief is this frame's normalised M
    np.testing.assert_allclose(filter_step(b, log_m, t, 1.0).numpy(), first.numpy())
