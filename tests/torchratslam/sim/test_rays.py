"""Compiled ray casting against the array path: distances, segments and positions along
them bit for bit, on random and degenerate walls and on the Rawseeds stand-ins' scans."""

from __future__ import annotations

import importlib
import math
from dataclasses import replace

import numpy as np
import pytest

from torchratslam.experiments.mbaram_tour import sim_session
from torchratslam.sim.laser import Laser

render = importlib.import_module("torchratslam.sim.render")  # the module, not the function


def cast_both(world, origin, angles, monkeypatch):
    out = []
    for compiled in (True, False):
        monkeypatch.setattr(render, "COMPILED", compiled)
        out.append(render.cast_rays(world, origin, angles))
    return out


def same(a, b):
    for x, y in zip(a, b):
        assert x.dtype == y.dtype and x.shape == y.shape
        assert np.array_equal(x, y, equal_nan=True)


@pytest.fixture(scope="module")
def base_world():
    session = sim_session(
        "sim:bicocca_like?hz=10&speed=1&frames=20", laps=1, seed=2, moving=0, moved=0
    )
    return session.world


def test_random_walls_cast_the_same_bit_for_bit(base_world, monkeypatch):
    rng = np.random.default_rng(21)
    hits = misses = 0
    for _ in range(30):
        segs = rng.uniform(-10.0, 10.0, (int(rng.integers(1, 60)), 4))
        world = replace(base_world, segments=segs, heights=np.ones(len(segs)))
        angles = rng.uniform(-math.pi, math.pi, int(rng.integers(1, 700)))
        origin = (float(rng.uniform(-5, 5)), float(rng.uniform(-5, 5)))
        a, b = cast_both(world, origin, angles, monkeypatch)
        same(a, b)
        hits += int((a[1] >= 0).sum())
        misses += int((a[1] == -1).sum())
    assert hits > 1000 and misses > 100  # both kinds of ray were cast


def test_degenerate_rays_cast_the_same(base_world, monkeypatch):
    # rays parallel to walls, through wall ends, from a point on a wall, equal hits at
    # one distance (two walls sharing an end), and no hit at all
    segs = np.array(
        [
            [1.0, -1.0, 1.0, 1.0],
            [1.0, 1.0, 3.0, 1.0],  # shares (1, 1) with the first
            [0.0, 0.0, 2.0, 0.0],  # the origin lies on it
            [-2.0, 0.0, -4.0, 0.0],  # along the ray at pi
            [1.0, 1.0, 1.0, 1.0],  # zero length
        ]
    )
    world = replace(base_world, segments=segs, heights=np.ones(len(segs)))
    angles = np.array([0.0, math.pi / 4, math.pi / 2, math.pi, -math.pi / 4, 3.0, -2.0])
    for origin in ((0.0, 0.0), (0.5, 0.0), (1.0, 0.0), (5.0, 5.0)):
        a, b = cast_both(world, origin, angles, monkeypatch)
        same(a, b)


def test_stand_in_scans_are_the_same(monkeypatch):
    session = sim_session(
        "sim:bovisa_like?hz=10&speed=1.5&frames=40", laps=1, seed=4, moving=6, moved=0
    )
    laser = Laser()
    for k in range(0, 40, 7):
        world = session.world_at(k)
        x, y, th = (float(v) for v in session.poses[k])
        a, b = cast_both(world, (x, y), th + laser.beam_angles, monkeypatch)
        same(a, b)
        assert (a[1] >= 0).sum() > 100  # the beams hit walls
    monkeypatch.setattr(render, "COMPILED", True)
    fast = [session.scans(k) for k in range(0, 40, 13)]
    monkeypatch.setattr(render, "COMPILED", False)
    slow = [session.scans(k) for k in range(0, 40, 13)]
    for f, s in zip(fast, slow):
        assert f.keys() == s.keys()
        for c in f:
            assert np.array_equal(f[c], s[c])
