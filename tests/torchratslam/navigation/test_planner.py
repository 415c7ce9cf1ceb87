"""Route planning and arbitration in the experience map's frame; frame labels."""

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
    plan = plan_route(em, 0)
    assert plan.route is not None and plan.route.ids == [5, 4, 3, 2, 1, 0]
    assert plan.tmap.times[0] > plan.tmap.times[5]


def test_a_forced_turn_keeps_the_label_the_robot_moved_with():
    s = next_label(LabelState(), to_node_m=5.0, held=1, event=-1, blocked=False, moved_m=0.1)
    assert s.label == Behaviour.FOLLOW
    s = next_label(s, to_node_m=0.5, held=1, event=-1, blocked=False, moved_m=0.1)
    assert s.label == Behaviour.LEFT
    s = next_label(LabelState(), to_node_m=5.0, held=1, event=3, blocked=True, moved_m=0.0)
    assert s.label == Behaviour.FOLLOW
    s = next_label(LabelState(), to_node_m=5.0, held=0, event=3, blocked=False, moved_m=0.0)
    assert s.label == Behaviour.TURN_AROUND
