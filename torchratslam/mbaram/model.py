"""MBARAM: a multi-channel Bayesian ART topological mapper (Chin et al., 2015).

Every node of the map is, per sensor channel ``k`` (front laser, rear laser, odometry),
a Gaussian region with mean ``mu[j, k]``, covariance ``Sigma[j, k]`` (diagonal as in the
paper's experiments, full as an option), a prior ``P(w_j)`` and a count ``N_j``. For
each input all nodes compete at once:

* competition (Eqs. 1-6): per channel the posterior ``P(w_j | x_k)`` (Gaussian
  likelihood times prior, normalised over nodes), combined as
  ``M_j = sum_k alpha_k P(w_j | x_k)``. Everything is done in log space
  (``log M_j = logsumexp_k(log alpha_k + log P(w_j | x_k))``), so a 682-beam
  likelihood, a product of hundreds of small densities, never underflows and the
  ordering of the losers is kept;
* vigilance (Eqs. 7-8): the hypervolume ``S_{j,k} = det(Sigma_{j,k})`` must stay below
  ``S_MAX`` in every channel. "Reset the winner and try the next best" is done without
  a loop over nodes: the candidates are ordered once by ``log M_j`` and the first one
  that passes is taken;
* learning (Eqs. 9-12) of the winner, or a new node when no node passes; an edge from
  the previous winner to the winner stores the adjacent angle between them.

The map is a :class:`networkx.DiGraph` whose nodes carry ``x``, ``y``, ``th`` (the
odometry channel's mean, in metres and radians) and whose edges carry ``d``,
``heading``, ``facing`` (RatSLAM link convention) plus ``angle`` (the adjacent angle,
world frame) and ``count``, so the experience-map plots and route planning work on it.

Node localisation (Section 2.1.3) is :meth:`MBARAM.localise`; the evaluation measures
are :func:`quantisation_error` (Eq. 14), :func:`compression_ratio` (Eq. 15) and
:func:`localisation_success` (Eqs. 16-17). :func:`run_mbaram` maps laps of a
:class:`~torchratslam.messages.Frame` stream and localises on further laps, with and
without the odometry channel.

MBARAM is a laser-and-odometry mapper, not an image local view nor a pose-cell
experience map: :class:`MBARAMMapper` (the frame-level module, lasers of the simulator
and odometry in, node out) is registered as ``"mbaram"`` in
:data:`torchratslam.registry.RANGE_MAPPERS`, and :func:`run_mbaram` builds its mapper
from that registry by name.


Example:
    >>> import torch
    >>> from torchratslam.mbaram.model import MBARAM, MBARAMParams
    >>> m = MBARAM(MBARAMParams(), channels={"a": 0.5, "b": 0.5})
    >>> m.learn({"a": torch.zeros(4), "b": torch.ones(2)}).is_new
    True
    >>> m.learn({"a": torch.zeros(4), "b": torch.ones(2)}).node
    0
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, cast

import networkx as nx
import numpy as np
import torch

from ratslam_graph.errors import ConfigError, InputError, MapFormatError
from ratslam_graph.geometry import odometry_step, wrap_angle
from ratslam_graph.params import Params, param
from torchratslam.messages import Frame
from torchratslam.registry import RANGE_MAPPERS

__all__ = [
    "LASER_CHANNELS",
    "MBARAM",
    "MBARAMMapper",
    "MBARAMParams",
    "MatchResult",
    "OdometryIntegrator",
    "RunResult",
    "compression_ratio",
    "frame_inputs",
    "localisation_success",
    "quantisation_error",
    "run_mbaram",
]

LASER_CHANNELS = ("laser_front", "laser_rear")
"""The laser channels of the paper's three-channel setup (the third is ``odometry``)."""

