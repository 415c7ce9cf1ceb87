"""The tour builder reads each tour's data: walls, routes, sessions and spacing as written."""

from __future__ import annotations

import numpy as np
import pytest

from torchratslam.sim.motion import Route
from torchratslam.sim.tour_builder import build_tour
from torchratslam.sim.tour_data import TOUR_SPECS
from torchratslam.sim.tour_spec import Box, LapFraction, Polyline, StreetGrid

SMALL = {
    "virtual_tour": {"frames_per_lap": 40},
    "lab_tour": {"speed": 1.0},
    "irat_like": {"speed": 0.8},
    "loop": {"laps": 1.0, "frames": 120},
    "lab_corridor": {"laps": 1.0, "frames": 120},
    "suburb": {"blocks": 2, "frames": 200},
    "bicocca_like": {"hz": 1.0, "frames": 450},  # 2.3 laps of the figure of eight
    "bovisa_like": {"hz": 0.5},
    "new_college": {"speed": 2.0},
}


def _walls(spec, own):
    """Brute force: the wall segments the spec draws, in order, before scaling."""
    out = []
    for w in spec.world.walls:
        if isinstance(w, Polyline):
            pts = list(w.points) + ([w.points[0]] if w.closed else [])
            out += [(*pts[i], *pts[i + 1]) for i in range(len(pts) - 1)]
        elif isinstance(w, Box):
            x0, x1, y0, y1 = w.cx - w.w / 2, w.cx + w.w / 2, w.cy - w.h / 2, w.cy + w.h / 2
            c = [(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)]
            out += [(*c[i], *c[i + 1]) for i in range(4)]
        else:
            assert isinstance(w, StreetGrid)
            return None  # random houses: checked by the suburb tests
    return np.array(out, np.float64) * spec.world.scale


def _nearest_arc(route: Route, point) -> float:
    """Brute force: the arc length of the densest-sampled route point nearest ``point``."""
    s = np.linspace(0.0, route.length, 200001)
    d = np.linalg.norm(route.at(s) - np.asarray(point), axis=1)
    return float(s[int(np.argmin(d))])


@pytest.mark.parametrize("name", sorted(TOUR_SPECS))
def test_tour_data_round_trips_through_the_builder(name):
    spec = TOUR_SPECS[name]
    tour = build_tour(spec, 1, SMALL[name])
    own = {**spec.options, **SMALL[name]}
    assert tour.name == name and tour.seed == 1
    assert tour.description == spec.description.format(**own)
    assert [s.name for s in tour.sessions] == [s.name for s in spec.sessions]
    assert list(tour.routes) == list(spec.routes)
    assert len(tour.bridges) == len(spec.bridges)
    assert tour.sessions[0].camera.kind == spec.camera.kind
    assert bool(tour.sessions[0].lasers) == spec.lasers
    walls = _walls(spec, own)
    if walls is not None:
        np.testing.assert_allclose(tour.world.segments, walls, rtol=0, atol=1e-12)
    for sspec, sess in zip(spec.sessions, tour.sessions, strict=True):
        route = tour.routes[sspec.route]
        kind = spec.spacing.kind
        if kind == "per_lap":
            ds = route.length / own["frames_per_lap"]
            n = round(sspec.laps * own["frames_per_lap"]) + 1
        elif kind == "laps":
            n = own["frames"]
            ds = own["laps"] * route.length / (n - 1)
        else:
            ds = own["speed"] / own["hz"]
            n = own["frames"] if kind == "frames" else own.get("frames")
        if n is None:
            exact = sspec.laps * route.length / ds
            n = (round(exact) if sspec.count == "round" else int(exact)) + 1
        assert len(sess) == n
        # the first pose lies on the route where the spec starts the session
        if sspec.start is None:
            s0 = 0.0
        elif isinstance(sspec.start, LapFraction):
            s0 = round(own[sspec.start.option] * own["frames_per_lap"]) * ds
        else:
            s0 = _nearest_arc(route, sspec.start)
        np.testing.assert_allclose(sess.poses[0, :2], route.at(np.array([s0]))[0], atol=1e-3)
        # frames ds apart along the route: every pose is where a brute-force walk puts it
        walk = route.at(s0 + ds * np.arange(n))
        np.testing.assert_allclose(sess.poses[:, :2], walk, atol=1e-3)
        np.testing.assert_allclose(np.diff(sess.times), 1.0 / own["hz"])


def test_lab_tour_arc_points_set_the_steps_of_its_turns():
    from torchratslam.sim import open_sim

    def max_turn_deg(options):
        s = open_sim(f"sim:lab_tour/session1?speed=0.03&{options}")
        th = np.unwrap(np.asarray(s.groundtruth(), np.float64)[:, 3])
        return float(np.degrees(np.abs(np.diff(th))).max())

    # a 0.6 m corner at 0.03 m a frame turns 2.9 degrees a frame; drawn through 24 points
    # it turns in 90 / 23 = 3.9-degree steps instead, through 96 in 0.95-degree ones
    assert max_turn_deg("arc_points=24") == pytest.approx(90 / 23, abs=0.1)
    assert max_turn_deg("arc_points=96") < 3.0
