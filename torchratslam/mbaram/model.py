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

Node localisation (Section 2.1.3) is :meth:`MBARAM.localise`; the match and vigilance
math lives in :mod:`torchratslam.mbaram.match`, the evaluation measures in
:mod:`torchratslam.mbaram.metrics`, and :func:`torchratslam.mbaram.run.run_mbaram` maps
laps of a :class:`~torchratslam.messages.Frame` stream and localises on further laps,
with and without the odometry channel.

MBARAM is a laser-and-odometry mapper, not an image local view nor a pose-cell
experience map: :class:`~torchratslam.mbaram.mapper.MBARAMMapper` (the frame-level
module, lasers of the simulator and odometry in, node out) is registered as ``"mbaram"``
in :data:`torchratslam.registry.RANGE_MAPPERS`, and
:func:`~torchratslam.mbaram.run.run_mbaram` builds its mapper from that registry by name.


Example:
    >>> import torch
    >>> from torchratslam.mbaram.model import MBARAM
    >>> from torchratslam.mbaram.params import MBARAMParams
    >>> m = MBARAM(MBARAMParams(), channels={"a": 0.5, "b": 0.5})
    >>> m.learn({"a": torch.zeros(4), "b": torch.ones(2)}).is_new
    True
    >>> m.learn({"a": torch.zeros(4), "b": torch.ones(2)}).node
    0
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import networkx as nx
import numpy as np
import torch

from ratslam_graph.geometry import wrap_angle
from torchratslam.errors import ConfigError, InputError, MapFormatError
from torchratslam.mbaram.match import (
    ChannelNodes,
    MatchResult,
    Vigilance,
    learn_node,
    log_match,
    select,
)
from torchratslam.mbaram.params import STATE_VERSION, MBARAMParams
from torchratslam.mbaram.tracking import filter_step, transition_matrix