STATE_VERSION = 1
_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class MBARAMParams(Params):
    """MBARAM parameters; defaults are the paper's Table 3 (indoor and outdoor)."""

    section: ClassVar[str] = "mbaram"

    s_max: float = param(1.0, "S_MAX,k: maximal hypervolume det(Sigma) of a node (lasers)", gt=0.0)
    s_max_odometry: float = param(1.0, "S_MAX,k of the odometry channel (Eq. 7)", gt=0.0)
    sigma_init_sq: float = param(0.01, "sigma_init^2: initial variance of a new node", gt=0.0)
    p_init: float = param(1.0, "P(w_j)_init: prior probability of a new node", gt=0.0)
    alpha_laser_front: float = param(0.4, "channel weight alpha of the front laser", ge=0.0)
    alpha_laser_rear: float = param(0.4, "channel weight alpha of the rear laser", ge=0.0)
    alpha_odometry: float = param(0.2, "channel weight alpha of the odometry channel", ge=0.0)
    covariance: str = param(
        "diag", "node covariance: diag (paper) | full", choices=("diag", "full")
    )
    vigilance: str = param(
        "updated",
        "hypervolume tested by Eq. 7: of the node after tentatively learning the input "
        "(updated) or as it stands (current)",
        choices=("updated", "current"),
    )
    var_floor: float = param(1e-6, "lower bound on every laser variance (numerical safety)", gt=0.0)
    var_floor_odometry: float = param(1e-6, "lower bound on every odometry variance", gt=0.0)
    laser_scale: float = param(1.0, "range units per metre fed to the laser channels", gt=0.0)
    laser_max_range: float = param(
        30.0, "ranges are clipped to [0, laser_max_range] metres", gt=0.0
    )
    odo_scale: float = param(1.0, "position units per metre fed to the odometry channel", gt=0.0)
    laser_outlier: float = param(
        0.0,
        "laser channels: weight eps of a uniform outlier density on [0, laser_max_range] "
        "mixed into each beam's Gaussian, p = (1 - eps) N + eps U (0 = off, the paper's "
        "Gaussian); diagonal covariance only",
        ge=0.0,
        lt=1.0,
    )
    loc_threshold: float = param(
        1.0, "Eq. 16: success when node-to-robot distance < this (m)", gt=0.0
    )

    def channel_weights(self) -> dict[str, float]:
        """The paper's three channels and their weights alpha_k."""
        return {
            "laser_front": self.alpha_laser_front,
            "laser_rear": self.alpha_laser_rear,
            "odometry": self.alpha_odometry,
        }


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


