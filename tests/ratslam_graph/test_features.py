"""The experience-map paper's features (Eqs. 1-4, 6, 8, 9, 10-11 and routes).

Each equation is restated here with explicit loops or the paper's matrices and compared
with the vectorised implementation, on random inputs and small hand-made maps.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ratslam_graph import queries
from ratslam_graph.errors import GraphError, InputError
from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.features import (
    average_transition,
    experience_activity,
    link_confidence,
    peak_experience,
    rotate_link_components,
    temporal_map,
)
from ratslam_graph.geometry import inverse, signed_delta, wrap_angle
from ratslam_graph.messages import Action, ActionKind
from ratslam_graph.params import ExperienceMapParams

PI = math.pi
RNG = np.random.default_rng(1234)


def clip_rad_180(a: float) -> float:
    while a > PI:
        a -= 2 * PI
    while a <= -PI:
        a += 2 * PI
    return a


class InOrderAlpha:
    """Alpha rule, Gauss-Seidel over the edges by source, then given order (test reference)."""

    def relax(self, pg, *, passes: int, correction: float = 0.5) -> np.ndarray:
        p = pg.poses.copy()
        order = np.argsort(pg.edges[:, 0], kind="stable")
        for _ in range(passes):
            for (i, j), (dx, dy, dth) in zip(
                pg.edges[order].tolist(), pg.measurements[order].tolist()
            ):
                c, s = math.cos(p[i, 2]), math.sin(p[i, 2])
                ex = p[j, 0] - (p[i, 0] + c * dx - s * dy)
                ey = p[j, 1] - (p[i, 1] + s * dx + c * dy)
                p[i, :2] += (ex * correction, ey * correction)
                p[j, :2] -= (ex * correction, ey * correction)
                da = clip_rad_180(p[j, 2] - p[i, 2] - dth)
                p[i, 2] = clip_rad_180(p[i, 2] + da * correction)
                p[j, 2] = clip_rad_180(p[j, 2] - da * correction)
        return p


def make(**kw) -> ExperienceMap:
    return ExperienceMap(ExperienceMapParams(**kw), backend=InOrderAlpha())


# ---------------------------------------------------------------- angles
def test_wrap_and_signed_delta_match_openratslam_loops():
    a = RNG.uniform(-20, 20, 500)
    np.testing.assert_allclose(
        wrap_angle(a, include_pi=True), [clip_rad_180(v) for v in a], atol=1e-12
    )
    assert (
        wrap_angle(PI, include_pi=True) == PI and wrap_angle(-PI, include_pi=True) == PI
    )  # (-pi, pi]
    b = RNG.uniform(-20, 20, 500)
    np.testing.assert_allclose(
        signed_delta(a, b, include_pi=True), [clip_rad_180(y - x) for x, y in zip(a, b)], atol=1e-12
    )


# ------------------------------------------------------------ Eqs. 1-4
def activity_loop(pc, vt, cur, vcur, ra, tha, dims=None):
    out = []
    for (x, y, th), v in zip(pc.tolist(), vt.tolist()):
        dx, dy, dth = abs(cur[0] - x), abs(cur[1] - y), abs(cur[2] - th)
        if dims is not None:
            dx, dy = (
                min(dx % dims[0], dims[0] - dx % dims[0]),
                min(dy % dims[0], dims[0] - dy % dims[0]),
            )
            dth = min(dth % dims[1], dims[1] - dth % dims[1])
        r = math.sqrt(dx**2 + dy**2) / ra  # Eq. 1
        t = dth / tha  # Eq. 2
        e = 0.0 if (r > 1 or t > 1) else 2 - r - t  # Eq. 3
        out.append(e if v == vcur else 0.0)  # Eq. 4
    return out


@pytest.mark.parametrize("dims", [None, (20, 36)])
def test_activity_follows_eqs_1_to_4(dims):
    n = 400
    cur = np.array([3.0, 18.5, 1.0])
    pc = np.column_stack([RNG.uniform(0, 20, n), RNG.uniform(0, 20, n), RNG.uniform(0, 36, n)])
    pc[:50] = cur + RNG.uniform(-2, 2, (50, 3))  # some inside the zone
    vt = RNG.integers(0, 3, n)
    e = experience_activity(pc, vt, cur, 1, zone_xy=3.0, zone_th=4.0, dims=dims)
    np.testing.assert_allclose(e, activity_loop(pc, vt, cur, 1, 3.0, 4.0, dims), atol=1e-12)
    assert e.min() >= 0 and e.max() <= 2 and np.count_nonzero(e) > 5
    assert np.all(e[vt != 1] == 0)  # Eq. 4: the view switches experiences off
    if dims is not None:  # the short way round the network: near; plainly: far
        near = experience_activity(
            np.array([[0.5, 18.0, 35.5]]), [1], cur, 1, zone_xy=3.0, zone_th=4.0, dims=dims
        )
        assert near[0] > 0
        plain = experience_activity(
            np.array([[0.5, 18.0, 35.5]]), [1], cur, 1, zone_xy=3.0, zone_th=4.0
        )
        assert plain[0] == 0


def test_peak_experience_and_map_activity():
    em = make(exp_activity_zone_xy=2.0, exp_activity_zone_th=3.0)
    em.store.add_experience(0, 0, 0, pc=(5, 5, 10), template_id=4)
    em.store.add_experience(1, 0, 0, pc=(5.5, 5, 10), template_id=4)  # closest to the packet
    em.store.add_experience(2, 0, 0, pc=(6, 6, 11), template_id=4)
    em.store.add_experience(3, 0, 0, pc=(6, 5, 10), template_id=9)  # other view: off
    pc = (5.8, 5.1, 10.2)
    act = queries.activity(em.view(), pc, 4)
    np.testing.assert_allclose(
        act, activity_loop(em.view().pc, em.view().template_id, pc, 4, 2.0, 3.0)
    )
    assert queries.peak_experience(em.view(), pc, 4) == (1, pytest.approx(act[1]))
    assert act[1] == act.max() and act[3] == 0
    # nothing active: learn a new experience
    assert queries.peak_experience(em.view(), pc, 77) == (-1, 0.0)
    assert peak_experience(np.zeros(0)) == (-1, 0.0)
    with pytest.raises(InputError):
        experience_activity(np.zeros((2, 3)), [1], np.zeros(3), 1, zone_xy=1.0, zone_th=1.0)


# ---------------------------------------------------------------- Eq. 6
def eq6_matrices(old_paper: np.ndarray, cur_paper: np.ndarray) -> np.ndarray:
    """dp_new = A dp_old + B dp_curr in the paper's (dth, dx, dy) order, literally."""
    _, ox, oy = old_paper
    _, cx, cy = cur_paper
    dtheta = 0.5 * (math.atan(cy / cx) - math.atan(oy / ox))
    ds = (math.hypot(cx, cy) + math.hypot(ox, oy)) / (2 * math.hypot(ox, oy))
    a = np.array(
        [
            [0.5, 0, 0],
            [0, ds * math.cos(dtheta), -ds * math.sin(dtheta)],
            [0, ds * math.sin(dtheta), ds * math.cos(dtheta)],
        ]
    )
    b = np.diag([0.5, 0.0, 0.0])
    return a @ old_paper + b @ cur_paper