__all__ = ["MBARAM"]


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
        self._ch: dict[str, ChannelNodes] = {}
        self._n = 0
        self._cap = 0
        self.counts = torch.zeros(0, dtype=self.dtype, device=self.device)
        self.prior = torch.zeros(0, dtype=self.dtype, device=self.device)
        self.graph = nx.DiGraph()
        self.prev_winner = -1
        self._track: dict[tuple[str, ...], torch.Tensor] = {}
        self._transition: torch.Tensor | None = None
        # per channel, the terms of the last localised input on this map (log_match's memo)
        self._memo: dict[str, tuple[torch.Tensor, torch.Tensor, Vigilance]] = {}

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
            finite = np.isfinite(x.numpy()) if x.device.type == "cpu" else torch.isfinite(x)
            if not bool(finite.all()):
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
    def _evaluate(
        self, x: dict[str, torch.Tensor], names: Sequence[str], *, memo: bool = False
    ) -> tuple[torch.Tensor, Vigilance]:
        """``log M_j`` (N,) and the vigilance of every node (``memo``: a
        channel whose input equals the last localised one reuses its terms)."""
        n = self._n
        return log_match(
            self._ch,
            x,
            names,
            self.weights,
            self.params,
            self.counts[:n],
            self.prior[:n],
            self.device,
            self._memo if memo else None,
        )

    def _select(
        self, x: dict[str, torch.Tensor], names: Sequence[str], *, memo: bool = False
    ) -> MatchResult:
        if self._n == 0:
            return MatchResult(-1)
        return select(*self._evaluate(x, names, memo=memo))

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
        return self._evaluate(x, names)[1].mask()

    def localise(
        self, inputs: Mapping[str, Any], channels: Iterable[str] | None = None
    ) -> MatchResult:
        """Node localisation (Section 2.1.3): the best node that passes vigilance; no learning.

        With ``params.loc_track_hops > 0`` consecutive calls (per channel set) are
        filtered (:mod:`torchratslam.mbaram.tracking`): the winner is the node of
        highest belief that passes vigilance, the belief combining this frame's
        ``log M_j`` with the previous belief moved along the map's edges;
        :meth:`learn` and :meth:`reset_tracking` forget the belief.

        Args:
            inputs: channel -> vector. Shape: (D_k,) each.
            channels: the channels used, e.g. ``LASER_CHANNELS`` for localisation
                without odometry (default all).

        Returns:
            :class:`MatchResult` with ``node == -1`` when no node passes.
        """
        names = self._channel_names(channels)
        x = self._check(inputs, names)
        p = self.params
        if p.loc_track_hops == 0 or self._n == 0:
            return self._select(x, names, memo=True)
        log_m, passed = self._evaluate(x, names, memo=True)
        if self._transition is None:
            self._transition = transition_matrix(
                torch.as_tensor(list(self.graph.edges), dtype=torch.long).reshape(-1, 2),
                self._n,
                p.loc_track_hops,
                dtype=self.dtype,
                device=self.device,
            )
        belief = filter_step(self._track.get(names), log_m, self._transition, p.loc_track_jump)
        self._track[names] = belief
        return select(belief, passed)

    def reset_tracking(self) -> None:
        """Forget the node filter's belief (``loc_track_hops``): the next
        :meth:`localise` starts from a uniform belief."""
        self._track.clear()
        self._transition = None

    def learn(self, inputs: Mapping[str, Any]) -> MatchResult:
        """One map-learning step (Algorithm 1): compete, vigilance, learn or add a node, link.

        Args:
            inputs: every channel -> vector. Shape: (D_k,) each.

        Returns:
            The :class:`MatchResult` (the winner, or the new node with ``is_new``).
        """
        x = self._check(inputs, self.names)
        self._track.clear()
        self._transition = None
        self._memo.clear()
        if not self._ch:
            for k, v in x.items():
                self._ch[k] = self._new_channel(k, v.numel())
        res = self._select(x, self.names)
        if res.node < 0:
            node = self._add_node(x)
            res = MatchResult(node, is_new=True, best=res.best)
        else:
            self._update(res.node, x)
        _link(self.graph, self.prev_winner, res.node)
        self.prev_winner = res.node
        return res

    def _new_channel(self, k: str, dim: int) -> ChannelNodes:
        p = self.params
        floor = p.var_floor_odometry if k == "odometry" else p.var_floor
        full = p.covariance == "full"
        return ChannelNodes(dim, full, self.angular.get(k, ()), floor, self.dtype, self.device)

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
            learn_node(ch, j, x[k], a, b)
        total = float(self.counts[: self._n].sum())
        self.prior[j] = n_j / total  # Eq. 11 (N_J before the increment)
        self.counts[j] = n_j + 1.0  # Eq. 12
        x_, y_, th_ = self._position(j)
        self.graph.nodes[j].update(x=x_, y=y_, th=th_, count=int(n_j + 1))
        for u, v in (*self.graph.in_edges(j), *self.graph.out_edges(j)):
            _edge_geometry(self.graph, u, v)

    def _position(self, j: int) -> tuple[float, float, float]:
        if self.position_channel is None:
            return 0.0, 0.0, 0.0
        m = [*self._ch[self.position_channel].mean[j].tolist(), 0.0, 0.0, 0.0]
        s = self.params.odo_scale
        return m[0] / s, m[1] / s, m[2]

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
            _edge_geometry(self.graph, int(u), int(v))
        self.prev_winner = int(state["prev_winner"])


def _edge_geometry(graph: nx.DiGraph, u: int, v: int) -> None:
    """Store the edge's length, adjacent angle, heading and facing from its nodes' poses."""
    nu, nv = graph.nodes[u], graph.nodes[v]
    dx, dy = nv["x"] - nu["x"], nv["y"] - nu["y"]
    angle = math.atan2(dy, dx)
    graph.edges[u, v].update(
        d=math.hypot(dx, dy),
        angle=angle,
        heading=wrap_angle(angle - nu["th"]),
        facing=wrap_angle(nv["th"] - nu["th"]),
    )


def _link(graph: nx.DiGraph, prev: int, node: int) -> None:
    """Add (or count again) the edge from the previous winner to this one."""
    if prev < 0 or prev == node:
        return
    if graph.has_edge(prev, node):
        graph.edges[prev, node]["count"] += 1
    else:
        graph.add_edge(prev, node, count=1)
    _edge_geometry(graph, prev, node)
