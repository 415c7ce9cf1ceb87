"""MBARAM as a pipeline module (the RANGE_MAPPERS registry) and the laser outlier model."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from torchratslam.errors import ConfigError
from torchratslam.mbaram.inputs import frame_inputs
from torchratslam.mbaram.mapper import MBARAMMapper
from torchratslam.mbaram.model import MBARAM
from torchratslam.mbaram.params import LASER_CHANNELS, MBARAMParams
from torchratslam.mbaram.run import run_mbaram
from torchratslam.messages import Frame
from torchratslam.registry import RANGE_MAPPERS

PARAMS = MBARAMParams(laser_scale=3.0, s_max_odometry=1e-4, var_floor_odometry=0.01)


def frames(n: int, seed: int, start: int = 0) -> list[Frame]:
    """A robot driving along x past a wall whose distance changes: 64-beam scans."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(start, start + n):
        x = 0.25 * i
        wall = 1.0 + 0.5 * math.sin(0.7 * x)
        base = wall + 0.3 * np.cos(np.linspace(0, math.pi, 64) + x)
        scans = {
            "laser_front": base + rng.normal(0, 0.01, 64),
            "laser_rear": base[::-1] + 0.2 + rng.normal(0, 0.01, 64),
        }
        out.append(Frame(i, 0.2 * i, None, 1.25, 0.0, 0.2, (x, 0.0, 0.0), scans))
    return out


def test_mbaram_is_a_registered_range_mapper():
    assert "mbaram" in RANGE_MAPPERS
    assert RANGE_MAPPERS.get("mbaram") is MBARAMMapper
    with pytest.raises(ConfigError, match="range-sensor mapper"):
        RANGE_MAPPERS.get("nope")
    with pytest.raises(ConfigError, match="range-sensor mapper"):
        run_mbaram([frames(3, 0)], params=PARAMS, mapper="nope")


def test_mapper_on_frames_equals_the_model_on_channel_inputs():
    mapper = RANGE_MAPPERS.get("mbaram")(PARAMS)
    model = MBARAM(PARAMS)
    for f in frames(30, 1):
        x = frame_inputs(f.scans, f.pose, PARAMS)
        assert mapper.learn(f) == model.learn(x).node
    assert len(mapper) == len(model) > 1
    for f in frames(12, 2, start=5):
        x = frame_inputs(f.scans, f.pose, PARAMS)
        assert mapper.localise(f) == model.localise(x).node
        assert mapper.localise(f, odometry=False) == model.localise(x, LASER_CHANNELS).node
    for k in model.names:
        torch.testing.assert_close(mapper.model.means(k), model.means(k), rtol=0, atol=0)


def test_run_mbaram_uses_the_registry_by_name():
    calls = []

    class Counting(MBARAMMapper):
        def learn(self, frame):
            calls.append(frame.index)
            return super().learn(frame)

    RANGE_MAPPERS.register("counting_test", Counting, overwrite=True)
    laps = [frames(20, 3), frames(20, 4)]
    a = run_mbaram(laps, [frames(20, 5)], PARAMS, mapper="counting_test")
    b = run_mbaram(laps, [frames(20, 5)], PARAMS)
    assert calls == [f.index for lap in laps for f in lap]
    assert a.metrics["nodes"] == b.metrics["nodes"]
    assert np.array_equal(a.loc_without, b.loc_without)


def test_integrated_odometry_steps_once_per_frame():
    """Localising with and without odometry on one frame must not integrate it twice."""
    mapper = MBARAMMapper(PARAMS, odometry="integrated")
    fs = frames(10, 6)
    for f in fs[:5]:
        mapper.learn(f)
    pose = mapper.inputs(fs[5])[1]
    mapper.localise(fs[5])
    mapper.localise(fs[5], odometry=False)
    assert mapper.inputs(fs[5])[1] == pose
    x, y, _ = mapper.inputs(fs[6])[1]
    assert x == pytest.approx(pose[0] + 1.25 * 0.2) and y == pytest.approx(0.0)


def test_laser_outlier_mixture_matches_a_per_beam_reference():
    """Eq. 5 with p = (1 - eps) N + eps / R per beam, against a loop over nodes and beams."""
    eps = 0.05
    p = MBARAMParams(laser_outlier=eps, laser_max_range=10.0)
    m = MBARAM(p, {"laser_front": 1.0}, angular={})
    rng = np.random.default_rng(0)
    for _ in range(12):
        m.learn({"laser_front": rng.uniform(0, 3, 8)})
    x = rng.uniform(0, 3, 8)
    n = len(m)
    mu, var = m.means("laser_front").tolist(), m.covariances("laser_front").tolist()
    prior = m.prior[:n].tolist()
    logp = []
    for j in range(n):
        s = 0.0
        for i in range(8):
            g = math.exp(-0.5 * (x[i] - mu[j][i]) ** 2 / var[j][i]) / math.sqrt(
                2 * math.pi * var[j][i]
            )
            s += math.log((1 - eps) * g + eps / 10.0)
        logp.append(s + math.log(prior[j]))
    top = max(logp)
    norm = top + math.log(sum(math.exp(v - top) for v in logp))
    expected = torch.tensor([v - norm for v in logp], dtype=torch.float64)
    torch.testing.assert_close(m.scores({"laser_front": x}), expected)


def test_laser_outlier_bounds_the_cost_of_occluded_beams():
    """Three beams blocked by a pedestrian: under the Gaussian a broad node elsewhere beats
    the tight node of this place; under the outlier mixture the tight node stays first."""
    state = {
        "version": 1,
        "channels": ["laser_front"],
        "weights": [1.0],
        "counts": np.array([5.0, 5.0]),
        "prior": np.array([0.5, 0.5]),
        "prev_winner": -1,
        "edges": np.zeros((0, 2), np.int64),
        "edge_counts": np.zeros(0, np.int64),
        "mean/laser_front": np.stack([np.zeros(20), np.full(20, 0.5)]),  # this place, elsewhere
        "cov/laser_front": np.stack([np.full(20, 0.01), np.full(20, 1.0)]),  # tight, broad
    }
    x = np.zeros(20)
    x[[3, 9, 15]] = 5.0  # occluded beams
    winners = {}
    for eps in (0.0, 0.01):
        m = MBARAM(MBARAMParams(laser_outlier=eps, s_max=10.0), {"laser_front": 1.0}, angular={})
        m.set_state(state)
        winners[eps] = m.localise({"laser_front": x}).node
        assert m.localise({"laser_front": np.zeros(20)}).node == 0  # unoccluded: this place
    assert winners == {0.0: 1, 0.01: 0}