def to_paper(t):  # [dx, dy, dth] -> (dth, dx, dy)
    return np.array([t[2], t[0], t[1]])


def test_link_averaging_follows_eq_6():
    for _ in range(200):
        old = np.array([RNG.uniform(0.1, 3), RNG.uniform(-3, 3), RNG.uniform(-1.5, 1.5)])
        cur = np.array([RNG.uniform(0.1, 3), RNG.uniform(-3, 3), RNG.uniform(-1.5, 1.5)])
        got = average_transition(old, cur)
        np.testing.assert_allclose(
            to_paper(got), eq6_matrices(to_paper(old), to_paper(cur)), atol=1e-12
        )
    # the new transition has the mean length; averaging a transition with itself keeps it
    old, cur = np.array([2.0, 0.0, 0.1]), np.array([0.0, 4.0, 0.3])
    got = average_transition(old, cur)
    assert math.hypot(got[0], got[1]) == pytest.approx(3.0)
    assert math.atan2(got[1], got[0]) == pytest.approx(PI / 4) and got[2] == pytest.approx(0.2)
    np.testing.assert_allclose(average_transition(old, old), old, atol=1e-15)
    # batched, and the wrap-safe mean heading change (deviation documented)
    batch = average_transition(np.tile(old, (5, 1)), np.tile(cur, (5, 1)))
    np.testing.assert_allclose(batch, np.tile(got, (5, 1)))
    near_pi = average_transition([1.0, 0.0, PI - 0.1], [1.0, 0.0, -PI + 0.1])
    assert abs(near_pi[2]) == pytest.approx(PI)
    # zero-length stored transition: half the current one (limit of the mean length)
    np.testing.assert_allclose(
        average_transition([0.0, 0.0, 0.0], [2.0, 2.0, 0.4]), [1.0, 1.0, 0.2]
    )


def _drive(em: ExperienceMap, legs):
    for v, w, dt in legs:
        em.on_odometry(v, w, dt)


