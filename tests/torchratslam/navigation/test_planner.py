"""Route planning and arbitration in the experience map's frame; frame labels."""

import itertools

import numpy as np

from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.params import ExperienceMapParams
from torchratslam.navigation.labels import LabelState, next_label
from torchratslam.navigation.planner import arbitrate, plan_route, to_map_frame
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
