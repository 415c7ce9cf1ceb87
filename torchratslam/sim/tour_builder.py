"""The one tour builder: reads a :class:`~torchratslam.sim.tour_spec.TourSpec` and makes
the :class:`~torchratslam.sim.session.Tour` (world, routes, sessions, obstacles, bridges).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from ratslam_graph.errors import unknown_name_message
from ratslam_graph.geometry import wrap_angle
from torchratslam.errors import InputError
from torchratslam.sim.laser import Laser
from torchratslam.sim.motion import OdometryNoise, Route, odometry_from_poses, poses_along
from torchratslam.sim.render import Camera
from torchratslam.sim.roads import arc_of, bridge_poses, check_clear, grid_drive, legs_path
from torchratslam.sim.session import Obstacles, Session, Tour
from torchratslam.sim.tour_spec import (
    Box,
    CameraSpec,
    EllipseRoute,
    GridDriveRoute,
    LapFraction,
    NoiseSpec,
    PolygonRoute,
    Polyline,
    RouteSpec,
    StreetGrid,
    TourSpec,
    WorldSpec,
    resolve,
)
from torchratslam.sim.world import World, WorldBuilder, make_texture

__all__ = ["CommonOptions", "build_tour", "split_options"]

Point = tuple[float, float]


def split_options(spec: TourSpec, options: Mapping[str, Any]) -> tuple[CommonOptions, dict]:
    """The common options and the tour's own (defaults filled in), checked.

    Raises:
        InputError: an unknown option or a bad common option value.
    """
    common = {f for f in CommonOptions.__dataclass_fields__}
    specific = set(spec.options)
    bad = set(options) - common - specific
    if bad:
        key = sorted(bad)[0]
        raise InputError(
            unknown_name_message(f"option of tour {spec.name!r}", key, common | specific)
        )
    o = CommonOptions(**{k: v for k, v in options.items() if k in common})
    for key in ("fog", "pixel_noise", "illumination", "moved_obstacles", "moving_obstacles"):
        v = getattr(o, key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or v < 0:
            raise InputError(f"tour option {key}={v!r} must be a number >= 0")
    if o.illumination_mode not in ("auto", "session", "lap", "drift"):
        raise InputError(f"illumination_mode {o.illumination_mode!r}: use session, lap or drift")
    return o, {**spec.options, **{k: v for k, v in options.items() if k in specific}}


def build_tour(spec: TourSpec, seed: int, options: Mapping[str, Any]) -> Tour:
    """The tour ``spec`` describes, for this seed and these options.

    Args:
        spec: the tour.
        seed: seed of the textures, odometry noise and obstacles.
        options: common options and the tour's own (:mod:`torchratslam.sim.tours`).

    Raises:
        InputError: an unknown option or an invalid option value.
    """
    o, own = split_options(spec, options)
    return _assemble(spec.name, _read(spec, seed, o, own), o, seed, dict(options))


def _positive(spec: TourSpec, own: Mapping[str, Any]) -> None:
    for key, offset in spec.positive:
        v = own[key]
        if v is None:
            continue
        v = v - offset if offset else v
        if not isinstance(v, (int, float)) or not v > 0:
            raise InputError(f"tour option {key} is too small or not a number; give a larger value")


def _check_fraction(f: LapFraction, own: Mapping[str, Any]) -> None:
    v = own[f.option]
    if isinstance(v, bool) or not f.low < float(v) < f.high:
        raise InputError(
            f"tour option {f.option}={v!r}: the session starts in the part of the route the "
            f"previous one leaves unmapped, between {f.low:g} and {f.high:g} lap (exclusive; "
            f"default {f.default:g})"
        )


def _world(spec: WorldSpec, seed: int, name: str, own: Mapping[str, Any]) -> World:
    wb = WorldBuilder(seed=seed, wall_height=spec.wall_height, style=spec.style)
    for w in spec.walls:
        if isinstance(w, Polyline):
            wb.polyline(list(w.points), closed=w.closed, height=w.height, scale=w.scale)
        elif isinstance(w, Box):
            wb.box(w.cx, w.cy, w.w, w.h, height=w.height)
        else:
            _street_grid(wb, w, seed, own)
    world = wb.build(name=name, floor=spec.floor, ceiling=spec.ceiling)
    return world.scaled(spec.scale) if spec.scale != 1.0 else world


def _street_grid(wb: WorldBuilder, grid: StreetGrid, seed: int, own: Mapping[str, Any]) -> None:
    """Houses round every block, then the city's outer wall past the outer streets."""
    blocks, block_size, street_width = own["blocks"], own["block_size"], own["street_width"]
    pitch = block_size + street_width
    g = np.random.default_rng([seed, grid.seed_key])
    half = block_size / 2
    for bx in range(int(blocks)):
        for by in range(int(blocks)):
            cx, cy = (bx + 0.5) * pitch, (by + 0.5) * pitch
            corners = [(cx - half, cy - half), (cx + half, cy - half)]
            corners += [(cx + half, cy + half), (cx - half, cy + half)]
            for i in range(4):
                p, q = np.array(corners[i]), np.array(corners[(i + 1) % 4])
                cuts = np.sort(g.uniform(*grid.cut_range, int(g.integers(*grid.houses))))
                ts = np.r_[0.0, cuts, 1.0]
                for a, b in itertools.pairwise(ts):
                    wb.segment(
                        tuple(p + a * (q - p)),
                        tuple(p + b * (q - p)),
                        height=float(g.uniform(*grid.house_heights)),
                    )
    edge = street_width / 2 + grid.edge_margin
    far = int(blocks) * pitch
    wb.polyline(
        [(-edge, -edge), (far + edge, -edge), (far + edge, far + edge), (-edge, far + edge)],
        height=grid.edge_height,
    )


