"""MBARAM's compiled laser terms against the tensor path: the kernels' numbers within
rounding, and the map, winners and localisations of a ray-cast session bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from torchratslam.experiments.mbaram_tour import PRESETS, laser_frames, sim_session
from torchratslam.mbaram import match
from torchratslam.mbaram._kernels import _SKIP_D, outlier_logp, updated_logs
from torchratslam.mbaram.params import MBARAMParams
from torchratslam.mbaram.run import run_mbaram

_LOG_2PI = math.log(2.0 * math.pi)


def _node_stats(rng: np.random.Generator, n: int, dim: int):
    mean = rng.uniform(0.0, 90.0, (n + 3, dim))  # room beyond the n nodes, as a channel has
    cov = np.exp(rng.uniform(math.log(1e-6), math.log(30.0), (n + 3, dim)))
    return mean, cov, np.log(cov)


def test_outlier_logp_is_the_tensor_sum_of_logaddexp():
    rng = np.random.default_rng(11)
    n, dim, eps, big_r = 23, 682, 0.01, 90.0
    mean, cov, logcov = _node_stats(rng, n, dim)
    log_u = math.log(eps / big_r)
    for x in (mean[4] + rng.normal(0.0, 0.05, dim), rng.uniform(0.0, 90.0, dim), mean[7]):
        got = outlier_logp(x, mean, cov, logcov, n, math.log1p(-eps), log_u)
        t = torch.from_numpy
        r = (t(x) - t(mean[:n])).square() / t(cov[:n])
        logn = (r + t(logcov[:n]) + _LOG_2PI) * -0.5 + math.log1p(-eps)
        want = torch.logaddexp(logn, torch.full_like(logn, log_u)).sum(-1).numpy()
        # rounding only: beams summed in another order, the corrections as block logs
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-9)


def test_updated_logs_of_the_rows_asked_is_eq_10_floored():
    rng = np.random.default_rng(12)
    n, dim = 17, 300
    mean, cov, logcov = _node_stats(rng, n, dim)
    counts = rng.integers(1, 40, n).astype(float)
    a, b = counts / (counts + 1), 1 / (counts + 1)
    x = mean[3] + rng.normal(0.0, 0.3, dim)
    rows = np.array([16, 0, 3, 3, 9], dtype=np.int64)
    floor = math.log(1e-6)
    got = updated_logs(x, mean, cov, logcov, rows, a * b, np.log(a), floor)
    for k, j in enumerate(rows):  # Eq. 10 per beam, by hand, in the variances themselves
        d = a[j] * (x - mean[j])
        var = np.maximum(a[j] * cov[j] + b[j] * d * d, 1e-6)
        assert got[k] == pytest.approx(np.log(var).sum(), rel=1e-12, abs=1e-9)


def test_far_beams_skip_a_correction_below_the_last_bit():
    # a beam with |log N - log U| > _SKIP_D multiplies the corrections' product by
    # 1 + exp(-gap), which is 1.0 exactly: skipping it changes nothing
    assert math.exp(-_SKIP_D) < 2.0**-60
    assert 1.0 + math.exp(-_SKIP_D) == 1.0


@pytest.fixture(scope="module")
def session_frames():
    session = sim_session(
        "sim:bicocca_like?hz=10&speed=1&frames=700", laps=1, seed=5, moving=4, moved=0
    )
    return list(laser_frames(session, 0, len(session)))


GAUSS = {"laser_scale": 3.0, "s_max_odometry": 2e-5, "var_floor_odometry": 0.01}
"""Gaussian laser channels (no outlier term) with nodes about as long as the sim preset's."""


@pytest.mark.parametrize(
    ("settings", "least"),
    [
        (PRESETS["sim"], 20),
        (PRESETS["dense"], 20),
        (PRESETS["paper"], 2),
        (GAUSS, 20),
        ({**PRESETS["sim"], "vigilance": "current", "s_max": 1e-300}, 2),
    ],
)
def test_compiled_run_is_the_tensor_paths_bit_for_bit(session_frames, settings, least, monkeypatch):
    params = MBARAMParams.from_dict(settings)
    out = {}
    for compiled in (True, False):
        monkeypatch.setattr(match, "COMPILED", compiled)
        out[compiled] = run_mbaram([session_frames], [], params)
    a, b = out[True], out[False]
    assert a.metrics["nodes"] > least
    assert a.metrics == b.metrics
    for field in ("winners", "node_xy", "loc_with", "loc_without", "path"):
        assert np.array_equal(getattr(a, field), getattr(b, field)), field
    assert list(a.model.graph.edges(data=True)) == list(b.model.graph.edges(data=True))
    for k in a.model.names:
        assert torch.equal(a.model.means(k), b.model.means(k))
        assert torch.equal(a.model.covariances(k), b.model.covariances(k))