class _Channel:
    """Node storage of one channel, with room that doubles as nodes are added."""

    def __init__(
        self, dim: int, full: bool, angular: Sequence[int], floor: float, dtype, device
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
        d = x - self.mean[:n]
        if self.has_ang:
            d = torch.where(self.ang, wrap_angle(d), d)
        return d

    def maha(self, d: torch.Tensor, n: int) -> torch.Tensor:
        """Squared Mahalanobis distances ``d_j^T Sigma_j^-1 d_j`` (full covariance), (n,)."""
        z = torch.linalg.solve_triangular(self.chol[:n], d.unsqueeze(-1), upper=False)
        return z.squeeze(-1).square().sum(-1)


class MBARAM:
    """Multi-channel Bayesian Adaptive Resonance Associative Memory.

    Args:
        params: the parameters (defaults: the paper's).
        channels: channel name -> weight alpha_k (must sum to 1); default the paper's
            ``laser_front``/``laser_rear``/``odometry`` with the weights of ``params``.
        angular: channel name -> indices of angular dimensions (differences wrapped to
            (-pi, pi]); default ``{"odometry": (2,)}`` (the heading).
        position_channel: channel whose mean gives the node's ``x, y, th`` (in units of
            ``params.odo_scale``); None stores zeros.
        dtype: float dtype of the node statistics (float64 by default: cheap here and
            robust for long scans).
        device: torch device.

    Inputs are dicts ``{channel: Tensor (D_k,)}``; the dimension of each channel is
    fixed by the first input.
    """

    def __init__(
        self,
        params: MBARAMParams | None = None,
        channels: Mapping[str, float] | None = None,
        *,
        angular: Mapping[str, Sequence[int]] | None = None,
        position_channel: str | None = "odometry",
        dtype: torch.dtype = torch.float64,
        device: torch.device | str | None = None,
    ) -> None:
        self.params = params if params is not None else MBARAMParams()
        weights = dict(channels) if channels is not None else self.params.channel_weights()
        if not weights:
            raise ConfigError("MBARAM needs at least one channel: pass channels={name: weight}")
        if any(w < 0 or not math.isfinite(w) for w in weights.values()):
            raise ConfigError(f"MBARAM channel weights must be finite and >= 0, got {weights}")
        total = sum(weights.values())
        if abs(total - 1.0) > 1e-6:
            raise ConfigError(
                f"MBARAM channel weights alpha_k must sum to 1 (paper, Eq. 3), got {total:g} "
                f"for {weights}; rescale them"
            )
        self.weights = weights
        self.names = tuple(weights)
        self.angular = {
            k: tuple(v) for k, v in (angular if angular is not None else {"odometry": (2,)}).items()
        }
        self.position_channel = position_channel if position_channel in weights else None
        self.dtype = dtype
        self.device = torch.device(device) if device is not None else torch.device("cpu")
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget every node and edge."""
        self._ch: dict[str, _Channel] = {}
        self._n = 0
        self._cap = 0
        self.counts = torch.zeros(0, dtype=self.dtype, device=self.device)
        self.prior = torch.zeros(0, dtype=self.dtype, device=self.device)
        self.graph = nx.DiGraph()
        self.prev_winner = -1

    def __len__(self) -> int:
        return self._n

    @property
    def num_nodes(self) -> int:
        return self._n

    @property
    def num_edges(self) -> int:
        return self.graph.number_of_edges()

    @property
    def dims(self) -> dict[str, int]:
        """Dimension of each channel (empty until the first input)."""
        return {k: c.dim for k, c in self._ch.items()}

    def means(self, channel: str) -> torch.Tensor:
        """Node means of one channel. Shape: (N, D_k)."""
        return self._ch[channel].mean[: self._n]

    def covariances(self, channel: str) -> torch.Tensor:
        """Node covariances of one channel. Shape: (N, D_k) diagonal or (N, D_k, D_k) full."""
        return self._ch[channel].cov[: self._n]

    def hypervolumes(self, channel: str) -> torch.Tensor:
        """``log S_{j,k} = log det Sigma_{j,k}`` (Eq. 8) of every node. Shape: (N,)."""
        return self._ch[channel].logdet[: self._n]

    @property
    def positions(self) -> np.ndarray:
        """Node positions ``[x, y, th]`` in metres/radians, shape (N, 3)."""
        if self._n == 0:
            return np.zeros((0, 3))
        return np.array(
            [[self.graph.nodes[j][a] for a in ("x", "y", "th")] for j in range(self._n)]
        )

    # --------------------------------------------------------------- checking
    def _check(self, inputs: Mapping[str, Any], names: Iterable[str]) -> dict[str, torch.Tensor]:
        out = {}
        for k in names:
            if k not in inputs:
                raise InputError(
                    f"MBARAM input lacks channel {k!r} (got {sorted(inputs)}); pass every "
                    f"channel of {list(self.names)}"
                )
            v = inputs[k]
            if isinstance(v, np.ndarray):
                v = np.ascontiguousarray(v)
            x = torch.as_tensor(v, dtype=self.dtype, device=self.device)
            if x.dim() != 1 or x.numel() == 0:
                raise InputError(
                    f"MBARAM channel {k!r} must be a non-empty 1-D vector, "
                    f"got shape {tuple(x.shape)}"
                )
            if not bool(torch.isfinite(x).all()):
                bad = int((~torch.isfinite(x)).sum())
                raise InputError(
                    f"MBARAM channel {k!r} has {bad} NaN/inf value(s); clean the input first "
                    "(frame_inputs clips laser ranges and rejects NaN)"
                )
            if k in self._ch and x.numel() != self._ch[k].dim:
                raise InputError(
                    f"MBARAM channel {k!r} has dimension {x.numel()} but the map was built with "
                    f"{self._ch[k].dim}; feed scans of one length (or start a new map)"
                )
            out[k] = x
        return out

    def _channel_names(self, channels: Iterable[str] | None) -> tuple[str, ...]:
        if channels is None:
            return self.names
        names = tuple(channels)
        unknown = [k for k in names if k not in self.weights]
        if unknown or not names:
            raise ConfigError(
                f"unknown MBARAM channel(s) {unknown or names}; valid: {list(self.names)}"
            )
        return names

    # ------------------------------------------------------------- the model
    def _evaluate(self, x: dict[str, torch.Tensor], names: Sequence[str]):
        """``log M_j`` (N,) and the vigilance pass mask (N,) of every node."""
        n = self._n
        logprior = self.prior[:n].log()
        counts = self.counts[:n]
        a = counts / (counts + 1.0)  # N/(N+1)
        b = 1.0 / (counts + 1.0)  # 1/(N+1)
        wsum = sum(self.weights[k] for k in names)
        if wsum <= 0:
            raise ConfigError(f"MBARAM channels {list(names)} all have weight 0; use others")
        log_terms = []
        passed = torch.ones(n, dtype=torch.bool, device=self.device)
        log_smax = {k: math.log(self.params.s_max) for k in names}
        if "odometry" in log_smax:
            log_smax["odometry"] = math.log(self.params.s_max_odometry)
        for k in names:
            ch = self._ch[k]
            d = ch.diff(x[k], n)  # (n, D)
            if ch.full:
                q = ch.maha(d, n)
            else:
                r = d.square_().div_(ch.cov[:n])  # (x - mu)^2 / sigma^2 per dimension
                q = r.sum(-1)
            eps = self.params.laser_outlier
            if eps > 0 and k != "odometry" and not ch.full:
                # per beam log((1 - eps) N(x; mu, s2) + eps / R): a beam blocked by a
                # pedestrian or a moved box costs at most -log(eps / R), not (x - mu)^2 / s2
                log_u = math.log(eps / (self.params.laser_max_range * self.params.laser_scale))
                logn = (r + ch.logcov[:n] + _LOG_2PI).mul_(-0.5).add_(math.log1p(-eps))
                logp = torch.logaddexp(logn, torch.full_like(logn, log_u)).sum(-1)
            else:
                logp = -0.5 * (ch.dim * _LOG_2PI + ch.logdet[:n] + q)  # Eq. 5
            joint = logp + logprior
            logpost = joint - torch.logsumexp(joint, 0)  # Eqs. 1, 4
            if self.weights[k] > 0:
                log_terms.append(math.log(self.weights[k] / wsum) + logpost)
            if self.params.vigilance == "current":
                logs = ch.logdet[:n]
            elif ch.full:
                # det(a Sigma + b d'd'^T), d' = a d: matrix determinant lemma (Eq. 10)
                logs = ch.dim * a.log() + ch.logdet[:n] + torch.log1p(a * b * q)
            else:
                # Eq. 10 per dimension: a s2 + b (a d)^2 = a s2 (1 + a b d^2 / s2), floored
                # as learning floors it; log S' = sum of the logs (Eq. 8)
                logv = r.mul_((a * b)[:, None]).log1p_().add_(ch.logcov[:n]).add_(a.log()[:, None])
                logs = logv.clamp_min_(ch.log_floor).sum(-1)
            passed &= logs <= log_smax[k]  # Eq. 7
        log_m = torch.logsumexp(torch.stack(log_terms), 0)  # Eq. 3 in log space
        return log_m, passed

    def _select(self, x, names) -> MatchResult:
        if self._n == 0:
            return MatchResult(-1)
        log_m, passed = self._evaluate(x, names)
        order = torch.argsort(log_m, descending=True, stable=True)  # Eq. 6, then next best
        ok = passed[order]
        best = int(order[0])
        if not bool(ok.any()):
            return MatchResult(-1, best=best)
        rank = int(torch.argmax(ok.to(torch.int8)))
        node = int(order[rank])
        return MatchResult(node, rank=rank, log_m=float(log_m[node]), best=best)

    def scores(
        self, inputs: Mapping[str, Any], channels: Iterable[str] | None = None
    ) -> torch.Tensor:
        """``log M_j`` of every node for one input (Eqs. 1-6 in log space).

        Args:
            inputs: channel -> vector. Shape: (D_k,) each.
            channels: the channels that compete (default all); weights are renormalised.

        Returns:
            Tensor of shape (N,).
        """
        names = self._channel_names(channels)
        x = self._check(inputs, names)
        if self._n == 0:
            return torch.zeros(0, dtype=self.dtype, device=self.device)
        return self._evaluate(x, names)[0]

    def vigilance_mask(
        self, inputs: Mapping[str, Any], channels: Iterable[str] | None = None
    ) -> torch.Tensor:
        """Which nodes pass the vigilance test (Eqs. 7-8) in every channel. Shape: (N,)."""
        names = self._channel_names(channels)
        x = self._check(inputs, names)
        if self._n == 0:
            return torch.zeros(0, dtype=torch.bool, device=self.device)
        return self._evaluate(x, names)[1]

    def localise(
        self, inputs: Mapping[str, Any], channels: Iterable[str] | None = None
    ) -> MatchResult:
        """Node localisation (Section 2.1.3): the best node that passes vigilance; no learning.

        Args:
            inputs: channel -> vector. Shape: (D_k,) each.
            channels: the channels used, e.g. ``LASER_CHANNELS`` for localisation
                without odometry (default all).

        Returns:
            :class:`MatchResult` with ``node == -1`` when no node passes.
        """
        names = self._channel_names(channels)
        return self._select(self._check(inputs, names), names)

    def learn(self, inputs: Mapping[str, Any]) -> MatchResult:
        """One map-learning step (Algorithm 1): compete, vigilance, learn or add a node, link.

        Args:
            inputs: every channel -> vector. Shape: (D_k,) each.

        Returns:
            The :class:`MatchResult` (the winner, or the new node with ``is_new``).
        """
        x = self._check(inputs, self.names)
        if not self._ch:
            for k, v in x.items():
                self._ch[k] = self._new_channel(k, v.numel())
        res = self._select(x, self.names)
        if res.node < 0:
            node = self._add_node(x)
            res = MatchResult(node, is_new=True, best=res.best)
        else:
            self._update(res.node, x)
        self._link(self.prev_winner, res.node)
        self.prev_winner = res.node
        return res

    def _new_channel(self, k: str, dim: int) -> _Channel:
        p = self.params
        floor = p.var_floor_odometry if k == "odometry" else p.var_floor
        full = p.covariance == "full"
        return _Channel(dim, full, self.angular.get(k, ()), floor, self.dtype, self.device)

    def _add_node(self, x: dict[str, torch.Tensor]) -> int:
        j = self._n
        if j >= self._cap:
            self._cap = max(8, 2 * self._cap)
            for ch in self._ch.values():
                ch.grow(self._cap)
            self.counts = torch.cat(
                [
                    self.counts,
                    torch.zeros(self._cap - len(self.counts), dtype=self.dtype, device=self.device),
                ]
            )
            self.prior = torch.cat(
                [
                    self.prior,
                    torch.ones(self._cap - len(self.prior), dtype=self.dtype, device=self.device),
                ]
            )
        s2 = self.params.sigma_init_sq
        for k, ch in self._ch.items():
            v = x[k]
            ch.mean[j] = torch.where(ch.ang, wrap_angle(v), v) if ch.has_ang else v
            if ch.full:
                ch.cov[j] = s2 * torch.eye(ch.dim, dtype=self.dtype, device=self.device)
                ch.chol[j] = math.sqrt(s2) * torch.eye(ch.dim, dtype=self.dtype, device=self.device)
            else:
                ch.cov[j] = s2
                ch.logcov[j] = math.log(s2)
            ch.logdet[j] = ch.dim * math.log(s2)
        self.counts[j] = 1.0  # the paper's N=0 followed by one Eq. 12 increment
        self.prior[j] = self.params.p_init
        self._n = j + 1
        x_, y_, th_ = self._position(j)
        self.graph.add_node(j, x=x_, y=y_, th=th_, count=1, created=j)
        return j

    def _update(self, j: int, x: dict[str, torch.Tensor]) -> None:
        n_j = float(self.counts[j])
        a, b = n_j / (n_j + 1.0), 1.0 / (n_j + 1.0)
        for k, ch in self._ch.items():
            floor = ch.floor
            d = x[k] - ch.mean[j]
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
        total = float(self.counts[: self._n].sum())
        self.prior[j] = n_j / total  # Eq. 11 (N_J before the increment)
        self.counts[j] = n_j + 1.0  # Eq. 12
        x_, y_, th_ = self._position(j)
        self.graph.nodes[j].update(x=x_, y=y_, th=th_, count=int(n_j + 1))
        for u, v in (*self.graph.in_edges(j), *self.graph.out_edges(j)):
            self._edge_geometry(u, v)

    def _position(self, j: int) -> tuple[float, float, float]:
        if self.position_channel is None:
            return 0.0, 0.0, 0.0
        m = [*self._ch[self.position_channel].mean[j].tolist(), 0.0, 0.0, 0.0]
        s = self.params.odo_scale
        return m[0] / s, m[1] / s, m[2]

    def _edge_geometry(self, u: int, v: int) -> None:
        nu, nv = self.graph.nodes[u], self.graph.nodes[v]
        dx, dy = nv["x"] - nu["x"], nv["y"] - nu["y"]
        angle = math.atan2(dy, dx)
        self.graph.edges[u, v].update(
            d=math.hypot(dx, dy),
            angle=angle,
            heading=wrap_angle(angle - nu["th"]),
            facing=wrap_angle(nv["th"] - nu["th"]),
        )

    def _link(self, prev: int, node: int) -> None:
        if prev < 0 or prev == node:
            return
        if self.graph.has_edge(prev, node):
            self.graph.edges[prev, node]["count"] += 1
        else:
            self.graph.add_edge(prev, node, count=1)
        self._edge_geometry(prev, node)

    # ------------------------------------------------------------ save/load
    def get_state(self) -> dict[str, Any]:
        """The whole map as numpy arrays and Python scalars (for saving)."""
        n = self._n
        st: dict[str, Any] = {
            "version": STATE_VERSION,
            "params": self.params.to_dict(),
            "channels": list(self.names),
            "weights": [self.weights[k] for k in self.names],
            "counts": self.counts[:n].cpu().numpy().copy(),
            "prior": self.prior[:n].cpu().numpy().copy(),
            "prev_winner": self.prev_winner,
            "edges": np.array([(u, v) for u, v in self.graph.edges], dtype=np.int64).reshape(-1, 2),
            "edge_counts": np.array(
                [c for *_, c in self.graph.edges(data="count")], dtype=np.int64
            ),
        }
        for k, ch in self._ch.items():
            st[f"mean/{k}"] = ch.mean[:n].cpu().numpy().copy()
            st[f"cov/{k}"] = ch.cov[:n].cpu().numpy().copy()
        return st

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restore a map saved by :meth:`get_state` (same channels)."""
        if state.get("version") != STATE_VERSION:
            raise MapFormatError(
                f"MBARAM state version {state.get('version')!r} is not {STATE_VERSION}; "
                "rebuild the map with this version"
            )
        if list(state["channels"]) != list(self.names):
            raise MapFormatError(
                f"MBARAM state has channels {list(state['channels'])}, this map {list(self.names)}"
            )
        self.reset()
        counts = np.asarray(state["counts"], dtype=np.float64)
        n = len(counts)
        if n == 0:
            return
        full = self.params.covariance == "full"
        for k in self.names:
            mean = torch.as_tensor(np.asarray(state[f"mean/{k}"]), dtype=self.dtype)
            cov = torch.as_tensor(np.asarray(state[f"cov/{k}"]), dtype=self.dtype)
            if mean.shape[0] != n or cov.shape[0] != n or (cov.dim() == 3) != full:
                raise MapFormatError(f"MBARAM state channel {k!r} is inconsistent with its counts")
            ch = self._new_channel(k, mean.shape[1])
            ch.mean, ch.cov = mean.to(self.device), cov.to(self.device)
            if full:
                ch.chol = torch.linalg.cholesky(ch.cov)
                ch.logdet = 2.0 * ch.chol.diagonal(dim1=-2, dim2=-1).log().sum(-1)
            else:
                ch.logcov = ch.cov.log()
                ch.logdet = ch.logcov.sum(-1)
            self._ch[k] = ch
        self._n = self._cap = n
        self.counts = torch.as_tensor(counts, dtype=self.dtype, device=self.device)
        self.prior = torch.as_tensor(
            np.asarray(state["prior"]), dtype=self.dtype, device=self.device
        )
        for j in range(n):
            x_, y_, th_ = self._position(j)
            self.graph.add_node(j, x=x_, y=y_, th=th_, count=int(counts[j]), created=j)
        for (u, v), c in zip(
            np.asarray(state["edges"]).tolist(), np.asarray(state["edge_counts"]).tolist()
        ):
            self.graph.add_edge(int(u), int(v), count=int(c))
            self._edge_geometry(int(u), int(v))
        self.prev_winner = int(state["prev_winner"])


# ---------------------------------------------------------------- front end
class OdometryIntegrator:
    """Dead reckoning from (vtrans, vrot, dt): the odometry channel's pose (x, y, th)."""

    def __init__(self, x: float = 0.0, y: float = 0.0, th: float = 0.0) -> None:
        self.pose = (float(x), float(y), float(th))

    def step(self, vtrans: float, vrot: float, dt: float) -> tuple[float, float, float]:
        """Advance by one interval (turn half, move, turn half) and return the pose."""
        self.pose = odometry_step(self.pose, vtrans, vrot, dt, midpoint=True)
        return self.pose


def frame_inputs(
    scans: Mapping[str, np.ndarray],
    pose: Sequence[float] | None,
    params: MBARAMParams,
    channels: Iterable[str] = ("laser_front", "laser_rear", "odometry"),
) -> dict[str, np.ndarray]:
    """Channel vectors from one frame's laser scans and odometric pose.

    Laser ranges are clipped to ``[0, laser_max_range]`` (+inf = no return = max range)
    and multiplied by ``laser_scale``; the pose becomes ``(x, y) * odo_scale, th``.

    Args:
        scans: ``{"laser_front": (N,), "laser_rear": (N,)}`` ranges in metres.
        pose: ``(x, y, th)`` for the odometry channel (None when it is not used).
        params: the MBARAM parameters.
        channels: the channels to build.

    Returns:
        channel -> float64 vector.
    """
    out: dict[str, np.ndarray] = {}
    for k in channels:
        if k == "odometry":
            if pose is None:
                raise InputError("the odometry channel needs a pose (x, y, th)")
            x, y, th = (float(v) for v in pose)
            out[k] = np.array([x * params.odo_scale, y * params.odo_scale, th])
            continue
        if k not in scans:
            raise InputError(
                f"frame has no scan {k!r} (has {sorted(scans)}); turn the lasers on in the "
                "simulator or use a dataset with laser scans"
            )
        r = np.asarray(scans[k], dtype=np.float64).reshape(-1)
        if np.isnan(r).any():
            raise InputError(f"scan {k!r} has {int(np.isnan(r).sum())} NaN range(s)")
        r = np.clip(np.nan_to_num(r, posinf=params.laser_max_range), 0.0, params.laser_max_range)
        out[k] = r * params.laser_scale
    return out


def quantisation_error(points: np.ndarray, nodes: np.ndarray) -> float:
    """Eq. 14: mean of ``||x_i - m_{x_i}|| / ||x||_max`` over the data vectors.

    Args:
        points: the data vectors (robot positions). Shape: (T, D).
        nodes: the best-matching node of each. Shape: (T, D).

    Returns:
        The QE; the normaliser ``x_(max)`` is the largest data-vector norm.
    """
    points, nodes = np.asarray(points, float), np.asarray(nodes, float)
    if points.shape != nodes.shape or points.size == 0:
        raise InputError(
            f"QE needs two equal non-empty (T, D) arrays, got {points.shape}, {nodes.shape}"
        )
    scale = float(np.linalg.norm(points, axis=1).max()) or 1.0
    return float(np.linalg.norm(points - nodes, axis=1).mean() / scale)


def compression_ratio(path_size: int, map_size: int) -> float:
    """Eq. 15: original path size (data vectors) over topological map size (nodes)."""
    if map_size <= 0:
        raise InputError("compression ratio of an empty map is undefined")
    return float(path_size) / float(map_size)


def localisation_success(
    node_xy: np.ndarray, true_xy: np.ndarray, threshold: float = 1.0
) -> np.ndarray:
    """Eqs. 16-17: success where the node is closer than ``threshold`` to the robot.

    Args:
        node_xy: the localised node's position per step, NaN where none passed. Shape: (T, 2).
        true_xy: the robot's position. Shape: (T, 2).
        threshold: the distance bound (1 m in the paper).

    Returns:
        Boolean array of shape (T,) (False where no node was found).
    """
    d = np.linalg.norm(np.asarray(node_xy, float) - np.asarray(true_xy, float), axis=1)
    return np.nan_to_num(d, nan=np.inf) < threshold


@dataclass
class RunResult:
    """What :func:`run_mbaram` measured.

    Attributes:
        model: the learnt map.
        metrics: the figures written to ``metrics.json``.
        path: true positions of the mapping frames. Shape: (T, 2).
        winners: learning-time winner of every mapping frame. Shape: (T,).
        node_xy: each node's place, the mean true position of the frames it won.
            Shape: (N, 2).
        nodes_per_lap: nodes added on each mapping lap.
        loc_path: true positions of the localisation frames. Shape: (L, 2).
        loc_lap: lap index (0-based within the localisation laps). Shape: (L,).
        loc_with: Eq. 16 success with the odometry channel. Shape: (L,).
        loc_without: the same with the laser channels only. Shape: (L,).
    """

    model: MBARAM
    metrics: dict[str, Any]
    path: np.ndarray
    winners: np.ndarray
    node_xy: np.ndarray
    nodes_per_lap: list[int] = field(default_factory=list)
    loc_path: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    loc_lap: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    loc_with: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    loc_without: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))