def _route(r: RouteSpec, seed: int, own: Mapping[str, Any], n: int = 0, ds: float = 0.0) -> Route:
    if isinstance(r, EllipseRoute):
        return Route.ellipse(r.a, r.b, start_deg=r.start_deg)
    if isinstance(r, PolygonRoute):
        return Route.polygon(
            list(r.corners),
            radius=resolve(r.radius, own),
            n_arc=max(2, round(resolve(r.arc_points, own))),
            closed=r.closed,
        )
    pitch = own["block_size"] + own["street_width"]
    n_nodes = int(own["blocks"]) + 1
    rng = np.random.default_rng([seed, r.seed_key])
    drive = grid_drive(rng, n_nodes, (n - 1) * ds + 2 * pitch, pitch)
    corners = [(i * pitch, j * pitch) for i, j in drive]
    return Route.polygon(corners, radius=resolve(r.radius, own), closed=False)


def _read(spec: TourSpec, seed: int, o: CommonOptions, own: dict[str, Any]) -> _Build:
    """The spec read for one seed and option values."""
    _positive(spec, own)
    for s in spec.sessions:
        if isinstance(s.start, LapFraction):
            _check_fraction(s.start, own)
    world = _world(spec.world, seed, spec.name, own)
    kind = spec.spacing.kind
    hz = own["hz"]
    routes: dict[str, Route] = {}
    plan: list[tuple[str, Route, float, int, float, float]] = []
    for s in spec.sessions:
        if s.route not in routes:
            r = spec.routes[s.route]
            if isinstance(r, GridDriveRoute):  # a drive as long as the session
                routes[s.route] = _route(r, seed, own, int(own["frames"]), own["speed"] / hz)
            else:
                routes[s.route] = _route(r, seed, own)
        route = routes[s.route]
        if kind == "per_lap":
            fpl = own["frames_per_lap"]
            ds = route.length / fpl
            n = round(s.laps * fpl) + 1
        elif kind == "laps":
            laps, frames = own["laps"], own["frames"]
            sp = spec.spacing
            n = int(frames) if frames is not None else round(laps * sp.frames_per / sp.laps_per) + 1
            ds = laps * route.length / max(n - 1, 1)
        elif kind == "frames":
            ds = own["speed"] / hz
            n = int(own["frames"])
        else:
            ds = own["speed"] / hz
            if own.get("frames") is not None:  # a drive of this many frames, lapping on
                n = int(own["frames"])
            else:
                n = (round if s.count == "round" else int)(s.laps * route.length / ds) + 1
        if isinstance(s.start, LapFraction):
            start = round(float(own[s.start.option]) * own["frames_per_lap"])
            if not plan[-1][3] - 1 < start < s.start.high * own["frames_per_lap"]:
                raise InputError(
                    f"tour option {s.start.option}={own[s.start.option]!r} rounds to frame "
                    f"{start} of {own['frames_per_lap']}, outside the part of the route the "
                    "previous session leaves unmapped; move it away from its ends"
                )
            s0 = start * ds
        elif s.start is None:
            s0 = 0.0
        else:
            s0 = arc_of(route, s.start)
        plan.append((s.name, route, s0, n, ds, hz))
    for name, r in spec.routes.items():
        if name not in routes:
            routes[name] = _route(r, seed, own)
    routes = {name: routes[name] for name in spec.routes}
    clearance = resolve(spec.clearance, own)
    for rt in routes.values():
        check_clear(world, rt, clearance)
    everywhere = {**routes, **{k: _route(r, seed, own) for k, r in spec.bridge_routes.items()}}
    return _Build(
        world=world,
        routes=routes,
        plan=plan,
        camera=_camera(o, spec.camera),
        noise=_noise(o, spec.noise),
        lasers=_lasers(o, spec.lasers),
        main_route=routes[spec.main_route],
        obstacle_size=resolve(spec.obstacle_size, own),
        obstacle_offset=resolve(spec.obstacle_offset, own),
        pedestrian_offset=resolve(spec.pedestrian_offset, own),
        obstacle_height=spec.obstacle_height,
        scale=spec.scale,
        description=spec.description.format(**own),
        bridges=[[(everywhere[g.route], g.start, g.stop) for g in legs] for legs in spec.bridges],
        clearance=clearance,
    )


