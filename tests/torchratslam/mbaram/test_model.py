"""MBARAM: equations on hand-sized cases, the vigilance search, learning, stability, errors,
and a ray-cast corridor loop with 682-beam front and rear lasers."""

from __future__ import annotations

import itertools
import math

import networkx as nx
import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from torchratslam.errors import ConfigError, InputError, MapFormatError
from torchratslam.mbaram.inputs import OdometryIntegrator, frame_inputs
from torchratslam.mbaram.metrics import compression_ratio, localisation_success, quantisation_error
from torchratslam.mbaram.model import MBARAM
from torchratslam.mbaram.params import LASER_CHANNELS, MBARAMParams
from torchratslam.mbaram.run import run_mbaram
from torchratslam.messages import Frame

TWO = {"a": 0.6, "b": 0.4}


def two_node_map(params: MBARAMParams | None = None) -> MBARAM:
    """Two nodes in two channels (a: 2-D, b: 1-D), node 0 learnt twice."""
    m = MBARAM(params or MBARAMParams(), TWO, angular={})
    m.learn({"a": [0.0, 0.0], "b": [1.0]})
    m.learn({"a": [0.2, 0.0], "b": [1.0]})  # same place: node 0 learns
    m.learn({"a": [5.0, 5.0], "b": [-3.0]})  # far: node 1
    return m


def gauss(x, mu, var):
    """Eq. 5 with a diagonal covariance, by hand."""
    q = sum((xi - mi) ** 2 / vi for xi, mi, vi in zip(x, mu, var))
    return math.exp(-0.5 * q) / ((2 * math.pi) ** (len(x) / 2) * math.sqrt(math.prod(var)))


def reference_select(m: MBARAM, x: dict, channels=None):
    """Algorithm 1 as written: pick the MAP node, reset it if it fails vigilance, repeat."""
    names = list(channels or m.names)
    wsum = sum(m.weights[k] for k in names)
    n = len(m)
    counts = m.counts[:n].tolist()
    prior = m.prior[:n].tolist()
    score = [0.0] * n
    for k in names:
        mu, var = m.means(k).tolist(), m.covariances(k).tolist()
        joint = [gauss(x[k], mu[j], var[j]) * prior[j] for j in range(n)]
        total = sum(joint)
        for j in range(n):
            score[j] += m.weights[k] / wsum * joint[j] / total  # Eq. 4
    remaining = list(range(n))
    while remaining:
        j = max(remaining, key=lambda i: (score[i], -i))  # Eq. 6
        ok = True
        for k in names:
            a = counts[j] / (counts[j] + 1)
            b = 1 / (counts[j] + 1)
            mu, var = m.means(k)[j].tolist(), m.covariances(k)[j].tolist()
            floor = m.params.var_floor_odometry if k == "odometry" else m.params.var_floor
            new = [max(a * v + b * (a * (xi - mi)) ** 2, floor) for xi, mi, v in zip(x[k], mu, var)]
            ok &= math.prod(new) <= m.params.s_max  # Eqs. 7, 8, 10
        if ok:
            return j, score
        remaining.remove(j)
    return -1, score


def test_params_are_the_papers():
    p = MBARAMParams()
    assert (p.s_max, p.sigma_init_sq, p.p_init) == (1.0, 0.01, 1.0)
    assert p.channel_weights() == {"laser_front": 0.4, "laser_rear": 0.4, "odometry": 0.2}
    with pytest.raises(ConfigError):
        MBARAMParams(s_max=0.0)
    with pytest.raises(ConfigError, match="sum to 1"):
        MBARAM(MBARAMParams(alpha_odometry=0.5))


def test_competition_two_nodes_two_channels_by_hand():
    m = two_node_map()
    assert len(m) == 2
    x = {"a": [0.3, 0.1], "b": [0.5]}
    _, score = reference_select(m, x)
    got = m.scores(x).exp().tolist()
    assert got == pytest.approx(score, rel=1e-9)
    assert sum(got) == pytest.approx(1.0)  # posteriors sum to 1 per channel, weights to 1
    # one channel only: that channel's posterior (Eq. 1)
    _, score_a = reference_select(m, x, ["a"])
    assert m.scores(x, ["a"]).exp().tolist() == pytest.approx(score_a, rel=1e-9)