@RANGE_MAPPERS.register("mbaram")
class MBARAMMapper:
    """MBARAM as a module of the pipeline: :class:`~torchratslam.messages.Frame` in, node out.

    Builds the channel inputs from each frame's laser scans (``frame.scans``) and its
    odometric pose (the ground-truth pose, the paper's accurate odometry, or dead
    reckoning of ``vtrans``/``vrot``, continuous over the whole run), then learns
    (Algorithm 1) or localises (Section 2.1.3) with :class:`MBARAM`.

    Args:
        params: MBARAM parameters.
        odometry: ``"groundtruth"`` or ``"integrated"``.
        dtype: float dtype of the node statistics.
        device: torch device.
    """

    def __init__(
        self,
        params: MBARAMParams | None = None,
        *,
        odometry: str = "groundtruth",
        dtype: torch.dtype = torch.float64,
        device: torch.device | str | None = None,
    ) -> None:
        if odometry not in ("groundtruth", "integrated"):
            raise ConfigError(f"odometry must be 'groundtruth' or 'integrated', got {odometry!r}")
        self.params = params if params is not None else MBARAMParams()
        self.mode = odometry
        self.model = MBARAM(self.params, dtype=dtype, device=device)
        self.integ: OdometryIntegrator | None = None
        self.keep_inputs = False  # remember every frame's inputs (to replay the mapping frames)
        self._memo: dict[int, tuple[Frame, dict[str, np.ndarray], tuple[float, float, float]]] = {}

    def __len__(self) -> int:
        return len(self.model)

    def inputs(self, frame: Frame) -> tuple[dict[str, np.ndarray], tuple[float, float, float]]:
        """The channel vectors of ``frame`` and its odometric pose (one integration step)."""
        hit = self._memo.get(id(frame))
        if hit is not None and hit[0] is frame:
            return hit[1], hit[2]
        if frame.pose is None and self.mode == "groundtruth":
            raise InputError("odometry='groundtruth' needs frames with a ground-truth pose")
        if self.integ is None:
            self.integ = OdometryIntegrator(*(frame.pose if frame.pose is not None else (0, 0, 0)))
        if self.mode == "integrated":
            pose = self.integ.step(frame.vtrans, frame.vrot, frame.dt)
        else:
            pose = cast(tuple[float, float, float], tuple(float(v) for v in frame.pose or ()))
        x = frame_inputs(frame.scans, pose, self.params)
        if not self.keep_inputs:
            self._memo.clear()
        self._memo[id(frame)] = (frame, x, pose)
        return x, pose

    def learn(self, frame: Frame) -> int:
        """One mapping step on ``frame``; returns the winning (or new) node."""
        return self.model.learn(self.inputs(frame)[0]).node

    def localise(self, frame: Frame, *, odometry: bool = True) -> int:
        """The node ``frame`` is localised at (-1 = none passes vigilance), no learning.

        Args:
            frame: the frame (its scans, and its pose when ``odometry``).
            odometry: use the odometry channel, or the lasers alone.
        """
        x = self.inputs(frame)[0]
        return self.model.localise(x, None if odometry else LASER_CHANNELS).node


