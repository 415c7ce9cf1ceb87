"""The office world: range scans, obstacles, exploration, determinism."""

import math

import numpy as np
import pytest

from ratslam_graph.navigation.arbitration import choose_path
from torchratslam.sim.laser import Laser
from torchratslam.sim.office.builder import build_office
from torchratslam.sim.office.explore import coverage
from torchratslam.sim.office.motion import Behaviour, MotionState, options
from torchratslam.sim.office.plan import FloorPlan
from torchratslam.sim.office.sensors import SensorParams
from torchratslam.sim.office.sim import OfficeParams, OfficeSim

CORRIDOR = FloorPlan(
    name="corridor", nodes={"a": (0.0, 0.0), "b": (10.0, 0.0)}, edges=(("a", "b", 2.0),),
    start=("a", 0.0),
)  # fmt: skip
EXACT = OfficeParams(
    sensors=SensorParams(laser=Laser(n_beams=91, fov_deg=180.0, max_range=20.0, noise=0.0))
)


def _analytic(x, y, th, angles, box=None):
    """Distance from (x, y) to the corridor's walls x = -1, 11, y = -1, 1 (and a box)."""
    out = []
    for a in (th + angles).tolist():
        c, s = math.cos(a), math.sin(a)
        d = []
        for wall, v, comp in ((11.0, x, c), (-1.0, x, c), (1.0, y, s), (-1.0, y, s)):
            if comp != 0 and (wall - v) / comp > 0:
                d.append((wall - v) / comp)
        if box is not None:  # the box face nearest along +x
            cx, cy, w, h = box
            if c > 0:
                t = (cx - w / 2 - x) / c
                if abs(y + t * s - cy) <= h / 2:
                    d.append(t)
        out.append(min(d))
    return np.array(out)


def test_range_scan_matches_analytic_distances_and_obstacles_block_rays():
    sim = OfficeSim(build_office(CORRIDOR), EXACT, seed=0)
    for _ in range(10):
        s = sim.step(Behaviour.FOLLOW)
    x, y, th = s.pose
    assert y == 0.0 and th == 0.0 and x > 0.5
    angles = EXACT.sensors.laser.beam_angles
    np.testing.assert_allclose(s.scan, _analytic(x, y, th, angles), rtol=1e-5, atol=1e-5)
    box = (6.0, 0.3, 1.0, 0.8)
    i = sim.place_obstacle(*box)
    s2 = sim.step(Behaviour.TURN_AROUND)  # turns in place: the pose stays
    s3 = sim.step(Behaviour.TURN_AROUND)
    assert s3.pose[0] == pytest.approx(x) and s2.blocked is False
    sim.remove_obstacle(i)
    sim2 = OfficeSim(build_office(CORRIDOR), EXACT, seed=0)
    sim2.place_obstacle(*box)
    for _ in range(10):
        s = sim2.step(Behaviour.FOLLOW)
    np.testing.assert_allclose(s.scan, _analytic(x, y, th, angles, box), rtol=1e-5, atol=1e-5)
    assert s.scan[45] == pytest.approx(5.5 - x)


def test_an_obstacle_blocks_the_path_until_it_is_removed():
    sim = OfficeSim(seed=1)
    box = (14.5, 2.0, 0.4, 1.8)  # across the corridor between B and b1
    i = sim.place_obstacle(*box)
    xs, blocked = [], False
    for _ in range(300):
        s = sim.step(Behaviour.FOLLOW)
        xs.append(s.pose[0])
        blocked |= s.blocked
        if s.blocked:
            assert sim.path_blocked(sim.local_paths()[Behaviour.TURN_AROUND])
    assert blocked and max(xs) < 14.5 - 0.2 - 0.5
    sim.remove_obstacle(i)
    sim.reset(1)
    assert not sim.path_blocked(sim.local_paths()[Behaviour.FOLLOW])
    xs = [sim.step(Behaviour.FOLLOW).pose[0] for _ in range(300)]
    assert max(xs) > 16.0


def test_exploration_covers_the_floor_and_stays_on_it():
    sim = OfficeSim(seed=3)
    o = sim.office
    xmin, ymin, xmax, ymax = o.world.bounds
    assert xmax - xmin > 25 and ymax - ymin > 10
    pts = []
    for _ in range(6000):
        s = sim.step(sim.explore())
        pts.append(s.pose[:2])
        if (sim.edge_visits > 0).all():
            break
    xy = np.array(pts)
    assert (sim.edge_visits > 0).all()
    assert o.is_free(xy).all()
    assert coverage(o, xy, 2.5) > 0.85  # room corners lie beyond 2.5 m of the centre lines


def test_junction_behaviours_and_arbitration_pick_the_branch_towards_the_route():
    o = build_office()
    X, Y = o.node("X"), o.node("Y")
    opts = options(o, X, Y)
    names = {b: o.names[w] for b, w in opts.items()}
    assert names == {Behaviour.FOLLOW: "W", Behaviour.LEFT: "F", Behaviour.RIGHT: "C",
                     Behaviour.TURN_AROUND: "X"}  # fmt: skip
    sim = OfficeSim(o, seed=0)
    sim._m = MotionState(u=X, v=Y, s=8.0, heading=0.0)
    paths = sim.local_paths()
    route = np.array([o.nodes[Y], o.nodes[o.node("F")], o.nodes[o.node("f1")]])
    bs = list(paths)
    assert bs[choose_path([paths[b] for b in bs], route).index] is Behaviour.LEFT


def test_runs_are_deterministic_given_a_seed():
    def run(seed):
        sim = OfficeSim(seed=seed)
        return [sim.step(sim.explore()) for _ in range(40)]

    a, b, c = run(5), run(5), run(6)
    for s, t in zip(a, b):
        np.testing.assert_array_equal(s.image, t.image)
        np.testing.assert_array_equal(s.scan, t.scan)
        np.testing.assert_array_equal(s.odometry, t.odometry)
        np.testing.assert_array_equal(s.pose, t.pose)
    assert any(not np.array_equal(s.odometry, t.odometry) for s, t in zip(a, c))
    assert a[-1].image.shape == (8, 12) and a[-1].image.dtype == np.uint8
    assert a[-1].odometry[2] == pytest.approx(1 / 7)
