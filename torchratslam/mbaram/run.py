"""Map laps of frames with MBARAM, then localise on further laps with and without the
odometry channel (the paper's Section 3 experiments)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from torchratslam.errors import InputError
from torchratslam.mbaram.mapper import MBARAMMapper
from torchratslam.mbaram.metrics import compression_ratio, localisation_success, quantisation_error
from torchratslam.mbaram.model import MBARAM
from torchratslam.mbaram.params import MBARAMParams
from torchratslam.messages import Frame
from torchratslam.registry import RANGE_MAPPERS

__all__ = ["RunResult", "run_mbaram"]


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