def _true_pose(mapper: Any, f: Frame) -> Sequence[float]:
    return f.pose if f.pose is not None else mapper.inputs(f)[1]


def _learn(
    mapper: Any, map_laps: Sequence[Iterable[Frame]], *, keep: bool
) -> tuple[np.ndarray, np.ndarray, list[int], list]:
    """Learn the map lap by lap.

    Returns:
        The true positions ``(F, 2)``, the winning node of every frame ``(F,)``, the
        nodes added per lap and (``keep``) the frames for a replay.
    """
    path, winners, per_lap, replay = [], [], [], []
    for lap in map_laps:
        before = len(mapper)
        for f in lap:
            winners.append(mapper.learn(f))
            path.append(_true_pose(mapper, f)[:2])
            if keep:
                replay.append((0, f))
        per_lap.append(len(mapper) - before)
    if not winners:
        raise InputError("MBARAM got no frames to map")
    return np.asarray(path, float), np.asarray(winners), per_lap, replay


def _node_positions(n: int, path: np.ndarray, winners: np.ndarray) -> np.ndarray:
    """Each node's place in the true frame: the mean true position of the frames it won
    (its odometry-channel mean when the odometry is the ground truth).

    Shape:
        path: ``(F, 2)``; winners: ``(F,)``; returns ``(n, 2)``.
    """
    node_xy = np.zeros((n, 2))
    np.add.at(node_xy, winners, path)
    node_xy /= np.maximum(np.bincount(winners, minlength=n), 1)[:, None]
    return node_xy


