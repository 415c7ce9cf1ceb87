"""MBARAM's match memo: a channel whose input repeats on an unchanged map reuses its
terms, giving the very numbers (bit for bit) of computing every channel afresh."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchratslam.mbaram.match import log_match
from torchratslam.mbaram.model import MBARAM
from torchratslam.mbaram.params import LASER_CHANNELS, MBARAMParams


def _inputs(rng: np.random.Generator, place: int) -> dict[str, np.ndarray]:
    """Laser-like ranges of one of a few places, with noise, and its odometric pose."""
    base = np.random.default_rng(place).uniform(0.5, 10.0, (2, 64))
    noise = rng.normal(0.0, 0.05, base.shape)
    return {
        "laser_front": base[0] + noise[0],
        "laser_rear": base[1] + noise[1],
        "odometry": np.array([place * 1.0, 0.5 * place, 0.1 * place]) + rng.normal(0, 0.01, 3),
    }


def _fresh(m: MBARAM, x: dict[str, np.ndarray], channels) -> tuple[torch.Tensor, torch.Tensor]:
    """``log M_j`` and the pass mask with every channel computed (no memo)."""
    names = tuple(channels or m.names)
    t = {k: torch.as_tensor(x[k], dtype=m.dtype) for k in names}
    n = len(m)
    return log_match(
        m._ch, t, names, m.weights, m.params, m.counts[:n], m.prior[:n], m.device, None
    )


@pytest.mark.parametrize(
    "overrides",
    [
        {},
        {"laser_scale": 3.0, "s_max_odometry": 2e-5, "var_floor_odometry": 0.01},
        {"laser_outlier": 0.01, "s_max_odometry": 2e-5, "var_floor_odometry": 0.01},
        {"covariance": "full", "s_max": 1e-120, "s_max_odometry": 1e-9},
    ],
)
def test_memo_gives_the_numbers_of_a_fresh_computation(overrides):
    params = MBARAMParams.from_dict({"laser_max_range": 12.0, **overrides})
    m = MBARAM(params)
    rng = np.random.default_rng(3)
    for step in range(40):
        m.learn(_inputs(rng, step % 7))
    assert len(m) >= 2
    for step in range(25):
        x = _inputs(rng, step % 9)
        for channels in (None, LASER_CHANNELS, None):
            want_m, want_p = _fresh(m, x, channels)
            names = tuple(channels or m.names)
            t = m._check(x, names)
            got_m, got_p = m._evaluate(t, names, memo=True)
            assert torch.equal(got_m, want_m)
            assert torch.equal(got_p.mask(), want_p.mask())
        if step % 5 == 4:
            m.learn(_inputs(rng, step % 11))  # the map changes: the memo must not be reused


def test_memo_is_dropped_when_the_map_learns_and_ignores_a_mutated_input():
    m = MBARAM(MBARAMParams.from_dict({"laser_max_range": 12.0}))
    rng = np.random.default_rng(5)
    for step in range(12):
        m.learn(_inputs(rng, step % 4))
    x = _inputs(rng, 1)
    m.localise(x)
    assert m._memo  # the localised channels are stored
    m.learn(_inputs(rng, 2))
    assert not m._memo
    # an input array changed in place after it was localised is a new input
    m.localise(x)
    x["laser_front"] += 0.5
    names = m.names
    got = m._evaluate(m._check(x, names), names, memo=True)
    want = _fresh(m, x, None)
    assert torch.equal(got[0], want[0]) and torch.equal(got[1].mask(), want[1].mask())