def _accumulate(start_facing, legs):
    x = y = t = 0.0
    f = start_facing
    for v, w, dt in legs:
        f = clip_rad_180(f + w * dt)
        x += v * dt * math.cos(f)
        y += v * dt * math.sin(f)
        t += dt
    return x, y, f, t


@pytest.mark.parametrize("averaging", [True, False])
def test_repeated_transitions_are_averaged_into_the_link(averaging):
    em = make(
        exp_initial_em_deg=0.0, exp_loops=0, exp_link_averaging=averaging, exp_link_time="per_link"
    )
    em.apply(Action(ActionKind.CREATE, dest_id=0))
    _drive(em, [(1.0, 0.0, 2.0)])
    em.apply(Action(ActionKind.CREATE, dest_id=1))  # link 0 -> 1: (2, 0, 0), 2 s
    old = em.posegraph().measurements[0].copy()
    np.testing.assert_allclose(old, [2.0, 0.0, 0.0], atol=1e-12)
    # drive back exactly, facing the other way (relative view angle pi): consistent with
    # the link, so averaging the reversed transition leaves it unchanged
    _drive(em, [(0.0, PI, 1.0), (1.0, 0.0, 2.0)])
    em.apply(Action(ActionKind.SET, dest_id=0, relative_rad=PI))
    np.testing.assert_allclose(em.posegraph().measurements[0], old, atol=1e-12)
    # go again, along a different path, and link to 1 (the pair is already linked)
    legs = [(0.0, PI, 1.0), (1.0, 0.15, 2.5)]
    x, y, f, t = _accumulate(em.accum_facing, legs)
    _drive(em, legs)
    rel = 0.05
    em.apply(Action(ActionKind.LINK, dest_id=1, relative_rad=rel))
    assert em.num_links == 1
    cur = np.array([x, y, clip_rad_180(f + rel)])  # exp 0 has th = 0: map frame = its frame
    link = em.links()
    got = em.posegraph().measurements[0]
    assert link["traversals"][0] == 3
    if averaging:
        np.testing.assert_allclose(
            to_paper(got), eq6_matrices(to_paper(old), to_paper(cur)), atol=1e-12
        )
        assert link["dt"][0] == pytest.approx(0.5 * (0.5 * (2.0 + 3.0) + t))
    else:  # OpenRatSLAM: the first measurement stays
        np.testing.assert_allclose(got, old, atol=1e-12)
        assert link["dt"][0] == 2.0


def test_invert_transition_composes_to_identity():
    t = np.column_stack([RNG.normal(size=50), RNG.normal(size=50), RNG.uniform(-PI, PI, 50)])
    inv = inverse(t, include_pi=True)
    # compose t then inv: x = tx + R(tth) inv_xy must be 0, heading 0
    c, s = np.cos(t[:, 2]), np.sin(t[:, 2])
    x = t[:, 0] + c * inv[:, 0] - s * inv[:, 1]
    y = t[:, 1] + s * inv[:, 0] + c * inv[:, 1]
    np.testing.assert_allclose(
        np.column_stack([x, y, wrap_angle(t[:, 2] + inv[:, 2], include_pi=True)]), 0, atol=1e-12
    )


# ---------------------------------------------------------------- Eq. 8
def test_rotate_link_components_is_eq_8():
    comp = RNG.normal(size=(30, 3))
    dth = RNG.uniform(-PI, PI, 30)
    expected = [
        np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
        @ to_paper(c)
        for c, a in zip(comp, dth)
    ]
    got = rotate_link_components(comp, dth)
    np.testing.assert_allclose([to_paper(g) for g in got], expected, atol=1e-12)


def test_relaxation_rotates_outgoing_link_components_by_eq_8():
    em = make(exp_loops=3)
    rng = np.random.default_rng(7)
    em.apply(Action(ActionKind.CREATE, dest_id=0))
    for k in range(1, 30):
        em.on_odometry(1.0, float(rng.uniform(-0.5, 0.5)), 1.0)
        if k % 7 == 0:
            em.apply(Action(ActionKind.LINK, dest_id=int(rng.integers(0, len(em) - 1))))
        else:
            em.apply(Action(ActionKind.CREATE, dest_id=len(em)))
    before_global = queries.link_components(em.view(), "global")
    before_local = queries.link_components(em.view(), "local")
    th_before = em.poses[:, 2].copy()
    em.iterate()
    dth = wrap_angle(em.poses[:, 2] - th_before, include_pi=True)
    assert np.abs(dth).max() > 1e-3  # relaxation did rotate experiences
    src = em.links()["src"]
    expected = []
    for comp, i in zip(before_global, src.tolist()):
        a = dth[i]
        m = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
        expected.append(m @ to_paper(comp))
    after = queries.link_components(em.view(), "global")
    np.testing.assert_allclose([to_paper(c) for c in after], expected, atol=1e-9)
    # stored relative
    np.testing.assert_array_equal(queries.link_components(em.view(), "local"), before_local)
    with pytest.raises(InputError):
        queries.link_components(em.view(), "polar")


