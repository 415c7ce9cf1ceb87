"""When the navigator believes it has arrived: map distance, and (by default) the goal's
place being the current experience."""

import itertools
from types import SimpleNamespace

import networkx as nx
import numpy as np
import pytest

from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.params import ExperienceMapParams
from torchratslam.errors import ConfigError
from torchratslam.navigation.agent import Goal, NavigationAgent
from torchratslam.navigation.params import NavParams
from torchratslam.navigation.planner import plan_route


def _corner(templates):
    """A corridor's end squeezed by the map: experiences 0.3 m apart along +x (the floor
    held them a metre apart), one per template given, the robot at the last."""
    em = ExperienceMap(ExperienceMapParams(exp_initial_em_deg=0.0, exp_link_time="per_link"))
    for vt in templates:
        em.create_experience(template_id=vt)
        em.on_odometry(0.3, 0.0, 1.0)
    return em


def _agent(em, **kw):
    robot = SimpleNamespace(slam=SimpleNamespace(experience_map=em))
    return NavigationAgent(robot, NavParams(**kw))  # type: ignore[arg-type]


def _at(em, i):
    em.set_current(i)  # the robot's map position is experience i's (no odometry since)
    em.accum_x = em.accum_y = 0.0
    return em


def test_distance_alone_stops_short_where_the_map_squeezes_the_floor():
    em = _corner([0, 1, 2, 3, 4, 5])
    goal = Goal("A", (5.0, 0.0), 5)
    _at(em, 3)  # 0.6 m of map from the goal experience, two experiences (2 m of floor) short
    assert _agent(em, arrive_at_place=False)._arrived(goal)
    assert not _agent(em)._arrived(goal)  # the goal's place is not current: drive on
    _at(em, 5)
    assert _agent(em)._arrived(goal)
    _at(em, 0)  # 1.5 m of map away: neither rule has arrived, however current
    assert not _agent(em, arrive_at_place=False)._arrived(goal)


def test_an_experience_with_the_goal_s_view_template_is_the_goal_s_place():
    em = _corner([0, 1, 2, 7, 4, 7])  # experience 3 saw the goal's view
    goal = Goal("A", (5.0, 0.0), 5)
    _at(em, 3)
    assert _agent(em)._arrived(goal)
    _at(em, 4)  # the goal's neighbour, another view
    assert not _agent(em)._arrived(goal)
    assert _agent(em, arrive_links=1)._arrived(goal)


@pytest.mark.parametrize("hops", [0, 1, 2, 3])
def test_the_goal_s_place_matches_a_breadth_first_search(hops):
    rng = np.random.default_rng(hops)
    em = _corner(rng.integers(0, 6, 30).tolist())
    for a, b in rng.integers(0, 30, (12, 2)).tolist():  # loop closures
        if a != b:
            em.link_to(b)
            em.set_current(a)
    goal = Goal("A", (0.0, 0.0), 11)
    g = nx.Graph(
        list(zip(em.store.src[: em.store.e].tolist(), em.store.dst[: em.store.e].tolist()))
    )
    want = set(nx.single_source_shortest_path_length(g, 11, cutoff=hops))
    vt = em.store.vt[: em.store.n]
    want |= set(np.flatnonzero(vt == vt[11]).tolist())
    assert set(_agent(em, arrive_links=hops).goal_place(goal).tolist()) == want


def test_arrive_links_must_not_be_negative():
    with pytest.raises(ConfigError):
        NavParams(arrive_links=-1)


def _square():
    """Two ways from the start (0) round a 6 x 6 m square to the goal: east then north
    (12 s at 0.5 m/s) and north then east (12 s plus ``extra`` on its first link)."""
    em = ExperienceMap(ExperienceMapParams(exp_initial_em_deg=0.0, exp_link_time="per_link"))
    add = em.store.add_experience
    start = add(0.0, 0.0, 0.0)
    east = [add(x, 0.0, 0.0) for x in (1.5, 3.0, 4.5, 6.0)] + [
        add(6.0, y, np.pi / 2) for y in (1.5, 3.0, 4.5)
    ]
    goal = add(6.0, 6.0, np.pi / 2)
    north = [add(0.0, y, np.pi / 2) for y in (1.5, 3.0, 4.5, 6.0)] + [
        add(x, 6.0, 0.0) for x in (1.5, 3.0, 4.5)
    ]
    for chain, extra in ((east, 0.0), (north, 2.0)):
        ids = [start, *chain, goal]
        for k, (a, b) in enumerate(itertools.pairwise(ids)):
            d = float(np.hypot(*(em.poses[b, :2] - em.poses[a, :2])))
            em.store.add_link(a, b, d, 0.0, 0.0, d / 0.5 + (extra if k == 0 else 0.0))
    em.current_id = start
    return em, goal, east, north