def test_repeated_input_reuses_node_and_learns_eqs_9_to_12():
    p = MBARAMParams()
    m = MBARAM(p, TWO, angular={})
    x = {"a": [1.0, 2.0], "b": [3.0]}
    r0 = m.learn(x)
    assert r0.is_new and r0.node == 0
    assert m.covariances("a")[0].tolist() == pytest.approx([0.01, 0.01])
    r1 = m.learn(x)
    assert not r1.is_new and r1.node == 0 and len(m) == 1
    # N=1: mu = mu/2 + x/2 = x; Sigma = Sigma/2 + (x - mu)^2/2 = 0.005
    assert m.means("a")[0].tolist() == pytest.approx([1.0, 2.0])
    assert m.covariances("a")[0].tolist() == pytest.approx([0.005, 0.005])
    assert float(m.prior[0]) == pytest.approx(1.0)  # Eq. 11: N_J / sum N = 1/1
    assert float(m.counts[0]) == 2.0
    # a nearby input, N=2: mu = 2/3 mu + x/3; Sigma = 2/3 Sigma + (x - mu_new)^2 / 3
    m.learn({"a": [1.3, 2.0], "b": [3.0]})
    mu = 2 / 3 * 1.0 + 1.3 / 3
    assert m.means("a")[0].tolist() == pytest.approx([mu, 2.0])
    var0 = 2 / 3 * 0.005 + (1.3 - mu) ** 2 / 3
    assert m.covariances("a")[0].tolist() == pytest.approx([var0, 2 / 3 * 0.005])
    assert m.num_edges == 0  # a node is never linked to itself


def test_vigilance_takes_the_best_node_that_passes():
    m = MBARAM(MBARAMParams(s_max=1.0), TWO, angular={})
    m.learn({"a": [0.0, 0.0], "b": [0.0]})
    m.learn({"a": [1.0, 1.0], "b": [6.0]})  # fails node 0 in channel b: node 1
    assert len(m) == 2
    # channel a (alpha 0.6) prefers node 0, channel b (alpha 0.4) node 1: node 0 is the
    # MAP node, but learning b = 3.5 would grow its b variance to 0.005 + 1.75^2 / 2 > 1
    x = {"a": [0.3, 0.3], "b": [3.5]}
    scores = m.scores(x).exp()
    assert scores.tolist() == pytest.approx([0.6, 0.4], abs=1e-9)
    mask = m.vigilance_mask(x)
    assert mask.tolist() == [False, True]
    expect, _ = reference_select(m, x)
    r = m.localise(x)
    assert r.node == expect == 1 and r.rank == 1 and r.best == 0
    assert m.localise(x, ["a"]).node == 0  # without channel b node 0 passes
    r = m.learn(x)
    assert r.node == 1 and not r.is_new and m.graph.has_edge(1, 1) is False


def test_current_vigilance_ignores_the_input_and_zero_weight_is_allowed():
    p = MBARAMParams(
        vigilance="current", alpha_odometry=0.0, alpha_laser_front=0.5, alpha_laser_rear=0.5
    )
    m = MBARAM(p)
    x = {"laser_front": np.ones(5), "laser_rear": np.ones(5), "odometry": [0.0, 0.0, 0.0]}
    far = {"laser_front": np.full(5, 50.0), "laser_rear": np.ones(5), "odometry": [9.0, 9, 1]}
    m.learn(x)
    # det(0.01 I) <= 1 as it stands: the far input is learnt by node 0 ...
    assert m.learn(far).node == 0 and len(m) == 1
    # ... and afterwards node 0 is "full" and never wins again
    assert float(m.hypervolumes("laser_front")[0]) > 0.0
    assert m.learn(x).is_new
    # with weight 0 the odometry channel does not compete but is still checked
    assert m.scores(x).exp().sum().item() == pytest.approx(1.0)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    s_max=st.sampled_from([1e-4, 1e-2, 1.0]),
    n_inputs=st.integers(2, 25),
)
def test_vectorised_search_matches_algorithm_1(seed, s_max, n_inputs):
    rng = np.random.default_rng(seed)
    m = MBARAM(MBARAMParams(s_max=s_max), TWO, angular={})
    for _ in range(n_inputs):
        x = {"a": rng.normal(0, 0.6, 2).tolist(), "b": rng.normal(0, 0.6, 1).tolist()}
        if len(m):
            expect, _ = reference_select(m, x)
            before = len(m)
            r = m.learn(x)
            assert r.node == (expect if expect >= 0 else before)
            assert r.is_new == (expect < 0)
        else:
            assert m.learn(x).is_new
    assert float(m.counts.sum()) == n_inputs
    assert torch.isfinite(m.scores(x)).all()


