"""MBARAM's match on the CPU in float64 with diagonal covariances, through the numba
kernels of :mod:`torchratslam.mbaram._kernels`: one compiled call per channel and one
to combine them, instead of a dozen tensor operations per channel.

:func:`log_match` is :func:`torchratslam.mbaram.match.log_match`'s computation (the
same equations in the same order); the laser channels' vigilance is tested on the
nodes :func:`~torchratslam.mbaram.match.select` reaches only. Logarithms and
exponentials are the C library's (the tensor path's are torch's), and sums run in
order, so the last bits of a log likelihood may differ from the tensor path's; the
map, the winners and the localisations do not (tested against the tensor path).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np
import torch

from torchratslam.errors import ConfigError
from torchratslam.mbaram.match import ChannelNodes, Vigilance
from torchratslam.mbaram.params import MBARAMParams

__all__ = ["eligible", "log_match"]

_LAZY_DIM = 16
"""Channels with more dimensions (the lasers) are vigilance-tested lazily."""


def eligible(channels: Mapping[str, ChannelNodes], names: Sequence[str]) -> bool:
    """Whether every channel of ``names`` can run compiled: diagonal, float64, CPU."""
    return all(
        not (ch := channels[k]).full and ch.dtype == torch.float64 and ch.device.type == "cpu"
        for k in names
    )


def log_match(
    channels: Mapping[str, ChannelNodes],
    x: Mapping[str, torch.Tensor],
    names: Sequence[str],
    weights: Mapping[str, float],
    params: MBARAMParams,
    counts: torch.Tensor,
    prior: torch.Tensor,
    memo: dict[str, tuple[torch.Tensor, torch.Tensor, Vigilance]] | None = None,
) -> tuple[torch.Tensor, Vigilance]:
    """:func:`torchratslam.mbaram.match.log_match` compiled (see the module docstring)."""
    from torchratslam.mbaram._kernels import combine

    cnt = counts.numpy()
    n = len(cnt)
    logprior = np.log(prior.numpy())
    a = cnt / (cnt + 1.0)
    b = 1.0 / (cnt + 1.0)
    ab, loga = a * b, np.log(a)
    wsum = sum(weights[k] for k in names)
    if wsum <= 0:
        raise ConfigError(f"MBARAM channels {list(names)} all have weight 0; use others")
    terms = []
    passed = np.ones(n, dtype=bool)
    lazy: list[Callable[[torch.Tensor], torch.Tensor]] = []
    for k in names:
        hit = memo.get(k) if memo is not None else None
        if hit is not None and torch.equal(hit[0], x[k]):
            logpost, vig = hit[1].numpy(), hit[2]
        else:
            s_max = params.s_max_odometry if k == "odometry" else params.s_max
            lp, vig = _channel(channels[k], x[k], k, params, ab, loga, logprior, s_max)
            logpost = lp
            if memo is not None:
                memo[k] = (x[k].clone(), torch.from_numpy(lp), vig)
        if weights[k] > 0:
            terms.append(math.log(weights[k] / wsum) + logpost)
        passed &= vig.base.numpy()
        lazy.extend(vig.lazy)
    log_m = combine(np.stack(terms))  # Eq. 3 in log space
    return torch.from_numpy(log_m), Vigilance(torch.from_numpy(passed), tuple(lazy))


def _channel(
    ch: ChannelNodes,
    x: torch.Tensor,
    k: str,
    params: MBARAMParams,
    ab: np.ndarray,
    loga: np.ndarray,
    logprior: np.ndarray,
    s_max: float,
) -> tuple[np.ndarray, Vigilance]:
    """One channel's log posterior (Eqs. 1, 4, 5) and vigilance (Eqs. 7-8, 10)."""
    from torchratslam.mbaram._kernels import (
        gauss_logp,
        normalise,
        outlier_logp,
        updated_logs,
        updated_logs_ang,
    )

    n = len(ab)
    xs = x.numpy()
    mean, cov, logcov, logdet = ch.mean.numpy(), ch.cov.numpy(), ch.logcov.numpy(), ch.logdet
    ang = ch.ang.numpy()
    eps = params.laser_outlier
    if eps > 0 and k != "odometry":
        log_u = math.log(eps / (params.laser_max_range * params.laser_scale))
        logp = outlier_logp(xs, mean, cov, logcov, n, math.log1p(-eps), log_u)
    else:
        logp = gauss_logp(xs, mean, cov, logdet.numpy(), ang, n)
    logpost = normalise(logp, logprior)  # Eqs. 1, 4
    log_smax = math.log(s_max)
    if params.vigilance == "current":
        return logpost, Vigilance(torch.from_numpy(logdet.numpy()[:n] <= log_smax))
    floor = ch.log_floor
    if ch.has_ang or ch.dim <= _LAZY_DIM:
        logs = updated_logs_ang(xs, mean, cov, logcov, ang, n, ab, loga, floor)
        return logpost, Vigilance(torch.from_numpy(logs <= log_smax))  # Eq. 7

    def test(rows: torch.Tensor) -> torch.Tensor:
        idx = rows.numpy().astype(np.int64, copy=False)
        logs = updated_logs(xs, mean, cov, logcov, idx, ab, loga, floor)
        return torch.from_numpy(logs <= log_smax)  # Eq. 7

    return logpost, Vigilance(torch.ones(n, dtype=torch.bool), (test,))
