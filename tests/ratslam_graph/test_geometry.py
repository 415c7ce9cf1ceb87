"""The one geometry module: wrapping, SE(2), alignment, ring distances, dead reckoning.

Each function is checked against a brute-force loop written here or an invariant.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from ratslam_graph.errors import InputError
from ratslam_graph.geometry import (
    align_se2,
    apply_se2,
    ate_rmse,
    between,
    chain_poses,
    compose,
    dead_reckoning,
    inverse,
    odometry_step,
    pc_distance,
    pc_distance_one,
    ring_distance,
    signed_delta,
    wrap_angle,
)

RNG = np.random.default_rng(11)
PI = math.pi


def _wrap_loop(a: float, include_pi: bool) -> float:
    """Add or subtract whole turns until the angle is in range (brute force)."""
    while a >= PI if not include_pi else a > PI:
        a -= 2 * PI
    while a < -PI if not include_pi else a <= -PI:
        a += 2 * PI
    return a


def _compose_loop(a, b):
    x, y, t = a
    return (
        x + math.cos(t) * b[0] - math.sin(t) * b[1],
        y + math.sin(t) * b[0] + math.cos(t) * b[1],
        t + b[2],
    )


# ---------------------------------------------------------------------------- angles
@pytest.mark.parametrize("include_pi", [False, True])
def test_wrap_matches_a_loop_and_keeps_its_range(include_pi):
    a = RNG.uniform(-40, 40, 400)
    got = wrap_angle(a, include_pi=include_pi)
    want = [_wrap_loop(v, include_pi) for v in a.tolist()]
    np.testing.assert_allclose(got, want, atol=1e-12)
    if include_pi:
        assert np.all(got > -PI) and np.all(got <= PI)
    else:
        assert np.all(got >= -PI) and np.all(got < PI)
    # differs from the input by whole turns only
    turns = (a - got) / (2 * PI)
    np.testing.assert_allclose(turns, np.round(turns), atol=1e-9)


def test_wrap_boundaries_and_types():
    assert wrap_angle(PI) == -PI and wrap_angle(-PI) == -PI  # [-pi, pi)
    assert wrap_angle(PI, include_pi=True) == PI and wrap_angle(-PI, include_pi=True) == PI
    assert isinstance(wrap_angle(7.0), float) and isinstance(wrap_angle(np.float64(7.0)), float)
    assert isinstance(wrap_angle(7), float)
    # a scalar, an array and a tensor give the same bits as the array formula
    a = RNG.uniform(-20, 20, 50)
    arr = wrap_angle(a)
    assert [wrap_angle(float(v)) for v in a] == arr.tolist()
    assert [wrap_angle(float(v), include_pi=True) for v in a] == wrap_angle(
        a, include_pi=True
    ).tolist()
    t = wrap_angle(torch.tensor(a))
    assert isinstance(t, torch.Tensor) and t.dtype == torch.float64
    assert t.tolist() == arr.tolist()
    t32 = wrap_angle(torch.tensor(a, dtype=torch.float32), include_pi=True)
    assert t32.dtype == torch.float32
    np.testing.assert_allclose(t32.numpy(), wrap_angle(a, include_pi=True), atol=1e-5)


def test_signed_delta_is_the_short_way_round():
    a, b = RNG.uniform(-10, 10, (2, 300))
    d = signed_delta(a, b)
    for x, y, v in zip(a.tolist(), b.tolist(), d.tolist()):
        # brute force: the smallest |b - a + 2 pi k| over k
        k = min(range(-5, 6), key=lambda k: abs(y - x + 2 * PI * k))
        assert v == pytest.approx(y - x + 2 * PI * k, abs=1e-9)


# ---------------------------------------------------------------------------- SE(2)
def test_compose_matches_a_loop_and_inverse_is_the_identity():
    a = np.c_[RNG.normal(size=(100, 2)) * 5, RNG.uniform(-6, 6, 100)]
    b = np.c_[RNG.normal(size=(100, 2)) * 5, RNG.uniform(-6, 6, 100)]
    ab = compose(a, b)
    for i in range(100):
        x, y, t = _compose_loop(a[i], b[i])
        np.testing.assert_allclose(ab[i, :2], [x, y], atol=1e-9)
        assert signed_delta(ab[i, 2], t) == pytest.approx(0.0, abs=1e-9)
    for flag in (False, True):
        ident = compose(a, inverse(a, include_pi=flag))
        np.testing.assert_allclose(ident[:, :2], 0.0, atol=1e-9)
        np.testing.assert_allclose(wrap_angle(ident[:, 2]), 0.0, atol=1e-9)
        back = compose(inverse(a, include_pi=flag), a)
        np.testing.assert_allclose(back[:, :2], 0.0, atol=1e-9)
    # between(a, b) is a^-1 b, and composing it back onto a gives b
    rel = between(a, b)
    np.testing.assert_allclose(rel, compose(inverse(a), b), atol=1e-9)
    again = compose(a, rel)
    np.testing.assert_allclose(again[:, :2], b[:, :2], atol=1e-9)
    np.testing.assert_allclose(signed_delta(again[:, 2], b[:, 2]), 0.0, atol=1e-9)


def test_compose_is_associative():
    a, b, c = (np.c_[RNG.normal(size=(20, 2)), RNG.uniform(-4, 4, 20)] for _ in range(3))
    left, right = compose(compose(a, b), c), compose(a, compose(b, c))
    np.testing.assert_allclose(left[:, :2], right[:, :2], atol=1e-9)
    np.testing.assert_allclose(signed_delta(left[:, 2], right[:, 2]), 0.0, atol=1e-9)


# ---------------------------------------------------------------------------- alignment
@pytest.mark.parametrize("angle", [0.0, 0.9, -2.5, PI])
def test_alignment_recovers_a_known_transform(angle):
    pts = np.c_[RNG.normal(size=(40, 2)) * 3, RNG.uniform(-3, 3, 40)]
    t = np.array([2.0, -7.0])
    moved = apply_se2(pts, angle, t)
    fit = align_se2(pts, moved)
    assert signed_delta(fit.angle, angle) == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(fit.translation, t, atol=1e-9)
    np.testing.assert_allclose(fit.rotation @ pts[0, :2] + fit.translation, moved[0, :2])
    got = fit.apply(pts)
    np.testing.assert_allclose(got[:, :2], moved[:, :2], atol=1e-9)
    np.testing.assert_allclose(signed_delta(got[:, 2], moved[:, 2]), 0.0, atol=1e-9)
    assert ate_rmse(pts, moved) < 1e-9
    assert ate_rmse(pts, moved, align=False) > 0.1 or angle == 0.0


def test_weighted_alignment_ignores_zero_weight_points_and_errors_are_clear():
    pts = RNG.normal(size=(30, 2))
    moved = apply_se2(pts, 0.4, np.array([1.0, 2.0]))
    moved[:5] += 100.0  # outliers with zero weight
    w = np.r_[np.zeros(5), np.ones(25)]
    fit = align_se2(pts, moved, w)
    assert fit.angle == pytest.approx(0.4, abs=1e-12)
    with pytest.raises(InputError, match="counts differ"):
        align_se2(pts[:3], pts[:4])
    with pytest.raises(InputError, match="NaN"):
        align_se2(np.full((3, 2), np.nan), pts[:3])
    with pytest.raises(InputError, match="one ground-truth pose"):
        ate_rmse(pts[:3], pts[:4])


# ---------------------------------------------------------------------------- rings
def test_pc_distance_is_symmetric_and_matches_a_loop():
    dims = (10, 12, 36)
    a = RNG.uniform(-15, 45, (200, 3))
    b = RNG.uniform(-15, 45, (200, 3))
    d = pc_distance(a, b, dims)
    np.testing.assert_array_equal(d, pc_distance(b, a, dims))
    for i in range(200):
        s = 0.0
        for k in range(3):
            # brute force: the nearest copy of b on the ring
            s += min(abs(a[i, k] - b[i, k] + j * dims[k]) for j in range(-6, 7)) ** 2
        assert d[i] == pytest.approx(math.sqrt(s), abs=1e-9)
    assert np.all(pc_distance(a, a, dims) == 0.0)
    np.testing.assert_allclose(
        ring_distance(a[:, 2], b[:, 2], 36),
        np.abs(signed_delta(a[:, 2] * 2 * PI / 36, b[:, 2] * 2 * PI / 36) * 36 / (2 * PI)),
        atol=1e-9,
    )
    np.testing.assert_array_equal(ring_distance(a, b, None), np.abs(a - b))


# ---------------------------------------------------------------------------- dead reckoning
def test_dead_reckoning_matches_a_step_by_step_loop():
    n = 60
    v, w, dt = RNG.random(n), RNG.normal(size=n), RNG.random(n) * 0.3
    out = dead_reckoning(v, w, dt, start=(1.0, -2.0, 0.5))
    x, y, th = 1.0, -2.0, 0.5
    for k in range(n):
        th += w[k] * dt[k]
        x += v[k] * dt[k] * math.cos(th)
        y += v[k] * dt[k] * math.sin(th)
        assert out[k, :2] == pytest.approx([x, y], abs=1e-9)
        assert signed_delta(out[k, 2], th) == pytest.approx(0.0, abs=1e-9)
    assert np.all(out[:, 2] >= -PI) and np.all(out[:, 2] < PI)
    with pytest.raises(InputError, match="one length"):
        dead_reckoning(v, w[:-1], dt)


def test_chain_poses_equals_composing_one_step_at_a_time():
    steps = np.c_[RNG.normal(size=(50, 2)), RNG.uniform(-1, 1, 50)]
    start = (3.0, 1.0, -2.0)
    got = chain_poses(steps, start)
    p = np.array(start)
    np.testing.assert_allclose(got[0], start)
    for k in range(1, 50):
        p = compose(p, steps[k])
        np.testing.assert_allclose(got[k, :2], p[:2], atol=1e-9)
        assert signed_delta(got[k, 2], p[2]) == pytest.approx(0.0, abs=1e-9)
    assert chain_poses(np.zeros((0, 3))).shape == (0, 3)


def test_odometry_steps_follow_dead_reckoning_and_close_a_circle():
    n = 40
    v, w, dt = RNG.random(n), RNG.normal(size=n), RNG.random(n) * 0.3
    pose = (1.0, -2.0, 0.5)
    want = dead_reckoning(v, w, dt, start=pose)
    for k in range(n):
        pose = odometry_step(pose, v[k], w[k], dt[k])
        assert pose[:2] == pytest.approx(tuple(want[k, :2]), abs=1e-9)
        assert signed_delta(pose[2], want[k, 2]) == pytest.approx(0.0, abs=1e-12)
        assert -PI <= pose[2] < PI
    # constant speed and turn rate: equal chords turning by equal angles close the loop
    for midpoint in (False, True):
        pose = (3.0, 4.0, 1.0)
        for _ in range(36):
            pose = odometry_step(pose, 2.0, 2 * PI / 36, 1.0, midpoint=midpoint)
        assert pose == pytest.approx((3.0, 4.0, 1.0), abs=1e-9)
    # the midpoint step goes along the mean heading
    x, y, _ = odometry_step((0.0, 0.0, 0.0), 1.0, 1.0, 1.0, midpoint=True)
    assert (x, y) == pytest.approx((math.cos(0.5), math.sin(0.5)))


# ---------------------------------------------------------------------------- one home
WRAP_IDIOMS = re.compile(
    r"%\s*\(?2(\.0)?\s*\*\s*(np|math)\.pi|np\.angle\(np\.exp\(1j|math\.remainder\("
    r"|atan2\(\s*(math|np)\.sin|np\.(mod|remainder)\([^)]*[+-]\s*(np|math)\.pi|def _?wrap"
)
#: the alpha rule's hot scalar loop inlines wrap_angle's arithmetic (commented there)
# the compiled kernels' copies of wrap_angle's float path (tested bit for bit against it)
ALLOWED = {
    "graph/ratslam_graph/geometry.py",
    "graph/ratslam_graph/backends/alpha.py",
    "graph/ratslam_graph/_frame_step.py",
}


def test_angles_are_wrapped_only_by_the_geometry_module():
    root = Path(__file__).resolve().parents[2]
    files = [*(root / "graph").rglob("*.py"), *(root / "torchratslam").rglob("*.py")]
    offenders = {
        str(f.relative_to(root)): m.group(0)
        for f in files
        if str(f.relative_to(root)) not in ALLOWED
        for m in [WRAP_IDIOMS.search(f.read_text())]
        if m
    }
    assert not offenders, f"wrap angles with ratslam_graph.geometry.wrap_angle: {offenders}"
    assert WRAP_IDIOMS.search("th = (a + np.pi) % (2 * np.pi) - np.pi")


def test_the_torch_side_shares_the_one_implementation():
    from ratslam_graph import geometry
    from torchratslam import eval as ev
    from torchratslam.maps import merge
    from torchratslam.pose_cells import stage

    assert ev.align_se2 is geometry.align_se2 and ev.dead_reckoning is geometry.dead_reckoning
    assert merge.pc_distance is geometry.pc_distance is stage.pc_distance


def test_pc_distance_one_gives_pc_distances_bits():
    rng = np.random.default_rng(3)
    dims = (21, 21, 36)
    # cells anywhere on the rings, exactly on cells, half a ring apart, and far outside
    a = np.concatenate(
        [
            rng.uniform(0, 21, (300, 3)),
            np.floor(rng.uniform(0, 21, (100, 3))),
            rng.uniform(-80, 80, (100, 3)),
        ]
    )
    b = np.concatenate(
        [
            rng.uniform(0, 21, (300, 3)),
            a[300:400] + np.array([10.5, 0.0, 18.0]),
            rng.uniform(-80, 80, (100, 3)),
        ]
    )
    for p, q in zip(a, b, strict=True):
        want = float(pc_distance(p, q, dims))
        got = pc_distance_one(p.tolist(), q.tolist(), dims)
        assert got.hex() == want.hex(), (p, q)
