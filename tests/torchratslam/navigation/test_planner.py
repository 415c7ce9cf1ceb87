"""Route planning and arbitration in the experience map's frame; frame labels."""

import itertools

import numpy as np
import pytest

from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.geometry import wrap_angle
from ratslam_graph.params import ExperienceMapParams
from torchratslam.navigation.labels import LabelState, next_label
from torchratslam.navigation.planner import (
    arbitrate,
    back_steps,
    plan_route,
    to_map_frame,
    turn_pairs,
)
from torchratslam.sim.office.motion import Behaviour


def test_to_map_frame_rotates_about_the_robot():
    pts = np.array([[3.0, 2.0], [2.0, 3.0]])
    out = to_map_frame(pts, np.array([2.0, 2.0, 0.0]), np.array([0.0, 0.0, np.pi / 2]))
    np.testing.assert_allclose(out, [[0.0, 1.0], [-1.0, 0.0]], atol=1e-12)


def test_arbitration_chooses_the_path_along_the_route_and_handicaps_turning():
    route = np.array([[0.0, 0.0], [0.0, 5.0]])  # the route goes up (+y)
    pose = np.array([0.0, 0.0, np.pi / 2])
    paths = [
        (Behaviour.FOLLOW, np.array([[0.0, 1.0], [0.0, 2.0], [0.0, 3.0]])),
        (Behaviour.LEFT, np.array([[-1.0, 0.0], [-2.0, 0.0]])),
        (Behaviour.TURN_AROUND, np.array([[0.0, -1.0], [0.0, -2.0]])),
    ]
    b, d = arbitrate(paths, pose, pose, route, lookahead_m=3.0, turn_margin_m=0.5)
    assert b is Behaviour.FOLLOW and d[Behaviour.FOLLOW] < d[Behaviour.LEFT]
    back = np.array([[0.0, 0.0], [0.0, -5.0]])
    b, d = arbitrate(paths, pose, pose, back, lookahead_m=3.0, turn_margin_m=0.5)
    assert b is Behaviour.TURN_AROUND
    b, _ = arbitrate(paths, pose, pose, back, lookahead_m=3.0, turn_margin_m=100.0)
    assert b is not Behaviour.TURN_AROUND


def test_plan_route_follows_links_and_groups_overlapping_experiences():
    em = ExperienceMap(ExperienceMapParams(exp_initial_em_deg=0.0, exp_link_time="per_link"))
    for _ in range(6):  # a chain 0..5 along +x, 1 m and 1 s apart
        em.create_experience()
        em.on_odometry(1.0, 0.0, 1.0)
    plan = plan_route(em, 0, directed=False)  # links both ways: back along the chain
    assert plan.route is not None and plan.route.ids == [5, 4, 3, 2, 1, 0]
    assert plan.tmap.times[0] > plan.tmap.times[5]
    # the links were driven 0 -> 5 only: no chain of executed behaviours leads back
    assert plan_route(em, 0).route is None
    em.set_current(0)
    fwd = plan_route(em, 5)
    assert fwd.route is not None and fwd.route.ids == [0, 1, 2, 3, 4, 5]


def test_a_forced_turn_keeps_the_label_the_robot_moved_with():
    s = next_label(LabelState(), to_node_m=5.0, held=1, event=-1, blocked=False, moved_m=0.1)
    assert s.label == Behaviour.FOLLOW
    s = next_label(s, to_node_m=0.5, held=1, event=-1, blocked=False, moved_m=0.1)
    assert s.label == Behaviour.LEFT
    s = next_label(LabelState(), to_node_m=5.0, held=1, event=3, blocked=True, moved_m=0.0)
    assert s.label == Behaviour.FOLLOW
    s = next_label(LabelState(), to_node_m=5.0, held=0, event=3, blocked=False, moved_m=0.0)
    assert s.label == Behaviour.TURN_AROUND


