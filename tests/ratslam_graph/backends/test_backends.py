"""Relaxation backends: the alpha rule (reference loop and vectorised), LM and iSAM2."""

import math

import gtsam
import numpy as np
import pytest

from ratslam_graph.backends import GraphErrorEvaluator, make_backend
from ratslam_graph.backends import alpha as alpha_module
from ratslam_graph.backends.alpha import (
    AlphaBackend,
    EdgeColouring,
    dependency_levels,
    reference_order,
)
from ratslam_graph.compare import compare_backends, format_table
from ratslam_graph.errors import ConfigError, GraphError, InputError
from ratslam_graph.geometry import (
    align_se2,
    apply_se2,
    ate_rmse,
    between,
    compose,
    wrap_angle,
)
from ratslam_graph.io import example_file, read_posegraph
from ratslam_graph.posegraph import PoseGraph

W100_ALPHA_FIXED_POINT = 1.077  # the compiled reference-order loop on w100
W100_LM = 0.569


@pytest.fixture(scope="module")
def w100():
    return read_posegraph(example_file("w100.graph"))


@pytest.fixture(scope="module")
def city():
    return read_posegraph(example_file("T1_city10000_04.txt"))


def _sequential_alpha(pg, order, passes, c=0.5):
    """Brute force: the rule link by link in the given order, in place (plain floats)."""
    x, y, th = (pg.poses[:, k].tolist() for k in range(3))
    for _ in range(passes):
        for i in order:
            f, t = pg.edges[i]
            mx, my, mth = pg.measurements[i]
            d, heading = math.hypot(mx, my), math.atan2(my, mx)
            lx = x[f] + d * math.cos(th[f] + heading)
            ly = y[f] + d * math.sin(th[f] + heading)
            ex, ey = x[t] - lx, y[t] - ly
            x[f] += ex * c
            y[f] += ey * c
            x[t] -= ex * c
            y[t] -= ey * c
            df = (th[t] - th[f] - mth + math.pi) % (2 * math.pi) - math.pi
            th[f] = (th[f] + df * c + math.pi) % (2 * math.pi) - math.pi
            th[t] = (th[t] - df * c + math.pi) % (2 * math.pi) - math.pi
    return np.stack([x, y, th], axis=1)


def _random_graph(rng, n=25, loops=15, noise=0.1):
    """A noisy chain with random loop closures; edges in random direction."""
    truth = np.zeros((n, 3))
    for i in range(1, n):
        truth[i] = compose(truth[i - 1], [1.0, 0.0, rng.uniform(-0.6, 0.6)])
    pairs = [(i, i + 1) for i in range(n - 1)]
    while len(pairs) < n - 1 + loops:
        a, b = rng.choice(n, 2, replace=False)
        if (a, b) not in pairs and (b, a) not in pairs:
            pairs.append((int(a), int(b)))
    edges = np.array(pairs)
    flip = rng.random(len(edges)) < 0.3
    edges[flip] = edges[flip][:, ::-1]
    meas = between(truth[edges[:, 0]], truth[edges[:, 1]]) + rng.normal(0, noise, (len(edges), 3))
    meas[:, 2] = wrap_angle(meas[:, 2])
    init = truth + rng.normal(0, 0.5, truth.shape)
    return PoseGraph(init, edges, meas), truth


def _edge_residual(pg, poses):
    return np.abs(pg.relative_errors(poses)).max()


# ---------------------------------------------------------------- alpha rule


def test_reference_backend_is_the_reference_loop(w100):
    order = reference_order(w100.edges).tolist()
    ours = make_backend("alpha_reference").relax(w100, passes=3)
    np.testing.assert_allclose(ours, _sequential_alpha(w100, order, 3), atol=1e-12)


@pytest.fixture(params=["vectorised", "scalar"])
def kernel(request, monkeypatch):
    """Run a test with the numpy kernel and with the small-graph Python kernel."""
    monkeypatch.setattr(
        alpha_module, "SCALAR_EDGES_PER_CLASS", 0 if request.param == "vectorised" else 10**9
    )
    return request.param


@pytest.mark.parametrize("seed", range(4))
def test_level_schedule_reproduces_the_reference_exactly(seed, kernel):
    pg, _ = _random_graph(np.random.default_rng(seed))
    ref = make_backend("alpha_reference").relax(pg, passes=40, correction=0.5)
    fast = make_backend("alpha", schedule="reference").relax(pg, passes=40, correction=0.5)
    np.testing.assert_allclose(fast, ref, atol=1e-9)
    # general correction uses the angle path rather than the c = 0.5 complex path
    ref3 = make_backend("alpha_reference").relax(pg, passes=40, correction=0.3)
    fast3 = make_backend("alpha", schedule="reference").relax(pg, passes=40, correction=0.3)
    np.testing.assert_allclose(fast3, ref3, atol=1e-9)