def test_graph_edges_store_adjacent_angle_and_positions():
    # S_MAX between det(Sigma_init / 2) = 1.25e-7 and det(Sigma_init) = 1e-6: only a repeat passes
    m = MBARAM(MBARAMParams(s_max_odometry=2e-7), {"odometry": 1.0})
    poses = [(0.0, 0.0, 0.0), (10.0, 0.0, 0.0), (10.0, 10.0, 1.5), (0.0, 0.0, 0.0)]
    nodes = [m.learn({"odometry": p}).node for p in poses]
    assert nodes == [0, 1, 2, 0]
    g = m.graph
    assert isinstance(g, nx.DiGraph)
    assert sorted(g.edges) == [(0, 1), (1, 2), (2, 0)]
    for u, v in g.edges:
        dx = g.nodes[v]["x"] - g.nodes[u]["x"]
        dy = g.nodes[v]["y"] - g.nodes[u]["y"]
        e = g.edges[u, v]
        assert e["angle"] == pytest.approx(math.atan2(dy, dx))
        assert e["d"] == pytest.approx(math.hypot(dx, dy))
        assert e["facing"] == pytest.approx(
            math.remainder(g.nodes[v]["th"] - g.nodes[u]["th"], 2 * math.pi)
        )
    assert g.nodes[2]["th"] == pytest.approx(1.5)
    assert nx.shortest_path(g, 0, 2, weight="d") == [0, 1, 2]
    assert m.positions.shape == (3, 3)


def test_heading_mean_wraps_around_pi():
    m = MBARAM(MBARAMParams(), {"odometry": 1.0})
    m.learn({"odometry": [0.0, 0.0, math.pi - 0.05]})
    m.learn({"odometry": [0.0, 0.0, -math.pi + 0.05]})
    th = float(m.means("odometry")[0, 2])
    assert abs(math.remainder(th - math.pi, 2 * math.pi)) < 1e-9  # not 0
    assert float(m.covariances("odometry")[0, 2]) == pytest.approx(0.005 + 0.05**2 / 2)


def test_long_scans_do_not_underflow():
    rng = np.random.default_rng(3)
    base = rng.uniform(0.5, 8.0, 682)
    m = MBARAM(MBARAMParams(), {"laser_front": 0.5, "laser_rear": 0.5})
    for i in range(12):
        m.learn({"laser_front": base + 0.01 * i, "laser_rear": base[::-1] + 0.02 * i})
    other = base + 5.0
    m.learn({"laser_front": other, "laser_rear": other[::-1]})
    assert len(m) == 2
    x = {"laser_front": base + 0.3, "laser_rear": base[::-1] + 0.3}
    # the product of 682 Gaussian densities underflows in float64 ...
    var = m.covariances("laser_front").numpy()
    mu = m.means("laser_front").numpy()
    dens = np.prod(
        np.exp(-0.5 * (x["laser_front"] - mu) ** 2 / var) / np.sqrt(2 * np.pi * var), axis=1
    )
    assert (dens == 0).all()
    # ... the log-space competition keeps both nodes finite and ordered by likelihood
    s = m.scores(x)
    assert torch.isfinite(s).all() and int(s.argmax()) == 0
    loglik = (-0.5 * ((x["laser_front"] - mu) ** 2 / var + np.log(2 * np.pi * var))).sum(1)
    assert np.argmax(loglik) == 0
    assert float(s[1]) < float(s[0]) < 1e-12  # the loser is far below, but not -inf
    assert math.isfinite(float(s[1]))


