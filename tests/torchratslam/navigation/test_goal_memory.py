"""Goal memory navigation: it works where the pose cells do not fold the floor."""

import itertools

import numpy as np

from torchratslam.experiments.reproduce import edge
from torchratslam.navigation.goal_memory import GoalMemoryAgent
from torchratslam.navigation.robot import MappingRobot
from torchratslam.sim.office.builder import build_office


def test_on_a_matrix_larger_than_the_floor_goal_memory_reaches_the_goal():
    """120 x 120 cells (30 m) on the small floor: no wrap, no collision, so the packet's
    cells are places and goal memory's route leads there."""
    s = edge.QUICK
    robot = MappingRobot(
        edge._config((120, 120), edge.PAPER_MAP), office=build_office(s.plan, seed=0), seed=0
    )
    agent = GoalMemoryAgent(robot)
    robot.explore(s.explore_s)
    goal = agent.mark_goal("C")
    agent.learn()
    assert agent.memory.num_links > 100 and agent.memory.jumps == 0
    trial = agent.navigate(goal)
    assert trial.reached
    assert trial.path_m <= 2.0 * trial.shortest_m
    # its route was a chain of learnt links from the packet's cell to the goal's
    route = trial.first_route
    assert route[-1] == goal.exp
    learnt = set(zip(agent.memory._src, agent.memory._dst, strict=True))
    assert all((a, b) in learnt for a, b in itertools.pairwise(route))
    assert np.hypot(*(trial.path_xy[-1] - np.asarray(goal.xy))) <= agent.params.reach_m