def _localise(
    mapper: Any, node_xy: np.ndarray, replay: list
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Localise every replayed frame with all channels and with the lasers only.

    Returns:
        True positions ``(L, 2)``, lap of each ``(L,)``, and the positions of the
        winning nodes with and without odometry ``(L, 2)`` (NaN where none won).
    """
    loc_true, loc_lap, with_xy, without_xy = [], [], [], []
    nan2 = np.array([np.nan, np.nan])
    for i, f in replay:
        loc_lap.append(i)
        node = mapper.localise(f)
        loc_true.append(_true_pose(mapper, f)[:2])
        with_xy.append(node_xy[node] if node >= 0 else nan2)
        node = mapper.localise(f, odometry=False)
        without_xy.append(node_xy[node] if node >= 0 else nan2)
    return (
        np.asarray(loc_true, float).reshape(-1, 2),
        np.asarray(loc_lap, np.int64),
        np.reshape(with_xy, (-1, 2)),
        np.reshape(without_xy, (-1, 2)),
    )


def _rate(ok: np.ndarray) -> float:
    return float(ok.mean()) if len(ok) else float("nan")


def run_mbaram(
    map_laps: Sequence[Iterable[Frame]],
    loc_laps: Sequence[Iterable[Frame]] = (),
    params: MBARAMParams | None = None,
    *,
    odometry: str = "groundtruth",
    dtype: torch.dtype = torch.float64,
    mapper: str = "mbaram",
) -> RunResult:
    """Learn a map over ``map_laps`` then localise on ``loc_laps`` with and without odometry.

    Args:
        map_laps: frame streams (one per lap) used for learning, in order.
        loc_laps: frame streams for localisation (no learning) that follow the mapping
            laps; empty = the mapping frames are replayed against the final map.
        params: MBARAM parameters.
        odometry: ``"groundtruth"`` (the paper assumes accurate odometry, e.g. GPS) or
            ``"integrated"`` (dead reckoning from the frames' noisy vtrans/vrot).
        dtype: float dtype of the node statistics.
        mapper: the range-sensor mapper, a name in
            :data:`torchratslam.registry.RANGE_MAPPERS` (its ``model`` must be an
            :class:`MBARAM`).

    Returns:
        :class:`RunResult`; ``metrics`` has nodes, edges, frames, qe, qe_m, cr,
        nodes_per_lap, localisation_rate_with_odometry,
        localisation_rate_without_odometry and their per-lap values.
    """
    params = params if params is not None else MBARAMParams()
    mapping = RANGE_MAPPERS.build(mapper, params, odometry=odometry, dtype=dtype)
    model = mapping.model
    if isinstance(mapping, MBARAMMapper):
        mapping.keep_inputs = not loc_laps  # the replay reuses the mapping frames' inputs
    path_a, win_a, per_lap, replay = _learn(mapping, map_laps, keep=not loc_laps)
    node_xy = _node_positions(len(model), path_a, win_a)
    qe_m = float(np.linalg.norm(path_a - node_xy[win_a], axis=1).mean())
    if loc_laps:
        replay = [(i, f) for i, lap in enumerate(loc_laps) for f in lap]
    loc_true_a, loc_lap_a, with_xy, without_xy = _localise(mapping, node_xy, replay)
    thr = params.loc_threshold
    ok_with = localisation_success(with_xy, loc_true_a, thr)
    ok_without = localisation_success(without_xy, loc_true_a, thr)
    rate = _rate
    laps_seen = sorted(set(loc_lap_a.tolist()))
    metrics = {
        "nodes": len(model),
        "edges": model.num_edges,
        "frames": len(win_a),
        "qe": quantisation_error(path_a, node_xy[win_a]),
        "qe_m": qe_m,
        "cr": compression_ratio(len(win_a), len(model)),
        "nodes_per_lap": per_lap,
        "localisation_frames": len(loc_true_a),
        "localisation_rate_with_odometry": rate(ok_with),
        "localisation_rate_without_odometry": rate(ok_without),
        "localisation_per_lap_with_odometry": [rate(ok_with[loc_lap_a == i]) for i in laps_seen],
        "localisation_per_lap_without_odometry": [
            rate(ok_without[loc_lap_a == i]) for i in laps_seen
        ],
        "odometry": odometry,
        "params": params.to_dict(),
    }
    return RunResult(
        model, metrics, path_a, win_a, node_xy, per_lap, loc_true_a, loc_lap_a, ok_with, ok_without
    )