def test_bad_input_is_an_input_error():
    m = two_node_map()
    with pytest.raises(InputError, match="dimension 3"):
        m.learn({"a": [0.0, 0.0, 0.0], "b": [1.0]})
    with pytest.raises(InputError, match="NaN"):
        m.learn({"a": [0.0, float("nan")], "b": [1.0]})
    with pytest.raises(InputError, match="lacks channel 'b'"):
        m.localise({"a": [0.0, 0.0]})
    with pytest.raises(InputError, match="1-D"):
        m.learn({"a": [[0.0, 0.0]], "b": [1.0]})
    with pytest.raises(ConfigError, match="unknown MBARAM channel"):
        m.localise({"a": [0.0, 0.0], "b": [1.0]}, ["c"])
    with pytest.raises(InputError, match="NaN"):
        frame_inputs(
            {"laser_front": np.array([1.0, np.nan]), "laser_rear": np.ones(2)},
            (0, 0, 0),
            MBARAMParams(),
        )
    with pytest.raises(InputError, match="no scan"):
        frame_inputs({"laser_front": np.ones(2)}, (0, 0, 0), MBARAMParams())
    assert len(m) == 2  # nothing was learnt from bad input


def test_frame_inputs_clip_and_scale():
    p = MBARAMParams(laser_scale=10.0, laser_max_range=5.0, odo_scale=2.0)
    x = frame_inputs(
        {"laser_front": np.array([1.0, np.inf, 7.0]), "laser_rear": np.array([-1.0])},
        (1.0, 2.0, 0.5),
        p,
    )
    assert x["laser_front"].tolist() == [10.0, 50.0, 50.0]
    assert x["laser_rear"].tolist() == [0.0]
    assert x["odometry"].tolist() == [2.0, 4.0, 0.5]


@pytest.mark.parametrize("vigilance", ["updated", "current"])
def test_full_covariance_matches_brute_force(vigilance):
    rng = np.random.default_rng(7)
    p = MBARAMParams(covariance="full", vigilance=vigilance, s_max=2e-6)
    m = MBARAM(p, {"a": 1.0}, angular={})
    for _ in range(30):
        m.learn({"a": rng.normal(0, 0.3, 3)})
    n = len(m)
    assert n >= 2
    x = rng.normal(0, 0.3, 3)
    cov = m.covariances("a").numpy()
    mu = m.means("a").numpy()
    counts, prior = m.counts[:n].numpy(), m.prior[:n].numpy()
    logp = np.array(
        [
            -0.5
            * (
                3 * np.log(2 * np.pi)
                + np.linalg.slogdet(c)[1]
                + (x - u) @ np.linalg.solve(c, x - u)
            )
            for c, u in zip(cov, mu)
        ]
    )
    joint = logp + np.log(prior)
    post = joint - np.log(np.exp(joint - joint.max()).sum()) - joint.max()
    assert m.scores({"a": x}).numpy() == pytest.approx(post, abs=1e-8)
    a, b = counts / (counts + 1), 1 / (counts + 1)
    if vigilance == "updated":
        hv = [
            np.linalg.slogdet(
                a[j] * cov[j] + b[j] * np.outer(a[j] * (x - mu[j]), a[j] * (x - mu[j]))
            )[1]
            for j in range(n)
        ]
    else:
        hv = [np.linalg.slogdet(c)[1] for c in cov]
    assert m.vigilance_mask({"a": x}).numpy().tolist() == (np.array(hv) <= np.log(2e-6)).tolist()
    # learning keeps Sigma = Eq. 10 (full) and its Cholesky factor consistent
    j = m.learn({"a": x}).node
    assert np.linalg.slogdet(m.covariances("a")[j].numpy())[1] == pytest.approx(
        float(m.hypervolumes("a")[j])
    )


def test_state_round_trip_gives_the_same_decisions():
    rng = np.random.default_rng(5)
    m = MBARAM(MBARAMParams(), TWO, angular={})
    for _ in range(20):
        m.learn({"a": rng.normal(0, 1, 2), "b": rng.normal(0, 1, 1)})
    st = m.get_state()
    m2 = MBARAM(MBARAMParams(), TWO, angular={})
    m2.set_state(st)
    assert len(m2) == len(m) and sorted(m2.graph.edges) == sorted(m.graph.edges)
    for _ in range(10):
        x = {"a": rng.normal(0, 1, 2), "b": rng.normal(0, 1, 1)}
        assert m2.learn(x).node == m.learn(x).node
    with pytest.raises(MapFormatError):
        m2.set_state({**st, "version": 99})


