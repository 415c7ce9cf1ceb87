"""Geometry of routes and roads: arc lengths, wall clearance, bridge drives, grid drives."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ratslam_graph.geometry import wrap_angle
from torchratslam.sim.motion import Route
from torchratslam.sim.world import World

__all__ = ["arc_of", "bridge_poses", "check_clear", "grid_drive", "legs_path"]

Point = tuple[float, float]


def arc_of(route: Route, point: tuple[float, float]) -> float:
    """Arc length of the route point nearest to ``point`` (projected onto the polyline)."""
    a, b = route.points[:-1], route.points[1:]
    ab = b - a
    p = np.asarray(point, np.float64)
    t = np.clip(((p - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-18), 0.0, 1.0)
    d = np.linalg.norm(a + t[:, None] * ab - p, axis=1)
    i = int(np.argmin(d))
    return float(route.s[i] + t[i] * (route.s[i + 1] - route.s[i]))


def check_clear(world: World, route: Route, clearance: float) -> None:
    """Raise if a wall comes closer than ``clearance`` to the route (a builder bug)."""
    p = route.at(np.linspace(0, route.length, 2000, endpoint=False))
    a, b = world.segments[:, :2], world.segments[:, 2:]
    ab = b - a
    t = np.clip(((p[:, None] - a[None]) * ab[None]).sum(-1) / (ab * ab).sum(-1)[None], 0, 1)
    d = np.linalg.norm(p[:, None] - (a[None] + t[..., None] * ab[None]), axis=-1)
    if d.min() < clearance:
        raise AssertionError(f"route passes {d.min():.2f} m from a wall (< {clearance})")


def legs_path(
    legs: Sequence[tuple[Route, Point | None, Point | None]],
    start: np.ndarray,
    end: np.ndarray,
    ds: float,
) -> np.ndarray:
    """``(P, 2)`` dense polyline along the legs' routes from ``start`` to ``end``."""
    pts = []
    for route, a, c in legs:
        sa = arc_of(route, tuple(start) if a is None else a)
        sb = arc_of(route, tuple(end) if c is None else c)
        if route.closed and sb <= sa + 1e-9:
            sb += route.length
        if sb < sa:
            raise AssertionError(f"bridge leg runs backwards along its route ({sa} -> {sb})")
        n = max(2, math.ceil((sb - sa) / (ds / 20)) + 1)
        pts.append(route.at(np.linspace(sa, sb, n)))
    path = np.concatenate(pts)
    path[0], path[-1] = start, end
    return path


def bridge_poses(
    end: np.ndarray, start: np.ndarray, path: np.ndarray, ds: float, max_turn: float
) -> np.ndarray:
    """Poses driving from one session's last pose to the next one's first, along ``path``.

    Steps of at most ``ds`` (equal spacing, at most 5 % longer when the length is not a
    multiple), headings along the direction of travel, so the odometry integrates back
    exactly; where the direction changes by more than ``max_turn`` in one frame (a
    U-turn), the robot first turns on the spot in steps of at most ``max_turn``. The
    last stretch arrives straight along the next session's first heading: the bridge
    ends at ``start - ds * (cos th0, sin th0)``, so the next session's first frame is one
    ordinary step.

    Shape:
        end, start: ``(3,)``; path: ``(P, 2)`` from ``end``'s to ``start``'s position ->
        ``(M, 3)`` (neither end included).
    """
    th0 = float(start[2])
    approach = start[:2] - ds * np.array([math.cos(th0), math.sin(th0)])
    seg = np.hypot(*np.diff(path, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    cut = max(float(s[-1]) - ds, 0.0)
    k = int(np.searchsorted(s, cut, side="right"))
    head = path[:k]
    cut_pt = np.array(
        [np.interp(cut, s, path[:, 0]), np.interp(cut, s, path[:, 1])], dtype=np.float64
    )
    way = np.vstack([head, cut_pt, approach])
    keep = np.r_[True, np.hypot(*np.diff(way, axis=0).T) > 1e-12]
    way = way[keep]
    ws = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(way, axis=0).T))])
    out: list[tuple[float, float, float]] = []
    x, y, th = (float(v) for v in end)

    def turn_to(target: float) -> None:
        nonlocal th
        dth = float(wrap_angle(target - th))
        n_rot = math.ceil(abs(dth) / max_turn - 1e-9) - 1
        for j in range(1, n_rot + 1):
            out.append((x, y, th + dth * j / (n_rot + 1)))
        th = th + dth * n_rot / (n_rot + 1) if n_rot > 0 else th

    if ws[-1] > 1e-12:
        n = max(1, math.ceil(ws[-1] / ds - 0.05))
        u = ws[-1] * np.arange(1, n + 1) / n
        px, py = np.interp(u, ws, way[:, 0]), np.interp(u, ws, way[:, 1])
        px[-1], py[-1] = approach
        for nx, ny in zip(px, py):
            h = math.atan2(ny - y, nx - x)
            turn_to(h)
            x, y, th = float(nx), float(ny), h
            out.append((x, y, th))
    turn_to(th0)  # the next session's first frame makes the last turn
    poses = np.array(out, np.float64).reshape(-1, 3)
    poses[:, 2] = wrap_angle(poses[:, 2])
    return poses


def grid_drive(
    rng: np.random.Generator, n_nodes: int, length_needed: float, pitch: float
) -> list[tuple[int, int]]:
    """Intersections visited by a drive through an ``n_nodes`` x ``n_nodes`` street grid.

    From the south-west corner heading east, at every intersection the car goes
    straight, left or right (a U-turn only at a dead end), choosing the directed street
    it has driven least often (ties at random): every street gets driven in both
    directions, again and again, and the drive closes many loops.
    """
    visits: dict[tuple[tuple[int, int], tuple[int, int]], int] = {}
    node, heading = (0, 0), (1, 0)
    path = [node]
    total = 0.0
    while total < length_needed:
        left, right = (-heading[1], heading[0]), (heading[1], -heading[0])
        options = []
        for d in (heading, left, right):
            nxt = (node[0] + d[0], node[1] + d[1])
            if 0 <= nxt[0] < n_nodes and 0 <= nxt[1] < n_nodes:
                options.append((visits.get((node, nxt), 0), float(rng.random()), d, nxt))
        if not options:  # dead end (cannot happen on a full grid): turn round
            d = (-heading[0], -heading[1])
            options.append((0, 0.0, d, (node[0] + d[0], node[1] + d[1])))
        _, _, heading, nxt = min(options)
        visits[(node, nxt)] = visits.get((node, nxt), 0) + 1
        node = nxt
        path.append(node)
        total += pitch
    return path