@pytest.mark.parametrize("correction", [0.5, 0.25])
def test_colour_schedule_is_a_gauss_seidel_sweep_in_colour_order(correction, kernel):
    pg, _ = _random_graph(np.random.default_rng(7), n=40, loops=30)
    backend = AlphaBackend()
    fast = backend.relax(pg, passes=25, correction=correction)
    colour = backend._colouring.colour
    order = np.lexsort((np.arange(len(colour)), colour)).tolist()
    brute = _sequential_alpha(pg, order, 25, correction)
    np.testing.assert_allclose(fast, brute, atol=1e-9)


def test_colour_classes_are_matchings_and_extend_incrementally(city):
    col = EdgeColouring()
    assert col.update(city.edges[:5000]) is False
    assert col.update(city.edges) is True  # appended: extended, not rebuilt
    deg = np.bincount(city.edges.ravel())
    assert col.num_colours <= 2 * deg.max() - 1
    for k in range(col.num_colours):
        nodes = city.edges[col.colour == k].ravel()
        assert len(np.unique(nodes)) == len(nodes), f"colour {k} touches a node twice"
    assert col.update(city.edges[1:]) is False  # anything else: recoloured


def test_dependency_levels_respect_the_reference_order(w100):
    level = dependency_levels(w100.edges)
    order = reference_order(w100.edges)
    last = {}
    for i in order.tolist():
        f, t = w100.edges[i]
        assert level[i] > max(last.get(f, -1), last.get(t, -1))
        last[f] = last[t] = level[i]


@pytest.mark.parametrize("seed", range(3))
def test_both_alphas_reach_the_same_fixed_point_on_consistent_graphs(seed, kernel):
    # noise-free measurements: every fixed point satisfies every link
    pg, truth = _random_graph(np.random.default_rng(seed), noise=0.0)
    ref = make_backend("alpha_reference").relax(pg, passes=400)
    fast = make_backend("alpha").relax(pg, passes=400)
    assert _edge_residual(pg, ref) < 1e-6
    assert _edge_residual(pg, fast) < 1e-6
    # same map up to where the relaxation left the whole (a rigid motion)
    assert ate_rmse(fast, ref) < 1e-6 and ate_rmse(fast, truth) < 1e-6


def test_w100_fixed_points(w100, monkeypatch):
    monkeypatch.setattr(alpha_module, "SCALAR_EDGES_PER_CLASS", 0)  # the numpy kernel
    ev = GraphErrorEvaluator(w100)
    ref = make_backend("alpha_reference").relax(w100, passes=300)
    assert ev(ref) == pytest.approx(W100_ALPHA_FIXED_POINT, rel=0.01)
    exact = make_backend("alpha", schedule="reference").relax(w100, passes=300)
    assert ev(exact) == pytest.approx(W100_ALPHA_FIXED_POINT, rel=0.01)
    np.testing.assert_allclose(exact, ref, atol=1e-9)
    # the colour order has its own fixed point: a pass no longer moves it, and its
    # error is close to the reference order's, far above least squares (0.569)
    colour = make_backend("alpha")
    p = colour.relax(w100, passes=1500)
    again = colour.relax(w100.with_poses(p), passes=1)
    assert np.abs(again - p).max() < 1e-7
    assert ev(p) == pytest.approx(W100_ALPHA_FIXED_POINT, rel=0.08)
    assert ev(p) > 1.5 * W100_LM


@pytest.mark.parametrize(("name", "passes"), [("w100", 150), ("city", 12)])
def test_fast_alpha_never_increases_the_error(name, passes, w100, city):
    pg = {"w100": w100, "city": city}[name]
    ev = GraphErrorEvaluator(pg)
    backend = make_backend("alpha")
    p, errors = pg.poses, [ev(pg.poses)]
    for _ in range(passes):
        p = backend.relax(pg.with_poses(p), passes=1)
        errors.append(ev(p))
    # then a few long strides
    for _ in range(3):
        p = backend.relax(pg.with_poses(p), passes=40)
        errors.append(ev(p))
    assert np.all(np.diff(errors) <= 1e-9 * errors[0]), errors


