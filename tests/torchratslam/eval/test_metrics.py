"""Evaluation: SE(2) alignment, ATE, dead reckoning and ICP on cases with known answers."""

import math

import numpy as np
import pytest

from torchratslam.errors import InputError
from torchratslam.eval.metrics import (
    align_se2,
    apply_se2,
    ate_rmse,
    dead_reckoning,
    icp,
    icp_rmse,
    interpolate_groundtruth,
)


def _rot(a):
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


@pytest.mark.parametrize("angle", [0.0, 0.7, -2.9, math.pi])
def test_align_se2_recovers_a_known_rigid_motion(angle):
    rng = np.random.default_rng(1)
    src = rng.normal(size=(50, 2)) * 5
    t = np.array([3.0, -1.5])
    dst = src @ _rot(angle).T + t
    fit = align_se2(src, dst)
    rot, tr = fit.rotation, fit.translation
    assert np.allclose(rot, _rot(angle), atol=1e-9)
    assert np.allclose(fit.apply(src), dst, atol=1e-9)
    assert np.allclose(tr, t, atol=1e-9)
    assert ate_rmse(src, dst) == pytest.approx(0.0, abs=1e-9)
    assert ate_rmse(src, dst, align=False) > 1.0


def test_align_se2_is_the_least_squares_optimum():
    # no rotation or translation nearby does better than the closed form (brute force)
    rng = np.random.default_rng(2)
    src = rng.normal(size=(30, 2))
    dst = src @ _rot(0.4).T + [1.0, 2.0] + rng.normal(scale=0.2, size=(30, 2))
    best = ate_rmse(src, dst)
    fit = align_se2(src, dst)
    t, base = fit.translation, fit.angle
    for da in np.linspace(-0.05, 0.05, 11):
        for dx in np.linspace(-0.05, 0.05, 5):
            moved = src @ _rot(base + da).T + t + [dx, -dx]
            assert np.sqrt(np.mean(np.sum((moved - dst) ** 2, 1))) >= best - 1e-12


def test_ate_has_no_scale_and_matches_known_noise():
    gt = np.stack([np.linspace(0, 10, 101), np.zeros(101)], 1)
    # a constant lateral offset of 0.3 m is removed by alignment
    assert ate_rmse(gt + np.array([0.0, 0.3]), gt) == pytest.approx(0.0, abs=1e-12)
    # a scaled trajectory is not rescaled: error remains
    assert ate_rmse(gt * 1.1, gt) > 0.2
    # alternating +-e lateral noise around a line cannot be aligned away: ATE = e
    noisy = gt.copy()
    noisy[:, 1] = np.where(np.arange(101) % 2 == 0, 0.1, -0.1)
    noisy[:, 1] -= noisy[:, 1].mean()
    assert ate_rmse(noisy, gt) == pytest.approx(0.1, rel=1e-3)


def test_ate_errors_are_clear():
    with pytest.raises(InputError, match=r"counts differ|one ground-truth pose"):
        ate_rmse(np.zeros((3, 2)), np.zeros((4, 2)))
    with pytest.raises(InputError, match="NaN"):
        ate_rmse(np.full((3, 2), np.nan), np.zeros((3, 2)))


def test_apply_se2_rotates_headings():
    out = apply_se2(np.array([[1.0, 0.0, 0.5]]), math.pi / 2, np.array([1.0, 1.0]))
    assert np.allclose(out, [[1.0, 2.0, 0.5 + math.pi / 2]])


def test_dead_reckoning_matches_a_brute_force_loop_and_closes_a_circle():
    rng = np.random.default_rng(3)
    v, w, dt = rng.random(40), rng.normal(size=40), rng.random(40) * 0.2
    out = dead_reckoning(v, w, dt, start=(1.0, 2.0, 0.3))
    x, y, th = 1.0, 2.0, 0.3
    for k in range(40):
        th += w[k] * dt[k]
        x += v[k] * dt[k] * math.cos(th)
        y += v[k] * dt[k] * math.sin(th)
        assert out[k, 0] == pytest.approx(x) and out[k, 1] == pytest.approx(y)
        assert math.cos(out[k, 2] - th) == pytest.approx(1.0)
    n = 360
    circ = dead_reckoning(np.ones(n), np.full(n, 2 * math.pi / n), np.ones(n))
    assert np.allclose(circ[-1, :2], [0.0, 0.0], atol=1e-9)


def test_interpolate_groundtruth():
    gt = np.array([[0.0, 0.0, 0.0, 3.0], [1.0, 2.0, 4.0, -3.0]])
    p = interpolate_groundtruth(gt, np.array([0.5]))
    assert p[0, 0] == pytest.approx(1.0) and p[0, 1] == pytest.approx(2.0)
    # heading goes the short way round through pi
    assert abs(abs(p[0, 2]) - math.pi) < 0.2


def test_icp_recovers_a_rigid_motion_between_two_maps():
    rng = np.random.default_rng(4)
    t = np.linspace(0, 2 * math.pi, 200, endpoint=False)
    target = np.stack(
        [4 * np.cos(t), 2 * np.sin(t)], 1
    )  # an ellipse: no symmetry for small motions to confuse
    src = (target - [0.2, -0.1]) @ _rot(-0.15).T
    res = icp(src, target)
    assert res.rmse < 1e-6
    assert np.allclose(res.aligned, target, atol=1e-5)
    # icp_rmse of a noisy copy equals the noise RMSE left after the best rigid fit
    noisy = target + rng.normal(scale=0.01, size=target.shape)
    r = icp_rmse(noisy, target)
    assert 0.0 < r < 0.02


def test_icp_ignores_far_outliers_with_max_distance():
    t = np.linspace(0, 2 * math.pi, 100, endpoint=False)
    target = np.stack([3 * np.cos(t), np.sin(t)], 1)
    src = np.vstack([target + np.array([0.05, 0.0]), [[50.0, 50.0]]])
    assert icp(src, target, max_distance=1.0).rmse < 1e-6
    assert icp(src, target).rmse > 1.0