def test_no_route_takes_a_shortcut_through_the_goal_or_the_start():
    # links slower than driving straight to the goal (0.25 m in 1 s, 0.5 m/s assumed):
    # reaching the goal through the goal node would be quicker than along the chain
    em = ExperienceMap(ExperienceMapParams(exp_initial_em_deg=0.0, exp_link_time="per_link"))
    for _ in range(6):
        em.create_experience()
        em.on_odometry(0.25, 0.0, 1.0)
    plan = plan_route(em, 0, directed=False)
    assert plan.route is not None
    ids = plan.route.ids
    assert ids[-1] in range(5) and ids[0] in range(2, 6)
    assert all(a - b == 1 for a, b in itertools.pairwise(ids))  # along the chain's links
    assert np.all(np.diff(plan.route.times) > 0)


def _chain(em: ExperienceMap, xy: np.ndarray, th: float) -> list[int]:
    """Experiences at ``xy`` facing ``th``, linked in order (driven at 0.5 m/s)."""
    ids = [em.store.add_experience(float(x), float(y), th) for x, y in xy]
    for a, b in itertools.pairwise(ids):
        d = float(np.hypot(*(em.poses[b, :2] - em.poses[a, :2])))
        em.store.add_link(a, b, d, 0.0, 0.0, d / 0.5)
    return ids


def test_turn_pairs_match_a_brute_force_search():
    rng = np.random.default_rng(3)
    poses = np.c_[rng.uniform(-4, 4, (250, 2)), rng.uniform(-np.pi, np.pi, 250)]
    moving = rng.random(250) < 0.8
    a, b = turn_pairs(poses, 1.0, np.pi / 4, moving)
    want = set()
    for i, j in itertools.permutations(range(250), 2):
        rot = abs(wrap_angle(poses[i, 2] - poses[j, 2]))
        near = np.hypot(*(poses[i, :2] - poses[j, :2])) <= 1.0
        if near and np.pi / 4 < rot < 3 * np.pi / 4 and moving[i] and moving[j]:
            want.add((i, j))
    assert set(zip(a.tolist(), b.tolist())) == want and len(a) == len(want)


def test_a_route_turns_where_two_ways_cross_though_that_turn_was_never_driven():
    em = ExperienceMap(ExperienceMapParams(exp_initial_em_deg=0.0, exp_link_time="per_link"))
    south = _chain(em, np.c_[np.zeros(4), [3.0, 2.0, 1.0, 0.3]], -np.pi / 2)
    east = _chain(em, np.c_[[0.4, 1.4, 2.4, 3.4], np.zeros(4)], 0.0)  # from the junction on
    em.set_current(south[0])
    assert plan_route(em, east[-1], turns=False).route is None
    plan = plan_route(em, east[-1], turns=True)
    assert plan.route is not None
    ids = plan.route.ids
    assert ids[0] == south[0] and ids[-1] in east  # (the goal's place: within 1 m of it)
    k = next(i for i, x in enumerate(ids) if x in east)  # one turn, south onto east
    assert ids[:k] == south[:k] and ids[k:] == east[east.index(ids[k]) : east.index(ids[-1]) + 1]
    assert np.hypot(*(em.poses[ids[k - 1], :2] - em.poses[ids[k], :2])) <= 1.0
    assert np.all(np.isfinite(plan.tmap.times[: em.store.n]))  # one time per experience


def test_no_route_steps_along_a_corridor_past_a_missing_link_by_turning():
    em = ExperienceMap(ExperienceMapParams(exp_initial_em_deg=0.0, exp_link_time="per_link"))
    x = np.arange(0.0, 6.01, 0.25)
    cut = int(np.flatnonzero(x == 3.0)[0])
    west = _chain(em, np.c_[x[::-1] + 0.1, np.full(len(x), 0.05)], np.pi)  # driven west
    east1 = _chain(em, np.c_[x[:cut], np.zeros(cut)], 0.0)  # east, up to the cut
    east2 = _chain(em, np.c_[x[cut:], np.zeros(len(x) - cut)], 0.0)  # on from it
    # a turn on the spot just short of the cut: half-turned experiences, linked by 0 m
    turning = [em.store.add_experience(2.9, 0.0, th) for th in np.linspace(0.3, 2.8, 6)]
    for a, b in itertools.pairwise([east1[-1], *turning, west[x.size - cut]]):
        em.store.add_link(a, b, 0.0, 0.0, 0.0, 0.3)
    em.set_current(east1[0])
    assert plan_route(em, east2[-1], turns=True).route is None  # turning never passes
    assert plan_route(em, east2[-1], directed=False).route is not None  # links both ways do