def test_naive_jacobi_alpha_diverges_on_w100(w100):
    # the warning of the alpha module's docstring, as a guard: all links from the same old
    # poses, corrections summed per node, c = 0.5
    ev = GraphErrorEvaluator(w100)
    p = w100.poses.copy()
    f, t = w100.edges[:, 0], w100.edges[:, 1]
    for _ in range(30):
        pred = compose(p[f], w100.measurements)
        err = p[t] - pred
        err[:, 2] = wrap_angle(err[:, 2])
        delta = np.zeros_like(p)
        np.add.at(delta, f, 0.5 * err)
        np.add.at(delta, t, -0.5 * err)
        p = p + delta
    assert not np.isfinite(ev(p)) or ev(p) > ev(w100.poses)


def test_alpha_options_are_checked(w100):
    with pytest.raises(ConfigError, match="passes"):
        make_backend("alpha").relax(w100, passes=-1)
    with pytest.raises(ConfigError, match="correction"):
        make_backend("alpha_reference").relax(w100, passes=1, correction=0.0)
    with pytest.raises(ConfigError, match="schedule"):
        make_backend("alpha", schedule="jacobi")


def test_alpha_leaves_the_graph_alone_and_handles_empty_graphs(w100):
    before = w100.poses.copy()
    make_backend("alpha").relax(w100, passes=5)
    np.testing.assert_array_equal(w100.poses, before)
    lone = PoseGraph(np.array([[1.0, 2.0, 0.5]]), np.zeros((0, 2)), np.zeros((0, 3)))
    for name in ("alpha", "alpha_reference", "gtsam", "isam2"):
        np.testing.assert_array_equal(make_backend(name).relax(lone, passes=3), lone.poses)


def test_alpha_grows_with_the_graph_like_a_fresh_backend(w100, kernel):
    online = make_backend("alpha")
    first = w100.subgraph(20)
    np.testing.assert_allclose(
        online.relax(first, passes=5), make_backend("alpha").relax(first, passes=5), atol=1e-12
    )
    for n in (50, 100):
        online.relax(w100.subgraph(n), passes=5)
    # appended edges are coloured in insertion order, so the online colouring is still
    # a valid schedule: check it against the brute-force sweep in its own order
    colour = online._colouring.colour
    order = np.lexsort((np.arange(len(colour)), colour)).tolist()
    np.testing.assert_allclose(
        online.relax(w100, passes=4), _sequential_alpha(w100, order, 4), atol=1e-9
    )


@pytest.mark.parametrize("correction", [0.5, 0.3])
def test_alpha_early_stop_only_at_a_fixed_point(kernel, correction):
    rng = np.random.default_rng(7)
    pg, truth = _random_graph(rng, n=60, loops=20)
    # consistent graph at its solution: the first pass moves nothing, one pass suffices
    exact = PoseGraph(truth, pg.edges, between(truth[pg.edges[:, 0]], truth[pg.edges[:, 1]]))
    b = AlphaBackend()
    out = b.relax(exact, passes=20, correction=correction, tol=1e-12)
    assert b.last_passes == 1 and b.last_converged
    np.testing.assert_allclose(out, truth, atol=1e-12)
    # a noisy graph far from its fixed point runs every pass, bit-identical to tol=0
    b0, b1 = AlphaBackend(), AlphaBackend()
    full = b0.relax(pg, passes=20, correction=correction)
    assert b0.last_passes == 20 and not b0.last_converged
    np.testing.assert_array_equal(b1.relax(pg, passes=20, correction=correction, tol=1e-9), full)
    assert b1.last_passes == 20
    # the brute-force sweep in the colour order agrees with the full run
    colour = b0._colouring.colour
    sweep = np.lexsort((np.arange(len(colour)), colour)).tolist()
    np.testing.assert_allclose(full, _sequential_alpha(pg, sweep, 20, correction), atol=1e-9)
    # at the sweep's fixed point: stopping early equals running every pass to ~1e-9
    settled = PoseGraph(b0.relax(pg, passes=3000, correction=correction), pg.edges, pg.measurements)
    b2 = AlphaBackend()
    early = b2.relax(settled, passes=20, correction=correction, tol=1e-9)
    assert b2.last_passes == 1 and b2.last_converged
    always = _sequential_alpha(settled, sweep, 20, correction)
    diff = early - always
    diff[:, 2] = wrap_angle(diff[:, 2])
    assert np.abs(diff).max() < 1e-8
    with pytest.raises(ConfigError, match="tol"):
        b2.relax(pg, passes=2, tol=-1.0)


