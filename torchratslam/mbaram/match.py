"""MBARAM's match and vigilance math: per-channel node statistics, the log match
``log M_j`` with the vigilance test, the choice of the winner and the learning rule.

The tensor operations here are the reference; diagonal float64 maps on the CPU run the
same equations compiled (:mod:`torchratslam.mbaram.compiled`, :data:`COMPILED`), with the
same maps, winners and localisations."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from ratslam_graph.geometry import wrap_angle
from torchratslam.errors import ConfigError
from torchratslam.mbaram.params import MBARAMParams

__all__ = ["ChannelNodes", "MatchResult", "Vigilance", "learn_node", "log_match", "select"]

_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class MatchResult:
    """The outcome of one :meth:`MBARAM.learn` or :meth:`MBARAM.localise` call.

    Attributes:
        node: the winning node (the new one when ``is_new``), or -1 when localisation
            found no node that passes vigilance.
        is_new: a new node was created because every existing node failed vigilance.
        rank: position of the winner in the candidate order (0 = the MAP node; -1 when
            new or none).
        log_m: ``log M_J`` of the winner (nan when new or none).
        best: the MAP node before vigilance (-1 for an empty map).
    """

    node: int
    is_new: bool = False
    rank: int = -1
    log_m: float = float("nan")
    best: int = -1


class ChannelNodes:
    """Node statistics of one channel (means, covariances, their logs), with room that
    doubles as nodes are added."""

    def __init__(
        self,
        dim: int,
        full: bool,
        angular: Sequence[int],
        floor: float,
        dtype: torch.dtype,
        device: torch.device,
    ) -> None:
        self.dim = dim
        self.full = full
        self.floor = floor
        self.log_floor = math.log(floor)
        self.ang = torch.zeros(dim, dtype=torch.bool, device=device)
        if len(angular):
            self.ang[list(angular)] = True
        self.has_ang = bool(self.ang.any())
        self.dtype, self.device = dtype, device
        self.mean = torch.empty(0, dim, dtype=dtype, device=device)
        shape = (0, dim, dim) if full else (0, dim)
        self.cov = torch.empty(shape, dtype=dtype, device=device)
        self.chol = torch.empty(shape if full else (0,), dtype=dtype, device=device)
        self.logcov = torch.empty((0,) if full else (0, dim), dtype=dtype, device=device)
        self.logdet = torch.empty(0, dtype=dtype, device=device)

    def grow(self, capacity: int) -> None:
        """Room for ``capacity`` nodes (the stored ones kept)."""

        def bigger(t: torch.Tensor) -> torch.Tensor:
            out = torch.zeros((capacity, *t.shape[1:]), dtype=t.dtype, device=t.device)
            out[: t.shape[0]] = t
            return out

        self.mean, self.cov, self.logdet = bigger(self.mean), bigger(self.cov), bigger(self.logdet)
        if self.full:
            self.chol = bigger(self.chol)
        else:
            self.logcov = bigger(self.logcov)

    def diff(self, x: torch.Tensor, n: int) -> torch.Tensor:
        """``x - mu_j`` of the first ``n`` nodes, angular dimensions wrapped. Shape: (n, D)."""
        d = x - self.mean[:n]
        if self.has_ang:
            d = torch.where(self.ang, wrap_angle(d), d)
        return d

    def maha(self, d: torch.Tensor, n: int) -> torch.Tensor:
        """Squared Mahalanobis distances ``d_j^T Sigma_j^-1 d_j`` (full covariance), (n,)."""
        z = torch.linalg.solve_triangular(self.chol[:n], d.unsqueeze(-1), upper=False)
        return z.squeeze(-1).square().sum(-1)


@dataclass(frozen=True)
class Vigilance:
    """The vigilance test (Eqs. 7-8) of every node: a pass mask of the channels
    computed at once (``base``) and the channels tested only on the nodes asked
    (``lazy``: a function from node indices to their pass mask), the 682-beam laser
    channels, whose test :func:`select` needs on the candidates it reaches only.

    Attributes:
        base: pass mask of the eager channels. Shape: (N,).
        lazy: per lazy channel, ``rows (K,) -> pass mask (K,)``.
    """

    base: torch.Tensor
    lazy: tuple[Callable[[torch.Tensor], torch.Tensor], ...] = field(default=())

    def rows(self, idx: torch.Tensor) -> torch.Tensor:
        """The pass mask of the nodes ``idx`` in every channel. Shape: (K,)."""
        ok = self.base[idx]
        for f in self.lazy:
            ok = ok & f(idx)
        return ok

    def mask(self) -> torch.Tensor:
        """The pass mask of every node in every channel. Shape: (N,)."""
        if not self.lazy:
            return self.base
        return self.rows(torch.arange(len(self.base), device=self.base.device))


def log_match(
    channels: Mapping[str, ChannelNodes],
    x: Mapping[str, torch.Tensor],
    names: Sequence[str],
    weights: Mapping[str, float],
    params: MBARAMParams,
    counts: torch.Tensor,
    prior: torch.Tensor,
    device: torch.device,
    memo: dict[str, tuple[torch.Tensor, torch.Tensor, Vigilance]] | None = None,
) -> tuple[torch.Tensor, Vigilance]:
    """``log M_j`` (Eqs. 1-6 in log space) and the vigilance pass mask (Eqs. 7-8) of
    every node.

    Args:
        channels: the node statistics per channel.
        x: the input per channel. Shape: (D_k,) each.
        names: the channels that compete; their weights are renormalised.
        weights: channel weights alpha_k.
        params: the parameters (S_MAX, outlier model, vigilance variant).
        counts: ``N_j`` of every node. Shape: (N,).
        prior: ``P(w_j)`` of every node. Shape: (N,).
        device: the device of the node statistics.
        memo: channel -> (input, log posterior, vigilance) of the last input seen on an
            unchanged map: a channel whose input equals the stored one reuses its terms
            (the same numbers, computed once), e.g. the laser channels of one frame
            localised with and without odometry. The caller clears it when the map
            changes; None computes every channel.

    Returns:
        ``log M_j`` (shape (N,)) and the :class:`Vigilance` of every node.
    """
    if COMPILED and counts.dtype == torch.float64:
        from torchratslam.mbaram import compiled

        if compiled.eligible(channels, names):
            return compiled.log_match(channels, x, names, weights, params, counts, prior, memo)
    n = len(counts)
    logprior = prior.log()
    a = counts / (counts + 1.0)  # N/(N+1)
    b = 1.0 / (counts + 1.0)  # 1/(N+1)
    wsum = sum(weights[k] for k in names)
    if wsum <= 0:
        raise ConfigError(f"MBARAM channels {list(names)} all have weight 0; use others")
    log_terms = []
    passed = torch.ones(n, dtype=torch.bool, device=device)
    lazy: list[Callable[[torch.Tensor], torch.Tensor]] = []
    for k in names:
        hit = memo.get(k) if memo is not None else None
        if hit is not None and torch.equal(hit[0], x[k]):
            logpost, ok = hit[1], hit[2]
        else:
            s_max = params.s_max_odometry if k == "odometry" else params.s_max
            logpost, ok = _channel_terms(channels[k], x[k], k, params, a, b, logprior, s_max)
            if memo is not None:
                memo[k] = (x[k].clone(), logpost, ok)
        if weights[k] > 0:
            log_terms.append(math.log(weights[k] / wsum) + logpost)
        passed &= ok.base
        lazy.extend(ok.lazy)
    log_m = torch.logsumexp(torch.stack(log_terms), 0)  # Eq. 3 in log space
    return log_m, Vigilance(passed, tuple(lazy))


COMPILED = True
"""Match diagonal float64 maps on the CPU with :mod:`torchratslam.mbaram.compiled`
(False: the tensor path below, the reference the compiled one is tested against)."""


def _channel_terms(
    ch: ChannelNodes,
    x: torch.Tensor,
    k: str,
    params: MBARAMParams,
    a: torch.Tensor,
    b: torch.Tensor,
    logprior: torch.Tensor,
    s_max: float,
) -> tuple[torch.Tensor, Vigilance]:
    """One channel's log posterior ``log P(w_j | x_k)`` (Eqs. 1, 4, 5) and its vigilance
    (Eqs. 7-8, 10) over the N nodes of :func:`log_match`. Shape: (N,) each."""
    n = len(a)
    eps = params.laser_outlier
    outlier = eps > 0 and k != "odometry" and not ch.full
    log_u = math.log(eps / (params.laser_max_range * params.laser_scale)) if outlier else 0.0
    d = ch.diff(x, n)  # (n, D)
    if ch.full:
        q = ch.maha(d, n)
    else:
        r = d.square_().div_(ch.cov[:n])  # (x - mu)^2 / sigma^2 per dimension
    if outlier:
        # per beam log((1 - eps) N(x; mu, s2) + eps / R): a beam blocked by a
        # pedestrian or a moved box costs at most -log(eps / R), not (x - mu)^2 / s2
        logn = (r + ch.logcov[:n] + _LOG_2PI).mul_(-0.5).add_(math.log1p(-eps))
        logp = torch.logaddexp(logn, torch.full_like(logn, log_u)).sum(-1)
    else:
        if not ch.full:
            q = r.sum(-1)
        logp = -0.5 * (ch.dim * _LOG_2PI + ch.logdet[:n] + q)  # Eq. 5
    joint = logp + logprior
    logpost = joint - torch.logsumexp(joint, 0)  # Eqs. 1, 4
    if params.vigilance == "current":
        logs = ch.logdet[:n]
    elif ch.full:
        # det(a Sigma + b d'd'^T), d' = a d: matrix determinant lemma (Eq. 10)
        logs = ch.dim * a.log() + ch.logdet[:n] + torch.log1p(a * b * q)
    else:
        # Eq. 10 per dimension: a s2 + b (a d)^2 = a s2 (1 + a b d^2 / s2), floored
        # as learning floors it; log S' = sum of the logs (Eq. 8)
        logv = r.mul_((a * b)[:, None]).log1p_().add_(ch.logcov[:n]).add_(a.log()[:, None])
        logs = logv.clamp_min_(ch.log_floor).sum(-1)
    return logpost, Vigilance(logs <= math.log(s_max))  # Eq. 7


def select(log_m: torch.Tensor, passed: Vigilance | torch.Tensor) -> MatchResult:
    """The best node that passes vigilance ("reset the winner and try the next best",
    without a loop over nodes): candidates ordered once by ``log M_j`` (Eq. 6); the
    lazy channels of a :class:`Vigilance` are tested on the candidates in that order,
    one, then blocks growing eightfold, until one passes.

    Shape:
        log_m, passed: (N,) with N >= 1.
    """
    vig = passed if isinstance(passed, Vigilance) else Vigilance(passed)
    if log_m.device.type == "cpu" and vig.base.device.type == "cpu":
        # numpy's stable sort of -log M is torch's stable descending sort, cheaper
        order = torch.from_numpy(np.argsort(-log_m.numpy(), kind="stable"))
        ranks = torch.from_numpy(np.flatnonzero(vig.base.numpy()[order.numpy()]))
    else:
        order = torch.argsort(log_m, descending=True, stable=True)  # Eq. 6, then next best
        ranks = torch.nonzero(vig.base[order]).squeeze(1)  # passing the eager channels
    best = int(order[0])
    start, size = 0, 1
    while start < len(ranks):
        block = ranks[start : start + size] if vig.lazy else ranks
        ok = vig.rows(order[block]) if vig.lazy else torch.ones(len(block), dtype=torch.bool)
        if bool(ok.any()):
            rank = int(block[int(torch.argmax(ok.to(torch.int8)))])
            node = int(order[rank])
            return MatchResult(node, rank=rank, log_m=float(log_m[node]), best=best)
        start, size = start + len(block), size * 8
    return MatchResult(-1, best=best)


def learn_node(ch: ChannelNodes, j: int, x: torch.Tensor, a: float, b: float) -> None:
    """Learn input ``x`` into node ``j`` of one channel (Eqs. 9-10), in place.

    Args:
        ch: the channel's node statistics.
        j: the node.
        x: the input. Shape: (D,).
        a: ``N_j / (N_j + 1)``.
        b: ``1 / (N_j + 1)``.
    """
    floor = ch.floor
    if (
        COMPILED
        and not ch.full
        and ch.dtype == torch.float64
        and ch.device.type == "cpu"
        and x.dtype == torch.float64
    ):
        from torchratslam.mbaram._kernels import learn_diag

        m, c, lc, ld = ch.mean.numpy(), ch.cov.numpy(), ch.logcov.numpy(), ch.logdet.numpy()
        learn_diag(m, c, lc, ld, j, x.numpy(), ch.ang.numpy(), a, b, floor)
        return
    d = x - ch.mean[j]
    if ch.has_ang:
        d = torch.where(ch.ang, wrap_angle(d), d)
    mu = ch.mean[j] + b * d  # Eq. 9
    if ch.has_ang:
        mu = torch.where(ch.ang, wrap_angle(mu), mu)
    dn = a * d  # x - mu_new
    if ch.full:
        cov = a * ch.cov[j] + b * torch.outer(dn, dn)  # Eq. 10 (full)
        diag = cov.diagonal()
        diag.clamp_(min=floor)
        chol = torch.linalg.cholesky(cov)
        ch.cov[j], ch.chol[j] = cov, chol
        ch.logdet[j] = 2.0 * chol.diagonal().log().sum()
    else:
        var = (a * ch.cov[j] + b * dn.square()).clamp_min(floor)  # Eq. 10 (x I)
        ch.cov[j] = var
        ch.logcov[j] = var.log()
        ch.logdet[j] = ch.logcov[j].sum()
    ch.mean[j] = mu