def test_arbitration_follows_the_route_s_shape_from_the_robot_not_its_offset():
    # the map holds the route's turn 2.5 m behind the robot (two representations of a
    # junction apart in the map): the route turns left where the robot is
    pose = np.zeros(3)
    route = np.array([[-2.5, 0.0], [-2.5, 1.0], [-2.5, 2.0], [-2.5, 3.0]])
    s = np.linspace(0.1, 3.0, 30)[:, None]
    paths = [
        (
            Behaviour.LEFT,
            np.vstack([np.c_[s[:5, 0] * 0.7 / 0.5, 0 * s[:5, 0]], [0.7, 0] + s * [0, 1]]),
        ),
        (
            Behaviour.RIGHT,
            np.vstack([np.c_[s[:5, 0] * 0.7 / 0.5, 0 * s[:5, 0]], [0.7, 0] - s * [0, 1]]),
        ),
        (Behaviour.TURN_AROUND, -s * [1, 0]),
    ]
    b, d = arbitrate(paths, pose, pose, route, lookahead_m=3.0, turn_margin_m=0.6, from_robot=True)
    assert b is Behaviour.LEFT and d[Behaviour.LEFT] < d[Behaviour.RIGHT]
    # the same route placed on the robot: the same choice
    moved = route - route[0]
    b2, d2 = arbitrate(
        paths, pose, pose, moved, lookahead_m=3.0, turn_margin_m=0.6, from_robot=True
    )
    assert b2 is b and d2 == d
    # by map positions the route looks like the way back
    b3, _ = arbitrate(paths, pose, pose, route, lookahead_m=3.0, turn_margin_m=0.6)
    assert b3 is Behaviour.TURN_AROUND


def test_a_route_turns_back_along_links_driven_the_other_way():
    em = ExperienceMap(ExperienceMapParams(exp_initial_em_deg=0.0, exp_link_time="per_link"))
    s = np.arange(0.0, 5.01, 1.0)
    east = _chain(em, np.c_[s, np.zeros(6)], 0.0)  # a square loop driven anticlockwise
    north = _chain(em, np.c_[np.full(6, 6.0), s], np.pi / 2)
    west = _chain(em, np.c_[6.0 - s, np.full(6, 6.0)], np.pi)
    south = _chain(em, np.c_[np.zeros(5), 5.0 - s[:5]], -np.pi / 2)
    for a, b in ((east[-1], north[0]), (north[-1], west[0]), (west[-1], south[0])):
        em.store.add_link(a, b, 1.0, 0.0, 0.0, 2.0)
    em.store.add_link(south[-1], east[0], 1.0, 0.0, 0.0, 2.0)
    em.set_current(east[-1])  # at the east end, facing east; the goal is behind
    ahead = plan_route(em, east[1])
    assert ahead.route is not None and north[0] in ahead.route.ids  # round the loop
    back = plan_route(em, east[1], turn_back=True)
    assert back.route is not None
    ids = back.route.ids
    # turn around (pi at pi/2 rad/s: 2 s), 4 m back at 0.5 m/s (the goal's place is
    # reached within 1 m of it: the goal node's time makes up the last metre)
    assert back.route.total_time == pytest.approx(2.0 + 8.0)
    assert ahead.route.total_time > back.route.total_time + 20.0
    assert set(ids) <= set(east) and ids[0] in east[-2:]  # (the robot's place: within 1 m)
    keys = set(zip(em.store.src[: em.store.e].tolist(), em.store.dst[: em.store.e].tolist()))
    for a, b in itertools.pairwise(ids):  # each step a turn on the spot or a link backwards
        assert a == b or (b, a) in keys
    # one turn, at the start (the current experience faced back: the turn's time is the
    # start's), not at another experience near the robot, nor ahead
    assert [k for k in range(1, len(ids)) if ids[k] == ids[k - 1]] == []
    assert ids[:2] == [east[-1], east[-2]]
    em.accum_facing = np.pi  # the robot has turned round already: no turn left to take
    faced = plan_route(em, east[1], turn_back=True).route
    assert faced is not None and faced.total_time == pytest.approx(8.0)
    em.accum_facing = 0.0
    # the goal's place given: the route ends there, not at another experience near it
    only = plan_route(em, east[1], turn_back=True, goal_place=np.array([east[1]]))
    assert only.route is not None and only.route.ids[-1] == east[1]
    assert only.route.total_time == pytest.approx(2.0 + 8.0)
    assert np.all(np.diff(back.route.times) > 0)
    assert np.all(back.tmap.times[: em.store.n] <= ahead.tmap.times[: em.store.n] + 1e-9)
    # the goal ahead: turning back changes nothing
    em.set_current(east[0])
    fwd = plan_route(em, east[-1], turn_back=True)
    assert fwd.route is not None and fwd.route.ids == plan_route(em, east[-1]).route.ids