# ---------------------------------------------------------------- gtsam and iSAM2


def _lm_error_direct(pg):
    """LM straight from gtsam, built here independently of ratslam_graph.backends."""
    g = gtsam.NonlinearFactorGraph()
    for (a, b), m, info in zip(pg.edges.tolist(), pg.measurements, pg.information):
        g.add(
            gtsam.BetweenFactorPose2(
                a, b, gtsam.Pose2(*m), gtsam.noiseModel.Gaussian.Information(info)
            )
        )
    g.add(
        gtsam.PriorFactorPose2(
            0, gtsam.Pose2(*pg.poses[0]), gtsam.noiseModel.Isotropic.Sigma(3, 1e-4)
        )
    )
    init = gtsam.Values()
    for i, p in enumerate(pg.poses):
        init.insert(i, gtsam.Pose2(*p))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(0.0)
    params.setMaxIterations(200)
    result = gtsam.LevenbergMarquardtOptimizer(g, init, params).optimize()
    out = np.array(
        [
            [result.atPose2(i).x(), result.atPose2(i).y(), result.atPose2(i).theta()]
            for i in range(pg.num_poses)
        ]
    )
    return GraphErrorEvaluator(pg)(out)


@pytest.mark.parametrize("name", ["w100", "city500"])
def test_gtsam_and_isam2_reach_the_lm_error(name, w100, city):
    pg = w100 if name == "w100" else city.subgraph(500)
    lm = _lm_error_direct(pg)
    if name == "w100":
        assert lm == pytest.approx(W100_LM, rel=2e-3)
    ev = GraphErrorEvaluator(pg)
    assert ev(make_backend("gtsam").relax(pg, passes=0)) == pytest.approx(lm, rel=1e-6)
    # iSAM2 fed pose by pose, as online use does, then one settling update (with the
    # default threshold 0.01 it ends within ~3e-5; 0.001 gets to LM's error)
    isam = make_backend("isam2", relinearize_threshold=0.001)
    for n in range(2, pg.num_poses + 1, 1 if name == "w100" else 5):
        isam.relax(pg.subgraph(n), passes=0)
    final = isam.relax(pg, passes=0)
    final = isam.relax(pg, passes=0)
    assert isam.rebuilds == 1  # built once, then only appended to
    assert ev(final) == pytest.approx(lm, rel=1e-6)


def test_isam2_rebuilds_when_links_change_or_components_join():
    rng = np.random.default_rng(3)
    pg, _ = _random_graph(rng, n=30, loops=10)
    lm = make_backend("gtsam")
    isam = make_backend("isam2")
    isam.relax(pg, passes=0)
    assert isam.rebuilds == 1
    edited = PoseGraph(pg.poses, pg.edges, pg.measurements + 0.05)  # e.g. link averaging
    ev = GraphErrorEvaluator(edited)
    out = isam.relax(edited, passes=0)
    assert isam.rebuilds == 2
    assert ev(out) == pytest.approx(ev(lm.relax(edited, passes=0)), rel=1e-6)
    # two separate chains (a merge before any inter-map link): one prior each
    a, _ = _random_graph(rng, n=10, loops=3)
    b, _ = _random_graph(rng, n=10, loops=3)
    two = PoseGraph(
        np.vstack([a.poses, b.poses + np.array([5.0, 5.0, 0.0])]),
        np.vstack([a.edges, b.edges + 10]),
        np.vstack([a.measurements, b.measurements]),
    )
    isam = make_backend("isam2")
    p2 = isam.relax(two, passes=0)
    assert GraphErrorEvaluator(two)(p2) == pytest.approx(
        GraphErrorEvaluator(two)(lm.relax(two, passes=0)), rel=1e-6, abs=1e-9
    )
    joined = PoseGraph(
        two.poses, np.vstack([two.edges, [[9, 10]]]), np.vstack([two.measurements, [[1.0, 0, 0]]])
    )
    p3 = isam.relax(joined, passes=0)
    assert isam.rebuilds == 2  # joining two old components drops a prior: rebuild
    ev3 = GraphErrorEvaluator(joined)
    assert ev3(p3) == pytest.approx(ev3(lm.relax(joined, passes=0)), rel=1e-6)