# ---------------------------------------------------------------- Eq. 9
def obstacle_map(threshold: float) -> ExperienceMap:
    """0 junction; top route 0-1-2 (4 s, behaviour 1), bottom route 0-3-4-2 (9 s, behaviour 2)."""
    em = make(exp_loops=0, exp_link_confidence_threshold=threshold)
    for x, y in [(0, 0), (1, 1), (2, 0), (1, -1), (2, -1)]:
        em.store.add_experience(x, y, 0.0)
    em.store.add_link(0, 1, 1.4, 0.8, 0.0, 2.0, behaviour=1)
    em.store.add_link(1, 2, 1.4, -0.8, 0.0, 2.0, behaviour=1)
    em.store.add_link(0, 3, 1.4, -0.8, 0.0, 3.0, behaviour=2)
    em.store.add_link(3, 4, 1.0, 0.0, 0.0, 3.0, behaviour=2)
    em.store.add_link(4, 2, 1.0, 1.6, 0.0, 3.0, behaviour=2)
    em.set_current(0)
    return em


def test_transition_failures_lower_confidence_and_delete_the_link():
    em = obstacle_map(threshold=0.3)
    top = queries.route(em.view(), 2)
    assert top.ids == [0, 1, 2] and top.times == [0.0, 2.0, 4.0]
    # one success, then the top route is blocked: leaving 0 "towards the top"
    # (behaviour 1) the robot ends up at 3 instead of 1
    em.apply(Action(ActionKind.SET, dest_id=1), behaviour=1)
    em.set_current(0)
    n_ij, n_i = 2, 2  # successes of 0->1, departures from 0 with behaviour 1 (incl. creation)
    failures = 0
    while em.graph.has_edge(0, 1) and failures < 10:
        em.apply(Action(ActionKind.SET, dest_id=3), behaviour=1)
        n_i += 1
        failures += 1
        if not em.graph.has_edge(0, 1):
            break
        links = em.links()
        k = int(np.flatnonzero((links["src"] == 0) & (links["dst"] == 1))[0])
        assert (links["successes"][k], links["trials"][k]) == (n_ij, n_i)
        assert links["confidence"][k] == pytest.approx(n_ij / n_i)  # Eq. 9
        assert em.graph.edges[0, 1]["confidence"] == pytest.approx(n_ij / n_i)
        # the bottom link (behaviour 2) saw no trial
        k3 = int(np.flatnonzero((links["src"] == 0) & (links["dst"] == 3))[0])
        assert links["trials"][k3] == 1
        em.set_current(0)
    # deleted as soon as n_ij / n_i < 0.3: 2/7
    assert failures == 5 and n_ij / n_i < 0.3 <= n_ij / (n_i - 1)
    assert em.num_links == 4 and not em.graph.has_edge(0, 1)
    assert [0, 1] not in em.posegraph().edges.tolist()
    em.set_current(0)
    # the paper's adaptation: plan the longer route round the obstacle
    route = queries.route(em.view(), 2)
    assert route.ids == [0, 3, 4, 2] and route.times == [0.0, 3.0, 6.0, 9.0]
    assert route.total_time == 9.0 and len(route) == 4


def test_no_deletion_with_threshold_zero():
    em = obstacle_map(threshold=0.0)
    for _ in range(20):
        em.apply(Action(ActionKind.SET, dest_id=3), behaviour=1)
        em.set_current(0)
    assert em.num_links == 5
    assert em.graph.edges[0, 1]["confidence"] == pytest.approx(1 / 21)
    # learning a new experience is a departure too: one more failure for 0 -> 1
    new = em.create_experience(behaviour=1)
    assert em.graph.edges[0, 1]["trials"] == 22
    assert em.graph.edges[0, 3]["trials"] == 1  # other behaviour: untouched
    edge = em.graph.edges[0, new]
    assert (edge["traversals"], edge["successes"], edge["trials"], edge["behaviour"]) == (
        1,
        1,
        1,
        1,
    )


def test_link_confidence_function():
    np.testing.assert_allclose(link_confidence([1, 2, 0], [1, 4, 0]), [1.0, 0.5, 1.0])