def test_route_hysteresis_keeps_a_route_not_clearly_slower():
    em, goal, east, north = _square()
    plan = plan_route(em, goal)
    assert plan.route is not None and plan.route.ids[1] == east[0]  # 2 s faster
    # the route the robot was following: north, planned while east was slow
    em.store.link[0, 3] += 10.0
    followed = plan_route(em, goal).route
    em.store.link[0, 3] -= 10.0
    assert followed is not None and followed.ids[1] == north[0]
    kept = _agent(em, route_keep_s=5.0).keep_route(followed, plan)
    assert kept.ids == followed.ids  # 2 s faster is not enough to turn onto the other way
    assert kept.times[-1] == pytest.approx(plan.route.times[-1] + 2.0)
    assert _agent(em, route_keep_s=1.0).keep_route(followed, plan).ids == plan.route.ids
    # the robot has driven two links north: the route is rejoined where it is
    em.current_id = north[1]
    here = plan_route(em, goal)
    assert here.route is not None
    kept = _agent(em, route_keep_s=5.0).keep_route(followed, here)
    assert kept.ids == [north[1], *followed.ids[3:]]
    # a link of the followed way is gone: the fresh route at once
    em.current_id = 0
    em.store.remove_link(north[2], north[3])
    fresh = plan_route(em, goal)
    assert fresh.route is not None and fresh.route.ids[1] == east[0]
    assert _agent(em, route_keep_s=100.0).keep_route(followed, fresh).ids == fresh.route.ids


def test_a_route_back_along_links_counts_as_intact_for_route_hysteresis():
    em = ExperienceMap(ExperienceMapParams(exp_initial_em_deg=0.0, exp_link_time="per_link"))
    east = [em.store.add_experience(float(x), 0.0, 0.0) for x in range(6)]  # driven east
    for a, b in itertools.pairwise(east):
        em.store.add_link(a, b, 1.0, 0.0, 0.0, 2.0)
    loop = [em.store.add_experience(5.0, 3.0, np.pi), em.store.add_experience(0.0, 3.0, np.pi)]
    em.store.add_link(east[-1], loop[0], 3.0, 0.0, 0.0, 3.0)
    em.store.add_link(loop[0], loop[1], 5.0, 0.0, 0.0, 4.0)
    em.store.add_link(loop[1], east[0], 3.0, 0.0, 0.0, 3.0)
    _at(em, east[-1])
    k = em.store.link_index(loop[0], loop[1])
    em.store.link[k, 3] += 10.0  # the loop was slow when the route was planned
    followed = plan_route(em, east[0], turn_back=True).route
    em.store.link[k, 3] -= 10.0
    assert followed is not None and not set(followed.ids) & set(loop)  # back along east
    fresh = plan_route(em, east[0], turn_back=True)
    assert fresh.route is not None and loop[0] in fresh.route.ids  # now 2 s faster
    kept = _agent(em, turn_back=True, route_keep_s=5.0).keep_route(followed, fresh)
    assert kept.ids == followed.ids  # its steps back along links are intact
    # read as links the way they were driven, those steps are broken: the fresh route
    off = _agent(em, turn_back=False, route_keep_s=5.0).keep_route(followed, fresh)
    assert off.ids != followed.ids and loop[0] in off.ids


def test_a_short_link_followed_back_counts_as_intact_for_route_hysteresis():
    # east along y = 0 with d learnt 7 cm behind c[0] (linked c[0] -> d); a loop round
    # (north) is the other way to the goal
    em = ExperienceMap(ExperienceMapParams(exp_initial_em_deg=0.0, exp_link_time="per_link"))
    add = em.store.add_experience
    w = [add(x, 0.0, 0.0) for x in (0.0, 0.5, 1.0)]
    d = add(1.43, 0.0, 0.0)
    c = [add(x, 0.0, 0.0) for x in (1.5, 2.0, 2.5, 3.0)]
    for a, b in itertools.pairwise([*w, d]):
        em.store.add_link(a, b, 0.5, 0.0, 0.0, 1.0)
    em.store.add_link(c[0], d, 0.07, np.pi, 0.0, 0.2)
    for a, b in itertools.pairwise(c):
        em.store.add_link(a, b, 0.5, 0.0, 0.0, 1.0)
    up = [add(1.0, 2.0, 0.0), add(3.0, 2.0, -np.pi / 2)]
    em.store.add_link(w[0], up[0], 2.2, 0.0, 0.0, 1.5)
    em.store.add_link(up[0], up[1], 2.0, 0.0, 0.0, 2.0)
    k = em.store.link_index(up[0], up[1])
    em.store.add_link(up[1], c[-1], 2.0, 0.0, 0.0, 1.5)
    _at(em, w[0])
    em.store.link[k, 3] += 10.0  # the loop was slow when the route was planned
    followed = plan_route(em, c[-1], radius_m=0.3, back_step_m=0.1).route
    em.store.link[k, 3] -= 10.0
    assert followed is not None and followed.ids == [*w, d, *c]
    fresh = plan_route(em, c[-1], radius_m=0.3, back_step_m=0.1)
    assert fresh.route is not None and fresh.route.ids == [w[0], *up, c[-1]]  # 5 s against 6.2 s
    kept = _agent(em, back_step_m=0.1, route_keep_s=5.0).keep_route(followed, fresh)
    assert kept.ids == followed.ids  # the step d -> c[0] is intact
    # without the steps the followed route is broken at d: only its end is rejoined
    plain = plan_route(em, c[-1], radius_m=0.3)
    off = _agent(em, route_keep_s=5.0).keep_route(followed, plain)
    assert off.ids == [w[0], *up, c[-1]]


def test_back_step_must_not_be_negative():
    with pytest.raises(ConfigError):
        NavParams(back_step_m=-0.1)