@dataclass
class CommonOptions:
    """Options common to every tour (see :mod:`torchratslam.sim.tours`)."""

    camera: str | None = None
    width: int | None = None
    height: int | None = None
    fov_deg: float | None = None
    cam_height: float | None = None
    fog: float = 0.0
    pixel_noise: float = 0.0
    lasers: bool | None = None
    laser_beams: int = 682
    laser_fov_deg: float = 240.0
    laser_max_range: float = 30.0
    laser_noise: float = 0.01
    scale_error: float | None = None
    rot_scale_error: float | None = None
    heading_bias: float | None = None
    trans_noise: float | None = None
    rot_noise: float | None = None
    exact_odometry: bool = False
    illumination: float = 0.0
    illumination_mode: str = "auto"
    moved_obstacles: int = 0
    moving_obstacles: int = 0


def _camera(o: CommonOptions, spec: CameraSpec) -> Camera:
    kw: dict[str, Any] = {
        "kind": spec.kind,
        "width": spec.width,
        "height": spec.height,
        "cam_height": spec.cam_height,
    }
    if spec.fov_deg is not None:
        kw["fov_deg"] = spec.fov_deg
    if o.camera is not None and o.camera != kw["kind"]:
        kw["kind"] = o.camera
        kw.update(width=256, height=64) if o.camera == "panoramic" else kw.update(
            width=128, height=96
        )
    for k in ("width", "height", "fov_deg", "cam_height"):
        if getattr(o, k) is not None:
            kw[k] = getattr(o, k)
    return Camera(fog=o.fog, **kw)


def _noise(o: CommonOptions, spec: NoiseSpec) -> OdometryNoise | None:
    if o.exact_odometry:
        return None
    defaults = {f.name: getattr(spec, f.name) for f in fields(spec)}
    kw = {k: (getattr(o, k) if getattr(o, k) is not None else v) for k, v in defaults.items()}
    return OdometryNoise(**kw)


def _lasers(o: CommonOptions, default: bool) -> dict[str, Laser]:
    on = default if o.lasers is None else bool(o.lasers)
    if not on:
        return {}
    kw: dict[str, Any] = dict(
        n_beams=int(o.laser_beams),
        fov_deg=o.laser_fov_deg,
        max_range=o.laser_max_range,
        noise=o.laser_noise,
    )
    return {"laser_front": Laser(**kw), "laser_rear": Laser(mount_angle_deg=180.0, **kw)}


def _box_shape(sizes: np.ndarray) -> np.ndarray:
    """``(4K, 4)`` faces of squares of side ``sizes`` centred at the origin."""
    h = np.asarray(sizes, np.float64)[:, None] / 2
    c = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float64)
    p = (c[None] * h[..., None]).reshape(-1, 4, 2)
    q = np.roll(p, -1, axis=1)
    return np.concatenate([p, q], -1).reshape(-1, 4)