def test_metrics_by_hand():
    pts = np.array([[3.0, 4.0], [0.0, 0.0]])
    nodes = np.array([[3.0, 3.0], [0.0, 0.0]])
    assert quantisation_error(pts, nodes) == pytest.approx((1.0 / 5.0) / 2)  # ||.||_max = 5
    assert compression_ratio(1200, 6) == 200.0
    ok = localisation_success(
        np.array([[0.0, 0.5], [np.nan, np.nan], [2.0, 0.0]]), np.zeros((3, 2)), 1.0
    )
    assert ok.tolist() == [True, False, False]
    with pytest.raises(InputError):
        compression_ratio(10, 0)


def test_odometry_integrator_closes_a_square():
    odo = OdometryIntegrator()
    for _ in range(4):
        for _ in range(10):
            odo.step(1.0, 0.0, 0.1)
        odo.step(0.0, math.pi / 2, 1.0)
    assert odo.pose[0] == pytest.approx(0.0, abs=1e-9) and odo.pose[1] == pytest.approx(
        0.0, abs=1e-9
    )


# --------------------------------------------------------- ray-cast corridor loop
def _rect(x0, y0, x1, y1):
    p = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)
    return np.stack([p, np.roll(p, -1, 0)], 1)


WALLS = np.concatenate([_rect(-1, -1, 21, 9), _rect(1, 1, 19, 7)])  # a 2 m wide loop


def _raycast(x, y, th, n=682, fov_deg=240.0, rmax=30.0):
    fov = math.radians(fov_deg)
    ang = th + np.linspace(-fov / 2, fov / 2, n)
    d = np.stack([np.cos(ang), np.sin(ang)], 1)[:, None]
    a, e = WALLS[None, :, 0], (WALLS[:, 1] - WALLS[:, 0])[None]
    w = a - np.array([x, y])
    den = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * e[..., 1] - w[..., 1] * e[..., 0]) / den
        u = (w[..., 0] * d[..., 1] - w[..., 1] * d[..., 0]) / den
    r = np.where((t > 1e-9) & (u >= 0) & (u <= 1), t, np.inf).min(1)
    return np.minimum(r, rmax)


def corridor_lap(seed: int, step: float = 0.5):
    """One lap of the loop as Frames with 682-beam front/rear scans and noisy odometry."""
    rng = np.random.default_rng(seed)
    corners = np.array([[0, 0], [20, 0], [20, 8], [0, 8], [0, 0]], float)
    frames, i = [], 0
    for p, q in itertools.pairwise(corners):
        length = float(np.linalg.norm(q - p))
        th = math.atan2(q[1] - p[1], q[0] - p[0])
        for s in np.arange(0.0, length, step):
            x, y = p + (q - p) * s / length + rng.normal(0, 0.05, 2)
            t = th + rng.normal(0, 0.02)
            scans = {
                "laser_front": _raycast(x, y, t) + rng.normal(0, 0.02, 682),
                "laser_rear": _raycast(x, y, t + math.pi) + rng.normal(0, 0.02, 682),
            }
            frames.append(Frame(i, 0.1 * i, None, step / 0.1, 0.0, 0.1, (x, y, t), scans))
            i += 1
    return frames


@pytest.fixture(scope="module")
def corridor_run():
    laps = [corridor_lap(seed) for seed in range(4)]
    params = MBARAMParams(laser_scale=3.0, s_max_odometry=1e-4, var_floor_odometry=0.01)
    return run_mbaram(laps[:3], laps[3:], params)


