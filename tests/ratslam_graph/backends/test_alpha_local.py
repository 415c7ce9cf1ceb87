"""``alpha_local``: the alpha rule on the links a change reaches."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ratslam_graph.backends import make_backend
from ratslam_graph.backends.alpha import AlphaBackend
from ratslam_graph.backends.alpha_local import AlphaLocalBackend
from ratslam_graph.errors import ConfigError
from ratslam_graph.geometry import between, compose, wrap_angle
from ratslam_graph.posegraph import PoseGraph


def _chain(rng, n, noise=0.0):
    """Poses along a wiggly path, the chain of odometry links between them."""
    truth = np.zeros((n, 3))
    for i in range(1, n):
        truth[i] = compose(truth[i - 1], [1.0, 0.0, rng.uniform(-0.4, 0.4)])
    edges = np.array([(i, i + 1) for i in range(n - 1)])
    meas = between(truth[:-1], truth[1:]) + rng.normal(0, noise, (n - 1, 3))
    meas[:, 2] = wrap_angle(meas[:, 2])
    return truth, edges, meas


def _sweep_in_creation_order(pg, c=0.5):
    """Brute force: one alpha-rule pass, link after link in creation order (floats)."""
    x, y, th = (pg.poses[:, k].tolist() for k in range(3))
    for (f, t), (mx, my, mth) in zip(pg.edges.tolist(), pg.measurements.tolist(), strict=True):
        lx = x[f] + math.cos(th[f]) * mx - math.sin(th[f]) * my
        ly = y[f] + math.sin(th[f]) * mx + math.cos(th[f]) * my
        ex, ey = (x[t] - lx) * c, (y[t] - ly) * c
        x[f], y[f], x[t], y[t] = x[f] + ex, y[f] + ey, x[t] - ex, y[t] - ey
        df = ((th[t] - th[f] - mth + math.pi) % (2 * math.pi) - math.pi) * c
        th[f], th[t] = th[f] + df, th[t] - df
    return np.stack([x, y, wrap_angle(np.array(th))], axis=1)


def test_first_call_is_one_alpha_sweep_over_every_link():
    rng = np.random.default_rng(1)
    truth, edges, meas = _chain(rng, 40, noise=0.05)
    extra = np.array([[0, 20], [5, 35], [10, 39]])
    meas2 = between(truth[extra[:, 0]], truth[extra[:, 1]])
    pg = PoseGraph(truth + rng.normal(0, 0.3, truth.shape), np.r_[edges, extra], np.r_[meas, meas2])
    local = AlphaLocalBackend(tol=1e-15).relax(pg, passes=1)
    np.testing.assert_allclose(local, _sweep_in_creation_order(pg), atol=1e-12)
    # and like alpha, it reaches a fixed point that satisfies a consistent graph
    truth_pg = PoseGraph(
        truth + rng.normal(0, 0.05, truth.shape),
        pg.edges,
        between(truth[pg.edges[:, 0]], truth[pg.edges[:, 1]]),
    )
    out = AlphaLocalBackend(tol=1e-12).relax(truth_pg, passes=2000)
    assert np.abs(truth_pg.relative_errors(out)).max() < 1e-6


def test_appending_a_consistent_experience_touches_only_its_links():
    rng = np.random.default_rng(2)
    truth, edges, meas = _chain(rng, 30)
    backend = AlphaLocalBackend()
    poses = truth[:2].copy()
    out = backend.relax(PoseGraph(poses, edges[:1], meas[:1]), passes=20)
    for k in range(2, 30):
        # the experience map places the new experience where its link puts it
        poses = np.vstack([out, compose(out[-1], meas[k - 1])])
        pg = PoseGraph(poses, edges[:k], meas[:k])
        out = backend.relax(pg, passes=20)
        np.testing.assert_allclose(out, pg.poses, atol=1e-12)
        # brute force: the links touching the new node or its predecessor
        touching = sum(1 for f, t in edges[:k] if {f, t} & {k, k - 1})
        assert backend.last_links == touching and backend.last_passes == 1
        assert backend.last_converged


def test_a_loop_closure_relaxes_its_loop_like_alpha_and_leaves_far_nodes_alone():
    rng = np.random.default_rng(3)
    n = 200
    truth, edges, meas = _chain(rng, n, noise=0.01)
    poses = truth.copy()
    for i in range(1, n):  # dead reckoning along the noisy links
        poses[i] = compose(poses[i - 1], meas[i - 1])
    close = np.array([[150, n - 1]])
    cm = between(truth[150:151], truth[n - 1 :])
    pg = PoseGraph(poses, np.r_[edges, close], np.r_[meas, cm])
    backend = AlphaLocalBackend(tol=1e-4)
    backend.relax(PoseGraph(poses, edges, meas), passes=20)  # the map before the closure
    out = pg.poses
    frames = 0
    while frames < 200:  # frames after the closure, 20 sweeps each
        out = backend.relax(PoseGraph(out, pg.edges, pg.measurements), passes=20)
        frames += 1
        if backend.last_converged:
            break
    assert backend.last_converged and frames < 200
    assert backend.relax(PoseGraph(out, pg.edges, pg.measurements), passes=20) is not None
    assert backend.last_links == 0  # nothing changed since: nothing to do
    ref = pg.poses
    alpha = AlphaBackend()
    for _ in range(frames):
        ref = alpha.relax(PoseGraph(ref, pg.edges, pg.measurements), passes=20)
    # the loop's shape (relative poses of its nodes) agrees with alpha's to about a centimetre
    rel_local = between(out[150:-1], out[151:])
    rel_alpha = between(ref[150:-1], ref[151:])
    # (alpha sweeps in colour order over the whole graph, so it spreads the error a little
    # differently: a few centimetres on this 7 cm closure)
    np.testing.assert_allclose(rel_local, rel_alpha, atol=0.05)
    # the wave died out along the chain: its start never moved, the loop did
    np.testing.assert_allclose(out[:50], poses[:50], rtol=0, atol=1e-12)
    assert np.any(out[150:] != poses[150:], axis=1).sum() >= 30


def test_alpha_wave_carries_its_front_to_the_next_call():
    """With ``carry`` (``alpha_wave``) the wave cut short by ``passes`` or ``budget`` goes
    on at the next call, until it dies down; without it the rest of the correction is
    dropped (nothing new happens, so nothing wakes the links again)."""
    rng = np.random.default_rng(4)
    n = 120
    truth, edges, meas = _chain(rng, n, noise=0.0)
    close = np.array([[10, n - 1]])
    cm = between(truth[10:11], truth[n - 1 :])
    noisy = truth + rng.normal(0, 0.2, truth.shape)
    pg = PoseGraph(noisy, np.r_[edges, close], np.r_[meas, cm])
    wave = make_backend("alpha_wave", tol=1e-9)
    assert wave.carry and wave.name == "alpha_wave"
    dropped = AlphaLocalBackend(tol=1e-9)
    outs = {}
    for name, backend in (("wave", wave), ("dropped", dropped)):
        out = pg.poses
        for _ in range(300):  # 2 sweeps a call
            out = backend.relax(PoseGraph(out, pg.edges, pg.measurements), passes=2)
        outs[name] = out
    # 300 calls of 2 sweeps with the front carried = one call of 600 sweeps
    whole = AlphaLocalBackend(tol=1e-9).relax(pg, passes=600)
    np.testing.assert_allclose(outs["wave"], whole, rtol=0, atol=1e-9)
    # without it, everything after the first call's 2 sweeps is dropped
    first = AlphaLocalBackend(tol=1e-9).relax(pg, passes=2)
    np.testing.assert_array_equal(outs["dropped"], first)
    assert np.abs(outs["dropped"] - whole).max() > 1e-2
    # a budget stops the call early: the rest is carried too
    budgeted = make_backend("alpha_wave", tol=1e-9)
    p = np.ascontiguousarray(pg.poses.copy())
    link = np.stack([np.hypot(pg.measurements[:, 0], pg.measurements[:, 1]),
                     np.arctan2(pg.measurements[:, 1], pg.measurements[:, 0]),
                     pg.measurements[:, 2]], 1)  # fmt: skip
    src, dst = np.ascontiguousarray(pg.edges[:, 0]), np.ascontiguousarray(pg.edges[:, 1])
    budgeted.relax_inplace(p, src, dst, link, passes=50, budget=30)
    assert budgeted.last_links < 30 + 2 * len(src) and not budgeted.last_converged
    assert budgeted.last_passes < 50 and len(budgeted._front)
    start = np.abs(pg.relative_errors(p)).max()
    for _ in range(300):
        budgeted.relax_inplace(p, src, dst, link, passes=50, budget=30)
        assert budgeted.last_links < 30 + 2 * len(src)
    assert np.abs(pg.relative_errors(p)).max() < start / 10


def test_options_and_registry():
    assert isinstance(make_backend("alpha_local"), AlphaLocalBackend)
    with pytest.raises(ConfigError, match="tol"):
        AlphaLocalBackend(tol=0)
    empty = PoseGraph(np.zeros((1, 3)), np.zeros((0, 2), int), np.zeros((0, 3)))
    np.testing.assert_array_equal(AlphaLocalBackend().relax(empty, passes=5), np.zeros((1, 3)))


def test_the_experience_map_relaxes_its_own_arrays_with_alpha_local():
    """End to end: the map made with alpha_local has the same experiences and links as
    with alpha, poses within the wave's residual, and each frame's relaxation touched
    only a few links."""
    import torch

    from torchratslam.config import load_config
    from torchratslam.pipeline import RatSLAM
    from torchratslam.sim import open_sim

    torch.set_num_threads(1)
    maps = {}
    touched = []
    for name in ("alpha", "alpha_local"):
        slam = RatSLAM(load_config("virtual_tour", exp_backend=name))
        cb = None
        if name == "alpha_local":

            def cb(step, slam=slam):
                touched.append(slam.experience_map.backend.last_links)

        slam.run(
            open_sim("sim:virtual_tour/session2?frames_per_lap=100"),
            progress=False,
            max_frames=250,
            callback=cb,
        )
        maps[name] = (slam.experience_map.poses.copy(), slam.experience_map.num_links, slam.ate())
    (pa, la, ate_a), (pl, ll, ate_l) = maps["alpha"], maps["alpha_local"]
    assert pa.shape == pl.shape and la == ll
    assert abs(ate_l - ate_a) < 0.1 * ate_a + 0.05
    # most frames touch the new link or nothing; a loop closure may sweep the loop
    assert np.median(touched) <= 4 and max(touched) <= 250 * ll
