"""The paper's ICP figure (LibICP point-to-point residual) against a brute-force loop
implementation and known transforms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from torchratslam.errors import InputError
from torchratslam.eval import compare_icp, icp, libicp_point_to_point, nearest_neighbours


def brute_libicp(template, model, max_iter=200, min_delta=1e-4):
    """LibICP's point-to-point loop written out: nearest neighbours by scanning every
    template point, centroids and the 2x2 cross-covariance summed in loops."""
    rot, t = np.eye(2), np.zeros(2)
    for _ in range(max_iter):
        moved = [rot @ p + t for p in model]
        pairs = []
        for q in moved:
            best, bj = math.inf, -1
            for j, p in enumerate(template):
                d = (q[0] - p[0]) ** 2 + (q[1] - p[1]) ** 2
                if d < best:
                    best, bj = d, j
            pairs.append((q, template[bj]))
        mu_m = sum(q for q, _ in pairs) / len(pairs)
        mu_t = sum(p for _, p in pairs) / len(pairs)
        h = np.zeros((2, 2))
        for q, p in pairs:
            for a in range(2):
                for b in range(2):
                    h[a, b] += (q[a] - mu_m[a]) * (p[b] - mu_t[b])
        u, _, vt = np.linalg.svd(h)
        r = vt.T @ u.T
        if np.linalg.det(r) < 0:
            r = vt.T @ np.diag([1.0, np.linalg.det(r)]) @ u.T
        ti = mu_t - r @ mu_m
        rot, t = r @ rot, r @ t + ti
        if max(np.linalg.norm(r - np.eye(2)), np.linalg.norm(ti)) < min_delta:
            break
    res = 0.0
    for p in model:
        q = rot @ p + t
        res += min((q[0] - s[0]) ** 2 + (q[1] - s[1]) ** 2 for s in template)
    return rot, t, res / len(model)


def loop_path(rng, n, noise=0.0):
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pts = np.c_[3 * np.cos(th), 1.5 * np.sin(th)] + rng.normal(0, 0.05, (n, 2))
    return pts + rng.normal(0, noise, pts.shape)


@pytest.mark.parametrize("seed", range(3))
def test_equals_a_brute_force_libicp(seed):
    rng = np.random.default_rng(seed)
    template = loop_path(rng, 40)
    a = rng.uniform(-0.2, 0.2)
    c, s = math.cos(a), math.sin(a)
    model = loop_path(rng, 33, noise=0.03) @ np.array([[c, -s], [s, c]]).T + rng.normal(0, 0.2, 2)
    res = libicp_point_to_point(template, model)
    r, t, mse = brute_libicp(template, model)
    assert np.allclose(res.rotation, r, atol=1e-10) and np.allclose(res.translation, t, atol=1e-10)
    assert res.residual_m2 == pytest.approx(mse, rel=1e-10)
    assert res.rmse_m == pytest.approx(math.sqrt(mse), rel=1e-10)


def test_recovers_a_known_rigid_motion_with_zero_residual():
    rng = np.random.default_rng(7)
    template = loop_path(rng, 60)
    a, t = 0.15, np.array([0.3, -0.2])
    c, s = math.cos(a), math.sin(a)
    rot = np.array([[c, -s], [s, c]])
    model = (template - t) @ rot  # template = R model + t
    res = libicp_point_to_point(template, model)
    assert res.angle_rad == pytest.approx(a, abs=1e-6)
    assert np.allclose(res.translation, t, atol=1e-6)
    assert res.residual_m2 < 1e-10 and np.allclose(res.aligned, template, atol=1e-5)


def test_residual_is_a_mean_square_not_a_root():
    """A model offset by a known distance from every template point, and pinned there
    (a single pair cannot move it closer): residual = d^2, the project's RMSE = d."""
    template = np.array([[0.0, 0.0], [10.0, 0.0]])
    res = libicp_point_to_point(template, np.array([[0.0, 0.3], [10.0, -0.3]]), max_iter=0)
    assert res.residual_m2 == pytest.approx(0.09)
    assert res.rmse_m == pytest.approx(0.3)


def test_roles_and_both_figures_are_named():
    rng = np.random.default_rng(3)
    single = loop_path(rng, 50)
    multi = np.r_[loop_path(rng, 50, noise=0.02), [[0.0, 0.0]] * 5]  # extra points inside
    out = compare_icp(single, multi)
    assert out["libicp_mse_m2"] == pytest.approx(libicp_point_to_point(single, multi).residual_m2)
    assert out["icp_rmse_m"] == pytest.approx(icp(multi, single).rmse)
    assert out["icp_rmse_swapped_m"] == pytest.approx(icp(single, multi).rmse)
    # moving the multisession map (the paper's roles) sees the 5 stray points
    swapped = libicp_point_to_point(multi, single).residual_m2
    assert out["libicp_mse_m2"] > 10 * swapped
    assert set(out["transform"]) == {"dth_rad", "tx_m", "ty_m"}


def test_nearest_neighbours_matches_a_scan_and_bad_input_is_refused():
    rng = np.random.default_rng(0)
    q, p = rng.normal(size=(30, 2)), rng.normal(size=(17, 2))
    j, d2 = nearest_neighbours(q, p)
    for i in range(30):
        dists = [float(((q[i] - x) ** 2).sum()) for x in p]
        assert j[i] == int(np.argmin(dists)) and d2[i] == pytest.approx(min(dists))
    with pytest.raises(InputError, match="non-empty"):
        libicp_point_to_point(np.zeros((0, 2)), p)
    with pytest.raises(InputError, match="NaN"):
        libicp_point_to_point(p, np.full((3, 2), np.nan))