def test_corridor_loop_map_converges_and_localises(corridor_run):
    r = corridor_run
    per_lap = r.metrics["nodes_per_lap"]
    assert per_lap[0] >= 5  # several places on the first lap
    assert sum(per_lap[1:]) < per_lap[0]  # later laps add less than the first
    assert r.metrics["nodes"] == sum(per_lap)
    # the map follows the path: every node's place lies in the corridor
    xy = r.node_xy
    in_corridor = ~((xy[:, 0] > 1) & (xy[:, 0] < 19) & (xy[:, 1] > 1) & (xy[:, 1] < 7))
    assert in_corridor.all()
    assert r.metrics["qe_m"] < 1.5
    assert r.metrics["cr"] == pytest.approx(r.metrics["frames"] / r.metrics["nodes"])
    rate_with = r.metrics["localisation_rate_with_odometry"]
    rate_without = r.metrics["localisation_rate_without_odometry"]
    assert rate_with >= 0.5 and rate_with > rate_without
    # the graph is one connected loop
    assert nx.is_weakly_connected(r.model.graph)


def test_localisation_without_odometry_ignores_the_odometry_channel(corridor_run):
    m = corridor_run.model
    f = corridor_lap(9)[17]
    x = frame_inputs(f.scans, f.pose, m.params)
    far = {**x, "odometry": x["odometry"] + np.array([100.0, 100.0, 0.0])}
    assert m.localise(x, LASER_CHANNELS).node == m.localise(far, LASER_CHANNELS).node


def test_cli_writes_metrics_and_figures(tmp_path):
    pytest.importorskip("torchratslam.sim")
    import json

    from torchratslam.cli import main

    out = tmp_path / "mb"
    code = main(
        [
            "mbaram",
            "--data",
            "sim:loop?laps=2&frames=100",
            "--out",
            str(out),
            "--laps",
            "1",
            "--loc-laps",
            "1",
            "--set",
            "laser_scale=3",
        ]
    )
    assert code == 0
    m = json.loads((out / "metrics.json").read_text())
    for key in ("nodes", "edges", "qe", "cr", "localisation_rate_with_odometry"):
        assert key in m
    assert 0 <= m["localisation_rate_without_odometry"] <= 1
    assert m["cr"] == pytest.approx(m["frames"] / m["nodes"])
    assert m["nodes_per_lap"] == [m["nodes"]]
    for name in ("map.png", "nodes_per_lap.png", "localisation.png", "state.npz"):
        assert (out / name).stat().st_size > 0
    assert main(["mbaram", "--data", "sim:loop", "--out", str(out), "--set", "s_max=-1"]) == 2


def _chain(hops: int, jump: float = 0.01) -> MBARAM:
    """Five nodes 10 units apart on a line, linked 0 -> 1 -> ... -> 4, tracking on."""
    built = MBARAM(MBARAMParams(s_max=1e-3), channels={"a": 1.0})
    for i in range(5):
        assert built.learn({"a": torch.tensor([10.0 * i, 0.0])}).is_new
    p = MBARAMParams(s_max=1e-3, vigilance="current", loc_track_hops=hops, loc_track_jump=jump)
    m = MBARAM(p, channels={"a": 1.0})
    m.set_state(built.get_state())
    return m


@pytest.mark.parametrize(("hops", "jump"), [(1, 0.01), (2, 0.3)])
def test_tracking_is_a_bayes_filter_over_the_maps_edges(hops, jump):
    m = _chain(hops, jump)
    n = 5
    # brute force: transition uniform over the nodes within `hops` edges (networkx)
    und = m.graph.to_undirected()
    t = np.zeros((n, n))
    for i in range(n):
        near = nx.single_source_shortest_path_length(und, i, cutoff=hops)
        for j in near:
            t[i, j] = 1.0 / len(near)
    belief = None
    for xv in (0.0, 9.0, 21.0, 40.0, 32.0, 5.0):
        x = {"a": torch.tensor([xv, 0.0])}
        log_m = m.scores(x).numpy()
        if belief is None:
            prior = np.full(n, 1.0 / n)
        else:
            prior = (1 - jump) * belief @ t + jump / n
        belief = np.exp(log_m) * prior
        belief /= belief.sum()
        got = m.localise(x)
        assert got.node == int(np.argmax(belief))  # every node passes "current" vigilance
        assert got.log_m == pytest.approx(math.log(belief.max()), rel=1e-9, abs=1e-9)
    # learning forgets the belief: the next frame starts from a uniform prior
    m.learn({"a": torch.tensor([0.0, 0.0])})
    far = {"a": torch.tensor([40.0, 0.0])}
    assert m.localise(far).node == 4
