"""Localisation over consecutive frames (the paper's Section 4 remedy: "comparing
several time stamps of sensory information"): a discrete Bayes filter over the map's
nodes whose motion model is the map's own edges.

Per frame, the belief ``b`` over nodes is predicted through the transition ``T`` (from
a node to any node within ``hops`` edges, either direction, uniformly; with probability
``jump`` to any node, so a wrong belief can recover) and corrected by the frame's
``log M_j`` (Eqs. 1-6)::

    log b_t = log((1 - jump) b_{t-1} T + jump / N) + log M_t - logsumexp(...)
"""

from __future__ import annotations

import math

import torch

__all__ = ["filter_step", "transition_matrix"]


def transition_matrix(
    edges: torch.Tensor, n: int, hops: int, *, dtype: torch.dtype, device: torch.device
) -> torch.Tensor:
    """Row-stochastic node transition: from node ``i`` uniformly to every node within
    ``hops`` edges of it (either direction, ``i`` itself included).

    Args:
        edges: the map's edges ``(u, v)``. Shape: (E, 2).
        n: number of nodes.
        hops: the most edges the robot crosses between two frames.
        dtype: float dtype of the result.
        device: its device.

    Returns:
        Tensor of shape (n, n) whose rows sum to 1.
    """
    adj = torch.eye(n, dtype=dtype, device=device)
    if len(edges):
        adj[edges[:, 0], edges[:, 1]] = 1.0
        adj[edges[:, 1], edges[:, 0]] = 1.0
    reach = torch.eye(n, dtype=dtype, device=device)
    for _ in range(hops):
        reach = ((reach @ adj) > 0).to(dtype)
    return reach / reach.sum(1, keepdim=True)


def filter_step(
    log_belief: torch.Tensor | None,
    log_m: torch.Tensor,
    transition: torch.Tensor,
    jump: float,
) -> torch.Tensor:
    """One predict-correct step of the node filter.

    Args:
        log_belief: the previous log belief (None: uniform, the first frame).
            Shape: (N,).
        log_m: this frame's ``log M_j``. Shape: (N,).
        transition: :func:`transition_matrix`. Shape: (N, N).
        jump: probability of moving to any node between two frames.

    Returns:
        The new log belief, normalised. Shape: (N,).
    """
    n = len(log_m)
    if log_belief is None:
        prior = torch.full_like(log_m, -math.log(n))
    else:
        prior = ((1.0 - jump) * (log_belief.exp() @ transition) + jump / n).log()
    post = log_m + prior
    return post - torch.logsumexp(post, 0)