def test_graph_error_is_gtsams_and_uses_the_file_information(w100, city):
    sub = city.subgraph(200)
    g = gtsam.NonlinearFactorGraph()
    for (a, b), m in zip(sub.edges.tolist(), sub.measurements):
        g.add(
            gtsam.BetweenFactorPose2(
                a,
                b,
                gtsam.Pose2(*m),
                gtsam.noiseModel.Diagonal.Sigmas(np.array([1 / 30, 1 / 30, 1 / 100])),
            )
        )
    v = gtsam.Values()
    for i, p in enumerate(sub.poses + 0.01):
        v.insert(i, gtsam.Pose2(*p))
    assert GraphErrorEvaluator(sub)(sub.poses + 0.01) == pytest.approx(g.error(v), rel=1e-12)
    # no information: the default unit model, or the sigmas asked for
    bare = PoseGraph(sub.poses, sub.edges, sub.measurements)
    unit = GraphErrorEvaluator(bare)(sub.poses + 0.01)
    moved = sub.poses + 0.01
    logs = [
        gtsam.Pose2.Logmap(
            gtsam.Pose2(*m).between(gtsam.Pose2(*moved[a]).between(gtsam.Pose2(*moved[b])))
        )
        for (a, b), m in zip(sub.edges.tolist(), sub.measurements)
    ]
    assert unit == pytest.approx(0.5 * np.sum(np.square(logs)), rel=1e-9)
    scaled = GraphErrorEvaluator(bare, sigmas=(2.0, 2.0, 2.0))(sub.poses + 0.01)
    assert scaled == pytest.approx(unit / 4, rel=1e-12)


def test_make_backend_errors():
    with pytest.raises(ConfigError, match="did you mean 'isam2'"):
        make_backend("isam")
    with pytest.raises(ConfigError, match="bad option"):
        make_backend("gtsam", passes=3)
    with pytest.raises(ConfigError, match="sigmas"):
        make_backend("gtsam", sigmas=(1.0, -1.0, 1.0))


def test_gtsam_reports_a_bad_information_matrix():
    info = np.zeros((1, 3, 3))
    pg = PoseGraph(np.zeros((2, 3)), [[0, 1]], [[1.0, 0, 0]], information=info)
    with pytest.raises(GraphError, match="information"):
        make_backend("gtsam").relax(pg, passes=0)


# ---------------------------------------------------------------- alignment, comparison


def test_align_se2_recovers_a_rigid_motion():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(50, 3))
    moved = apply_se2(pts, 1.234, np.array([3.0, -2.0]))
    fit = align_se2(pts, moved)
    angle, t = fit.angle, fit.translation
    assert angle == pytest.approx(1.234, abs=1e-12)
    np.testing.assert_allclose(t, [3.0, -2.0], atol=1e-12)
    np.testing.assert_allclose(fit.apply(pts), moved, atol=1e-12)
    assert ate_rmse(pts, moved) < 1e-12
    # brute force: no rotation on a fine grid fits better than the closed form
    noisy = moved[:, :2] + rng.normal(0, 0.1, (50, 2))
    best = ate_rmse(pts, noisy)
    for a in np.linspace(-np.pi, np.pi, 721):
        p = apply_se2(pts, a, np.zeros(2))[:, :2]
        t = noisy.mean(0) - p.mean(0)
        assert np.sqrt(np.mean(np.sum((p + t - noisy) ** 2, 1))) >= best - 1e-12
    with pytest.raises(InputError):
        ate_rmse(pts[:3], moved[:4])


def test_compare_backends_reports_time_error_and_ate(city):
    pg = city.subgraph(300)
    from ratslam_graph.io import read_poses

    gt = read_poses(example_file("ISAM2_GT_city10000.txt"))[:300]
    rows = compare_backends(pg, ("alpha", "gtsam", "isam2"), gt, passes=50)
    assert [r["name"] for r in rows] == ["alpha", "gtsam", "isam2"]
    by = {r["name"]: r for r in rows}
    ev = GraphErrorEvaluator(pg)
    for r in rows:
        assert r["time_s"] >= 0 and r["error"] == pytest.approx(ev(r["poses"]))
        assert r["ate_rmse_m"] == pytest.approx(ate_rmse(r["poses"], gt))
        assert r["error"] < r["initial_error"]
    assert by["gtsam"]["error"] == pytest.approx(by["isam2"]["error"], rel=1e-6)
    assert by["gtsam"]["error"] < by["alpha"]["error"]
    assert by["gtsam"]["ate_rmse_m"] < 0.5 * ate_rmse(pg.poses, gt)  # better than odometry
    assert "| gtsam |" in format_table(rows)
    with pytest.raises(InputError, match="groundtruth"):
        compare_backends(pg, ("alpha",), gt[:10])