def _normals(route: Route, s: np.ndarray) -> np.ndarray:
    d = route.at(s + 0.01) - route.at(s - 0.01)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.stack([-d[:, 1], d[:, 0]], -1)


@dataclass
class _Build:
    """A tour spec read for one seed and option values, before the sessions are made."""

    world: World
    routes: dict[str, Route]
    # per session: (name, route, start arc length, n frames, spacing ds, hz)
    plan: list[tuple[str, Route, float, int, float, float]]
    camera: Camera
    noise: OdometryNoise | None
    lasers: dict[str, Laser]
    main_route: Route
    obstacle_size: float = 1.0
    obstacle_offset: float = 2.0
    pedestrian_offset: float = 0.7
    obstacle_height: float = 1.8
    description: str = ""
    scale: float = 1.0
    # per gap between sessions i and i+1: legs (route, from, to) driven forward along
    # the route; None = the previous session's end / the next session's start
    bridges: list[list[tuple[Route, Point | None, Point | None]]] = field(default_factory=list)
    clearance: float = 0.1


def _assemble(name: str, b: _Build, o: CommonOptions, seed: int, options: dict) -> Tour:
    rng_obst = np.random.default_rng([seed, 99])
    n_moved, n_people = int(o.moved_obstacles), int(o.moving_obstacles)
    k_obst = n_moved + n_people
    obst_world = b.world
    shape: np.ndarray | None = None
    if k_obst:
        sizes = np.r_[np.full(n_moved, b.obstacle_size), np.full(n_people, 0.4 * b.scale)]
        shape = _box_shape(sizes)
        builder = WorldBuilder(seed=seed + 12345)
        tex, segs, heights, kinds = [], [], [], []
        for i, (x0, y0, x1, y1) in enumerate(shape):
            ln = math.hypot(x1 - x0, y1 - y0) / b.scale
            tex.append(make_texture(builder.rng, ln, kind="noise" if i // 4 >= n_moved else None))
            segs.append((x0, y0, x1, y1))
            h = b.obstacle_height if i // 4 < n_moved else 1.7 * b.scale
            heights.append(h)
            kinds.append("obstacle")
        cols = np.array([t.shape[1] for t in tex])
        extra = World(
            segments=np.array(segs) + 1e4,
            heights=np.array(heights),
            tex_start=np.concatenate([[0], np.cumsum(cols)[:-1]]).astype(np.int64),
            tex_cols=cols.astype(np.int64),
            atlas=np.concatenate(tex, axis=1),
            kinds=tuple(kinds),
            tex_res=b.world.tex_res,
        )
        obst_world = b.world.extended(extra)
    # moved boxes: one layout per (session, lap); pedestrians: walk along the main route
    layouts: dict[tuple[int, int], np.ndarray] = {}
    peds: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    if n_people:
        r = b.main_route
        peds = (
            rng_obst.uniform(0, r.length, n_people),
            rng_obst.uniform(0.3, 1.0, n_people) * b.scale,
            rng_obst.choice([-1.0, 1.0], n_people),
        )
    sessions = []
    t_global = 0.0
    n_sessions = len(b.plan)
    mode = o.illumination_mode
    if mode == "auto":
        mode = "session" if n_sessions > 1 else "lap"
    light_rng = np.random.default_rng([seed, 77])
    session_gain = 1 + o.illumination * light_rng.choice([-1, 1], 64) * light_rng.uniform(
        0.5, 1, 64
    )
    session_gain[0] = 1.0
    all_poses = [poses_along(route, s0 + ds * np.arange(n)) for _, route, s0, n, ds, _ in b.plan]
    path_xy = np.concatenate(all_poses)[:, :2]
    for i, (sname, route, s0, n, ds, hz) in enumerate(b.plan):
        s = s0 + ds * np.arange(n)
        poses = all_poses[i]
        dt = 1.0 / hz
        times = np.arange(n) * dt
        odo = odometry_from_poses(poses, dt, b.noise, np.random.default_rng([seed, 1000 + i]))
        laps = np.floor((s - s0) / route.length + 1e-9).astype(np.int64)
        # a final frame that closes the last lap exactly belongs to that lap
        laps = np.minimum(laps, max(0, math.ceil((s[-1] - s0) / route.length - 1e-9) - 1))
        if mode == "session":
            gain = np.full(n, session_gain[i])
        elif mode == "lap":
            gain = session_gain[laps % 64]
        else:
            gain = 1 + o.illumination * np.sin(2 * np.pi * times / max(times[-1], dt))
        obstacles = None
        if k_obst:
            centres = np.full((n, k_obst, 2), 1e4)
            if n_moved:
                for lap in np.unique(laps):
                    key = (i, int(lap))
                    if key not in layouts:
                        g = np.random.default_rng([seed, 55, i, int(lap)])
                        layouts[key] = _place_boxes(g, b, n_moved, path_xy)
                    centres[laps == lap, :n_moved] = layouts[key]
            if n_people:
                assert peds is not None
                start, speed, side = peds
                m = b.main_route
                tt = (t_global + times)[:, None]
                sp = start[None, :] + speed[None, :] * side[None, :] * tt
                pos = m.at(sp.ravel()).reshape(n, n_people, 2)
                nrm = _normals(m, sp.ravel()).reshape(n, n_people, 2)
                ped = pos + nrm * (side * b.pedestrian_offset)[None, :, None]
                # a pedestrian about to be run into steps out of the way (hidden)
                close = np.linalg.norm(ped - poses[:, None, :2], axis=-1) < 0.45 * b.scale
                ped[close] = 1e4
                centres[:, n_moved:] = ped
            assert shape is not None
            obstacles = Obstacles(shape=shape, centres=centres, world=obst_world, n_moved=n_moved)
        t_global += n * dt
        sessions.append(
            Session(
                name=sname,
                tour=name,
                world=b.world,
                poses=poses,
                times=times,
                odometry=odo,
                camera=b.camera,
                lasers=b.lasers,
                laps=laps,
                gain=gain,
                pixel_noise=float(o.pixel_noise),
                keys=np.column_stack([np.full(n, seed), np.full(n, i + 1), np.arange(n)]).astype(
                    np.int64
                ),
                obstacles=obstacles,
                info={"seed": seed, "options": dict(options)},
            )
        )
    bridges = []
    if b.bridges:
        max_turn = max(
            float(np.abs(wrap_angle(np.diff(ses.poses[:, 2]))).max(initial=0.0)) for ses in sessions
        )
        max_turn = max(1.5 * max_turn, 0.05)  # never turns much faster than the sessions
        for i, legs in enumerate(b.bridges):
            prev, nxt = sessions[i], sessions[i + 1]
            path = legs_path(legs, prev.poses[-1, :2], nxt.poses[0, :2], b.plan[i][4])
            check_clear(b.world, Route(path, closed=False), b.clearance)
            bridges.append(bridge_poses(prev.poses[-1], nxt.poses[0], path, b.plan[i][4], max_turn))
    return Tour(
        name=name,
        world=b.world,
        sessions=sessions,
        routes=b.routes,
        description=b.description,
        options={"seed": seed, **options},
        bridges=bridges,
        noise=b.noise,
        seed=seed,
    )


def _place_boxes(g: np.random.Generator, b: _Build, n: int, path_xy: np.ndarray) -> np.ndarray:
    """``(n, 2)`` centres beside the main route, clear of every session's path."""
    m = b.main_route
    cand = 40 * n
    sm = g.uniform(0, m.length, cand)
    side = g.choice([-1.0, 1.0], cand)
    xy = m.at(sm) + _normals(m, sm) * (side * b.obstacle_offset)[:, None]
    sub = path_xy[:: max(1, len(path_xy) // 4000)]
    clear = np.ones(cand, bool)
    for a in range(0, cand, 256):  # chunks bound the (candidates x path points) memory
        d = np.linalg.norm(xy[a : a + 256, None] - sub[None], axis=-1).min(1)
        clear[a : a + 256] = d > 0.75 * b.obstacle_size + 0.3 * b.scale
    ok = xy[clear]
    if len(ok) < n:  # pragma: no cover - the tours leave plenty of room
        raise InputError(f"no room for {n} moved obstacles in tour {b.world.name!r}")
    return ok[:n]