# --------------------------------------------------------- Eqs. 10-11
def brute_force_times(n, edges, w, start):
    """Floyd-Warshall over links traversable both ways."""
    d = np.full((n, n), np.inf)
    np.fill_diagonal(d, 0.0)
    for (a, b), t in zip(edges, w):
        d[a, b] = min(d[a, b], t)
        d[b, a] = min(d[b, a], t)
    for k in range(n):
        d = np.minimum(d, d[:, [k]] + d[[k], :])
    return d[start]


def test_temporal_map_iteration_reaches_the_shortest_times():
    for trial in range(5):
        n = 40
        e = 70
        edges = RNG.integers(0, n, (e, 2))
        edges = edges[edges[:, 0] != edges[:, 1]]
        w = RNG.uniform(0, 5, len(edges))
        start = trial
        got = temporal_map(n, edges, w, start)
        np.testing.assert_allclose(got, brute_force_times(n, edges, w, start))
    assert np.isinf(temporal_map(3, [[0, 1]], [1.0], 0)[2])
    with pytest.raises(InputError):
        temporal_map(3, [[0, 1]], [-1.0], 0)
    with pytest.raises(InputError):
        temporal_map(3, [[0, 1]], [1.0], 5)


def test_map_temporal_map_and_routes():
    em = make(exp_loops=1)
    rng = np.random.default_rng(3)
    em.apply(Action(ActionKind.CREATE, dest_id=0))
    for _ in range(80):
        em.on_odometry(1.0, float(rng.uniform(-0.4, 0.4)), float(rng.uniform(0.5, 2)))
        if rng.uniform() < 0.2 and len(em) > 3:
            dest = int(rng.integers(len(em)))
            if dest != em.current_id:
                em.apply(Action(ActionKind.LINK, dest_id=dest))
        else:
            em.apply(Action(ActionKind.CREATE, dest_id=len(em)))
        em.iterate()
    links = em.links()
    edges = np.column_stack([links["src"], links["dst"]])
    for start in (0, em.current_id, 17):
        expected = brute_force_times(len(em), edges, links["dt"], start)
        np.testing.assert_allclose(queries.temporal_map(em.view(), start), expected, atol=1e-9)
        iterated = queries.temporal_map(em.view(), start, method="iterate")
        np.testing.assert_allclose(iterated, expected, atol=1e-9)
    times = queries.temporal_map(em.view())
    for goal in (0, 5, len(em) - 1):
        route = queries.route(em.view(), goal)
        assert route.ids[0] == em.current_id and route.ids[-1] == goal
        assert route.total_time == pytest.approx(times[goal])
        for (a, b), (ta, tb) in zip(
            zip(route.ids, route.ids[1:]), zip(route.times, route.times[1:])
        ):
            k = em.store.link_index(a, b)
            assert k >= 0 and tb - ta == pytest.approx(links["dt"][k])
            assert tb == pytest.approx(times[b])  # each node time-stamped by the temporal map
    iso = em.store.add_experience(100.0, 100.0, 0.0)
    with pytest.raises(GraphError, match="cannot be reached"):
        queries.route(em.view(), iso)
    assert np.isinf(queries.temporal_map(em.view())[iso])
    with pytest.raises(InputError):
        queries.temporal_map(em.view(), method="astar")


def test_activity_measures_each_axis_on_its_own_ring():
    """dims (X, Y, TH): an experience across the y wrap of a 40-cell ring is near, the
    same offset in x (ring of 100) is not a wrap; (XY, TH) is the square special case."""
    pcs = np.array([[50.0, 39.5, 3.0], [99.5, 20.0, 3.0], [50.0, 20.0, 35.5]])
    cur = np.array([50.0, 0.5, 3.0])
    got = experience_activity(
        pcs, np.zeros(3), cur, 0, zone_xy=5.0, zone_th=4.0, dims=(100, 40, 36)
    )
    for i, p in enumerate(pcs):
        gaps = [
            min(abs(p[a] - cur[a]) % n, n - abs(p[a] - cur[a]) % n)
            for a, n in enumerate((100, 40, 36))
        ]
        r, t = math.hypot(gaps[0], gaps[1]) / 5.0, gaps[2] / 4.0
        assert got[i] == pytest.approx(0.0 if r > 1 or t > 1 else 2 - r - t)
    assert got[0] == pytest.approx(2 - 1 / 5)
    square = experience_activity(pcs, np.zeros(3), cur, 0, zone_xy=5.0, zone_th=4.0, dims=(100, 36))
    assert np.array_equal(
        square,
        experience_activity(
            pcs, np.zeros(3), cur, 0, zone_xy=5.0, zone_th=4.0, dims=(100, 100, 36)
        ),
    )