def test_a_route_steps_past_an_experience_learnt_behind_the_current_one():
    # driven east along y = 0: experience d was learnt 7 cm behind c[0] while c[0] was
    # current, so the pair's one link runs c[0] -> d (backwards); every later pass went
    # ... -> w[-1] -> d -> c[0] -> ..., and d -> c[0] was never learnt (a pair is linked
    # once): the driven links from the west end at d
    em = ExperienceMap(ExperienceMapParams(exp_initial_em_deg=0.0, exp_link_time="per_link"))
    w = _chain(em, np.c_[[0.0, 0.5, 1.0], np.zeros(3)], 0.0)
    c = _chain(em, np.c_[[1.5, 2.0, 2.5, 3.0, 3.5], np.zeros(5)], 0.0)
    d = em.store.add_experience(1.43, 0.0, 0.0)
    em.store.add_link(c[0], d, 0.07, np.pi, 0.0, 0.2)
    em.store.add_link(w[-1], d, 0.43, 0.0, 0.0, 0.86)
    em.set_current(w[0])
    for turns in (False, True):
        assert plan_route(em, c[-1], radius_m=0.3, turns=turns).route is None
        plan = plan_route(em, c[-1], radius_m=0.3, turns=turns, back_step_m=0.1)
        assert plan.route is not None
        assert plan.route.ids == [*w, d, *c]  # c[0] -> d followed back, d onto c[0]
        # the links' times: w's two, w[-1] -> d, c[0] -> d (backwards), c's four
        assert plan.route.total_time == pytest.approx(2.0 + 0.86 + 0.2 + 4.0)
    assert plan_route(em, c[-1], radius_m=0.3, back_step_m=0.05).route is None  # too long


def test_back_steps_are_short_links_between_experiences_facing_one_way():
    rng = np.random.default_rng(11)
    em = ExperienceMap(ExperienceMapParams(exp_initial_em_deg=0.0, exp_link_time="per_link"))
    for x, y, th in np.c_[rng.uniform(0, 3, (60, 2)), rng.uniform(-np.pi, np.pi, 60)]:
        em.store.add_experience(float(x), float(y), float(th))
    for a, b in rng.integers(0, 60, (120, 2)):
        if a != b:
            em.store.add_link(int(a), int(b), float(rng.uniform(0, 0.3)), 0.0, 0.0, 1.0)
    got = back_steps(em.store, em.poses, 0.1, np.pi / 4)
    st = em.store
    for k in range(st.e):  # one link at a time
        rot = abs(wrap_angle(em.poses[st.src[k], 2] - em.poses[st.dst[k], 2]))
        assert got[k] == (st.link[k, 0] <= 0.1 and rot <= np.pi / 4)
    assert 0 < got.sum() < st.e


def test_no_route_walks_back_along_a_chain_of_short_links():
    # a corridor driven west only, in links of 7 cm: followed against their way one at a
    # time (each lands where only links the way they were driven lead on), they never
    # take a route east
    em = ExperienceMap(ExperienceMapParams(exp_initial_em_deg=0.0, exp_link_time="per_link"))
    west = _chain(em, np.c_[np.arange(2.0, -0.01, -0.07), np.zeros(29)], np.pi)
    em.set_current(west[-1])  # at the west end, x = 0.04
    assert plan_route(em, west[0], radius_m=0.2, back_step_m=0.1, turns=True).route is None
    assert plan_route(em, west[0], radius_m=0.2, directed=False).route is not None
