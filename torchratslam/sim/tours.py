"""Tours: worlds, routes and sessions reproducing the papers' experiments.

* ``virtual_tour`` (multisession paper, Fig. 5): an ellipse (60.7 m lap) in a hall;
  256x64 panoramic, 1 Hz, 150 frames per lap. session1: a 3/4 lap (113 frames);
  session2: 2.9 laps from an unmapped point 0.873 lap round, reaching session1's
  start after 19 frames and replaying its frames from there (436 frames).
* ``lab_tour`` (Fig. 6): two rectangles forming a digital "8"; 640x480 forward camera
  (50 degrees), 1 Hz, 0.25 m/s. session1: two CCW laps of the small rectangle (153);
  session2: 1.9 CCW laps of the large one from an unmapped point (206).
* ``irat_like`` (Fig. 7): a 2 x 2 block road network at iRat scale (2.4 x 1.6 m);
  160x96 forward camera (75 degrees), 10 Hz, 0.2 m/s. session1-4: one CCW lap around
  each block (194 each); session5: in along an unmapped spur, then the outer loop,
  which joins all four (433).
* ``loop``: a corridor loop (38.3 m lap), 256x64 panoramic, 5 Hz, lasers on.
  session1: 6 laps, 1781 frames.
* ``suburb`` (issue 16, St Lucia-like): an 8 x 8 block street grid (40 m blocks, 12 m
  streets, buildings of varied heights and facades); a car with a 128x64 forward camera
  (60 degrees, 1.5 m up) at 10 m/s, 10 Hz; 20000 frames driving most streets several
  times in both directions. Options ``blocks``, ``block_size``, ``street_width``,
  ``frames``, ``speed``, ``hz``.

Every tour takes ``seed`` (textures, odometry noise, obstacles) and these options:

* camera: ``camera`` ("panoramic" or "forward"), ``width``, ``height``, ``fov_deg``,
  ``cam_height``, ``fog`` (m, 0 = off), ``pixel_noise`` (grey levels);
* lasers: ``lasers`` (bool), ``laser_beams`` (682), ``laser_fov_deg`` (240),
  ``laser_max_range`` (30 m), ``laser_noise`` (0.01 m); front and rear scanners;
* odometry: ``scale_error``, ``rot_scale_error``, ``heading_bias`` (rad/s),
  ``trans_noise`` (m/s), ``rot_noise`` (rad/s), or ``exact_odometry=True``;
* motion: ``hz``; ``speed`` (lab_tour, irat_like), ``frames_per_lap`` and
  ``session2_start`` (virtual_tour: where session 2 starts, in laps from session 1's
  start, inside the quarter session 1 leaves unmapped; default 0.873), ``laps`` and
  ``frames`` (loop);
* environment changes: ``illumination`` (relative gain amplitude, 0 = off) with
  ``illumination_mode`` ("session": one gain per session, the first at 1; "lap": one
  per lap; "drift": a slow sinusoid over each session), ``moved_obstacles`` (N boxes
  beside the path that move between laps and sessions), ``moving_obstacles`` (N
  pedestrians walking along the path, seen by camera and lasers).
"""

from __future__ import annotations

import inspect
import itertools
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ratslam_graph.errors import InputError, unknown_name_message
from ratslam_graph.geometry import dead_reckoning, wrap_angle
from torchratslam.messages import Frame
from torchratslam.sim.laser import Laser, scan
from torchratslam.sim.motion import (
    OdometryNoise,
    Route,
    odometry_from_poses,
    poses_along,
)
from torchratslam.sim.render import Camera, render
from torchratslam.sim.world import World, WorldBuilder, make_texture

__all__ = ["TOURS", "TOUR_PRESETS", "Obstacles", "Session", "Tour", "get_tour"]

Point = tuple[float, float]


@dataclass(frozen=True)
class Obstacles:
    """Boxes whose positions change from frame to frame (appended to the world).

    Attributes:
        shape: ``(4K, 4)`` box faces relative to their box centre (m).
        centres: ``(T, K, 2)`` box centres per frame (far away = absent).
        world: the world with the boxes' faces appended (textures included); its last
            ``4K`` segments are replaced per frame.
        n_moved: the first ``n_moved`` boxes are moved obstacles, the rest pedestrians.
    """

    shape: np.ndarray
    centres: np.ndarray
    world: World
    n_moved: int = 0

    def world_at(self, k: int) -> World:
        n = len(self.shape)
        seg = self.world.segments.copy()
        c = np.repeat(self.centres[k], 4, axis=0)
        seg[-n:] = self.shape + np.tile(c, 2)
        return replace(self.world, segments=seg)


def _obstacles(session: Session) -> Obstacles:
    """The session's obstacles (the caller knows it has some)."""
    assert session.obstacles is not None
    return session.obstacles


@dataclass
class Session:
    """One continuous recording: ground-truth poses, odometry, and lazily rendered frames.

    Attributes:
        name: "session1", "session2", ... (or "full").
        tour: the tour's name.
        world: the static world (without moving obstacles).
        poses: ``(T, 3)`` ground-truth ``[x, y, th]``.
        times: ``(T,)`` timestamps (s).
        odometry: ``(T, 3)`` ``[vtrans, vrot, dt]`` of the interval ending at each frame
            (noise included; ``dt = 0`` on the first frame and after a kidnap).
        camera: the camera.
        lasers: scanners by channel name ("laser_front", "laser_rear"); empty when off.
        laps: ``(T,)`` lap number of each frame (0-based, from the session's start).
        gain: ``(T,)`` illumination gain per frame.
        pixel_noise: std of the pixel noise (grey levels).
        keys: ``(T, 3)`` ``[seed, session number, frame]`` seeding each frame's noise, so
            a frame renders identically wherever it appears (e.g. in ``Tour.full()``).
        obstacles: moving boxes, or None.
        info: provenance (seed, tour options) written to a dataset's meta.json.
    """

    name: str
    tour: str
    world: World
    poses: np.ndarray
    times: np.ndarray
    odometry: np.ndarray
    camera: Camera
    lasers: dict[str, Laser] = field(default_factory=dict)
    # None: filled in by __post_init__ (so typed as arrays)
    laps: np.ndarray = None  # type: ignore[assignment]
    gain: np.ndarray = None  # type: ignore[assignment]
    pixel_noise: float = 0.0
    keys: np.ndarray = None  # type: ignore[assignment]
    obstacles: Obstacles | None = None
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = len(self.poses)
        if self.laps is None:
            self.laps = np.zeros(t, np.int64)
        if self.gain is None:
            self.gain = np.ones(t)
        if self.keys is None:
            self.keys = np.column_stack([np.zeros(t), np.ones(t), np.arange(t)]).astype(np.int64)

    def __len__(self) -> int:
        return len(self.poses)

    def __repr__(self) -> str:
        return f"Session({self.tour}/{self.name}, {len(self)} frames)"

    def world_at(self, k: int) -> World:
        """The world at frame ``k`` (with the obstacles where they are then)."""
        return self.world if self.obstacles is None else self.obstacles.world_at(k)

    def render(self, k: int) -> np.ndarray:
        """The ``(H, W)`` uint8 image of frame ``k``."""
        rng = np.random.default_rng(self.keys[k]) if self.pixel_noise > 0 else None
        return render(
            self.world_at(k),
            self.poses[k],
            self.camera,
            gain=float(self.gain[k]),
            pixel_noise=self.pixel_noise,
            rng=rng,
        )

    def scans(self, k: int) -> dict[str, np.ndarray]:
        """Laser ranges of frame ``k`` by channel (empty when the lasers are off)."""
        if not self.lasers:
            return {}
        world = self.world_at(k)
        rng = np.random.default_rng([*self.keys[k], 7])
        return {name: scan(world, self.poses[k], laser, rng) for name, laser in self.lasers.items()}

    def frame(self, k: int) -> Frame:
        """Frame ``k`` (rendered now)."""
        if not -len(self) <= k < len(self):
            raise InputError(f"frame {k} is out of range for {self!r}")
        k = k % len(self)
        vt, vr, dt = self.odometry[k]
        return Frame(
            index=k,
            t=float(self.times[k]),
            image=self.render(k),
            vtrans=float(vt),
            vrot=float(vr),
            dt=float(dt),
            pose=(float(self.poses[k, 0]), float(self.poses[k, 1]), float(self.poses[k, 2])),
            scans=self.scans(k),
            meta={
                "tour": self.tour,
                "session": (
                    f"session{self.keys[k, 1]}"
                    if self.keys[k, 1] < _BRIDGE_KEY
                    else f"bridge{self.keys[k, 1] - _BRIDGE_KEY}"
                ),
                "lap": int(self.laps[k]),
            },
        )

    def frames(self, start: int = 0, stop: int | None = None) -> Iterator[Frame]:
        """Iterate over the frames ``start..stop`` (rendered one at a time)."""
        for k in range(start, len(self) if stop is None else min(stop, len(self))):
            yield self.frame(k)

    def __iter__(self) -> Iterator[Frame]:
        return self.frames()

    def groundtruth(self) -> np.ndarray:
        """``(T, 4)`` ``[t, x, y, th]``."""
        return np.column_stack([self.times, self.poses])

    def dead_reckoning(self) -> np.ndarray:
        """``(T, 3)`` poses from integrating the (noisy) odometry from the true start.

        After a kidnap (``dt = 0`` inside the sequence) integration restarts at the
        true pose, as if the robot had been told where it was put down.
        """
        out = np.empty_like(self.poses)
        starts = [0, *np.flatnonzero(self.odometry[1:, 2] == 0) + 1, len(self)]
        for a, b in itertools.pairwise(starts):
            out[a:b] = dead_reckoning(*self.odometry[a:b].T, start=tuple(self.poses[a]))
        return out

    def subset(self, start: int = 0, stop: int | None = None) -> Session:
        """Frames ``start..stop`` as a new session (its first frame gets ``dt = 0``)."""
        stop = len(self) if stop is None else min(stop, len(self))
        if not 0 <= start < stop:
            raise InputError(f"empty frame range {start}:{stop} of {self!r}")
        sl = slice(start, stop)
        odo = self.odometry[sl].copy()
        odo[0] = 0.0
        obst = self.obstacles
        if obst is not None:
            obst = replace(obst, centres=obst.centres[sl])
        return replace(
            self,
            poses=self.poses[sl],
            times=self.times[sl],
            odometry=odo,
            laps=self.laps[sl],
            gain=self.gain[sl],
            keys=self.keys[sl],
            obstacles=obst,
        )

    def images(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """``(N, H, W)`` uint8 stack of rendered frames (convenience for small ranges)."""
        stop = len(self) if stop is None else min(stop, len(self))
        return np.stack([self.render(k) for k in range(start, stop)])


_BRIDGE_KEY = 1000
"""Noise keys of bridge frames use session number ``_BRIDGE_KEY + i`` (bridge i)."""


@dataclass
class Tour:
    """A world and the sessions recorded in it.

    Attributes:
        name: the tour's name.
        world: the static floor plan (for plots).
        sessions: the sessions, in the paper's order.
        routes: named routes (for plots).
        description: one line on what it reproduces.
        options: the options it was built with (seed included).
        bridges: per gap between consecutive sessions, the ``(M, 3)`` ground-truth poses
            of the drive along the tour's roads from where one session ends to where the
            next begins (used by :meth:`continuous`).
        noise: the odometry error model (None = exact).
        seed: the tour's seed.
    """

    name: str
    world: World
    sessions: list[Session]
    routes: dict[str, Route] = field(default_factory=dict)
    description: str = ""
    options: dict = field(default_factory=dict)
    bridges: list[np.ndarray] = field(default_factory=list)
    noise: OdometryNoise | None = None
    seed: int = 0

    def session(self, key: int | str) -> Session:
        """A session by 1-based number or name ("session2")."""
        names = [s.name for s in self.sessions]
        if isinstance(key, str):
            if key in names:
                return self.sessions[names.index(key)]
            if key == "full":
                return self.full()
            if key == "continuous":
                return self.continuous()
            raise InputError(
                unknown_name_message(
                    f"session of tour {self.name!r}", key, [*names, "full", "continuous"]
                )
            )
        if not 1 <= key <= len(self.sessions):
            raise InputError(f"tour {self.name!r} has sessions 1..{len(self.sessions)}, not {key}")
        return self.sessions[key - 1]

    def full(self) -> Session:
        """All sessions concatenated (a kidnap between them: ``dt = 0``, zero odometry)."""
        if len(self.sessions) == 1:
            return self.sessions[0]
        ss = self.sessions
        times, t0 = [], 0.0
        for s in ss:
            period = float(np.median(s.odometry[1:, 2])) if len(s) > 1 else 1.0
            times.append(s.times - s.times[0] + t0)
            t0 = times[-1][-1] + period
        obst = None
        if ss[0].obstacles is not None:
            o = ss[0].obstacles
            obst = replace(o, centres=np.concatenate([_obstacles(s).centres for s in ss]))
        return Session(
            name="full",
            tour=self.name,
            world=self.world,
            poses=np.concatenate([s.poses for s in ss]),
            times=np.concatenate(times),
            odometry=np.concatenate([s.odometry for s in ss]),
            camera=ss[0].camera,
            lasers=ss[0].lasers,
            laps=np.concatenate([s.laps for s in ss]),
            gain=np.concatenate([s.gain for s in ss]),
            pixel_noise=ss[0].pixel_noise,
            keys=np.concatenate([s.keys for s in ss]),
            obstacles=obst,
            info=ss[0].info,
        )

    def continuous(self) -> Session:
        """All sessions driven in one continuous run, joined by drives along the roads.

        The robot drives session 1, then along the tour's own routes (:attr:`bridges`)
        from where it ended to where session 2 begins, then session 2, and so on: the
        single mapping session the multisession paper compares with ("the robot
        continuously moves through the environment"). Bridge frames are ordinary
        frames with odometry; a session's frames keep their poses, noise keys and
        odometry (its first frame gets the odometry of the step that reaches it). One
        clock (``times = k * dt``); ``info["parts"]`` lists every session and bridge as
        ``{"name", "start", "stop"}`` frame ranges. Moved obstacles keep the previous
        session's last layout on a bridge; pedestrians are absent there.

        Returns:
            The continuous session (named "continuous"); the only session of a
            single-session tour.

        Raises:
            InputError: the tour was built without bridges between its sessions.
        """
        ss = self.sessions
        if len(ss) == 1:
            return ss[0]
        if len(self.bridges) != len(ss) - 1:
            raise InputError(
                f"tour {self.name!r} has no roads between its sessions; use full() instead"
            )
        dts = [float(np.median(s.odometry[1:, 2])) for s in ss if len(s) > 1]
        dt = dts[0] if dts else 1.0
        poses, keys, laps, gain, centres, parts, own = [], [], [], [], [], [], []
        n = 0
        for i, sess in enumerate(ss):
            if i > 0:
                br = self.bridges[i - 1]
                m = len(br)
                poses.append(br)
                keys.append(
                    np.column_stack(
                        [np.full(m, self.seed), np.full(m, _BRIDGE_KEY + i), np.arange(m)]
                    ).astype(np.int64)
                )
                laps.append(np.full(m, ss[i - 1].laps[-1]))
                gain.append(np.full(m, ss[i - 1].gain[-1]))
                if sess.obstacles is not None:
                    o = _obstacles(ss[i - 1])
                    c = np.repeat(o.centres[-1:], m, axis=0)
                    c[:, o.n_moved :] = 1e4  # no pedestrians on a bridge
                    centres.append(c)
                parts.append({"name": f"bridge{i}", "start": n, "stop": n + m})
                n += m
            poses.append(sess.poses)
            keys.append(sess.keys)
            laps.append(sess.laps)
            gain.append(sess.gain)
            if sess.obstacles is not None:
                centres.append(sess.obstacles.centres)
            parts.append({"name": sess.name, "start": n, "stop": n + len(sess)})
            own.append((n, sess))
            n += len(sess)
        all_poses = np.concatenate(poses)
        rng = np.random.default_rng([self.seed, 2000])
        odo = odometry_from_poses(all_poses, dt, self.noise, rng)
        for a, sess in own:  # a session's own odometry (same noise as when run alone)
            odo[a + 1 : a + len(sess)] = sess.odometry[1:]
        obst = None
        if ss[0].obstacles is not None:
            obst = replace(ss[0].obstacles, centres=np.concatenate(centres))
        return Session(
            name="continuous",
            tour=self.name,
            world=self.world,
            poses=all_poses,
            times=np.arange(n) * dt,
            odometry=odo,
            camera=ss[0].camera,
            lasers=ss[0].lasers,
            laps=np.concatenate(laps),
            gain=np.concatenate(gain),
            pixel_noise=ss[0].pixel_noise,
            keys=np.concatenate(keys),
            obstacles=obst,
            info={**ss[0].info, "parts": parts},
        )

    def plot(self, ax: Any = None, *, legend: bool = True) -> Any:
        """Floor plan with each session's path coloured; crosses mark starts, diamonds ends."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(6, 5))
        self.world.plot(ax)
        colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
        for i, s in enumerate(self.sessions):
            c = colors[i % len(colors)]
            ax.plot(
                s.poses[:, 0], s.poses[:, 1], "-", color=c, lw=1.2, label=f"{s.name} ({len(s)})"
            )
            ax.plot(*s.poses[0, :2], "x", color=c, ms=10, mew=2)
            ax.plot(*s.poses[-1, :2], "D", color=c, ms=6)
        ax.set_title(self.name)
        if legend:
            ax.legend(fontsize=8, loc="upper right")
        return ax

    def __repr__(self) -> str:
        parts = ", ".join(f"{s.name}: {len(s)}" for s in self.sessions)
        return f"Tour({self.name!r}, {parts})"


# ---------------------------------------------------------------------------- helpers


@dataclass
class _Opts:
    """Options common to every tour (see the module docstring)."""

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


def _split_options(name: str, options: dict, own: Callable) -> tuple[_Opts, dict]:
    common = {f for f in _Opts.__dataclass_fields__}
    specific = set(inspect.signature(own).parameters) - {"seed", "opts"}
    bad = set(options) - common - specific
    if bad:
        key = sorted(bad)[0]
        raise InputError(unknown_name_message(f"option of tour {name!r}", key, common | specific))
    o = _Opts(**{k: v for k, v in options.items() if k in common})
    for key in ("fog", "pixel_noise", "illumination", "moved_obstacles", "moving_obstacles"):
        v = getattr(o, key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or v < 0:
            raise InputError(f"tour option {key}={v!r} must be a number >= 0")
    if o.illumination_mode not in ("auto", "session", "lap", "drift"):
        raise InputError(f"illumination_mode {o.illumination_mode!r}: use session, lap or drift")
    return o, {k: v for k, v in options.items() if k in specific}


def _camera(o: _Opts, **defaults) -> Camera:
    kw = dict(defaults)
    if o.camera is not None and o.camera != kw["kind"]:
        kw["kind"] = o.camera
        kw.update(width=256, height=64) if o.camera == "panoramic" else kw.update(
            width=128, height=96
        )
    for k in ("width", "height", "fov_deg", "cam_height"):
        if getattr(o, k) is not None:
            kw[k] = getattr(o, k)
    return Camera(fog=o.fog, **kw)


def _noise(o: _Opts, **defaults: float) -> OdometryNoise | None:
    if o.exact_odometry:
        return None
    kw = {k: (getattr(o, k) if getattr(o, k) is not None else v) for k, v in defaults.items()}
    return OdometryNoise(**kw)


def _lasers(o: _Opts, default: bool) -> dict[str, Laser]:
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
    """What a tour builder returns before the common options are applied."""

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


def _assemble(name: str, b: _Build, o: _Opts, seed: int, options: dict) -> Tour:
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
            path = _legs_path(legs, prev.poses[-1, :2], nxt.poses[0, :2], b.plan[i][4])
            _check_clear(b.world, Route(path, closed=False), b.clearance)
            bridges.append(
                _bridge_poses(prev.poses[-1], nxt.poses[0], path, b.plan[i][4], max_turn)
            )
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


def _legs_path(
    legs: list[tuple[Route, Point | None, Point | None]],
    start: np.ndarray,
    end: np.ndarray,
    ds: float,
) -> np.ndarray:
    """``(P, 2)`` dense polyline along the legs' routes from ``start`` to ``end``."""
    pts = []
    for route, a, c in legs:
        sa = _arc_of(route, tuple(start) if a is None else a)
        sb = _arc_of(route, tuple(end) if c is None else c)
        if route.closed and sb <= sa + 1e-9:
            sb += route.length
        if sb < sa:
            raise AssertionError(f"bridge leg runs backwards along its route ({sa} -> {sb})")
        n = max(2, math.ceil((sb - sa) / (ds / 20)) + 1)
        pts.append(route.at(np.linspace(sa, sb, n)))
    path = np.concatenate(pts)
    path[0], path[-1] = start, end
    return path


def _bridge_poses(
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


def _check_clear(world: World, route: Route, clearance: float) -> None:
    """Raise if a wall comes closer than ``clearance`` to the route (a builder bug)."""
    p = route.at(np.linspace(0, route.length, 2000, endpoint=False))
    a, b = world.segments[:, :2], world.segments[:, 2:]
    ab = b - a
    t = np.clip(((p[:, None] - a[None]) * ab[None]).sum(-1) / (ab * ab).sum(-1)[None], 0, 1)
    d = np.linalg.norm(p[:, None] - (a[None] + t[..., None] * ab[None]), axis=-1)
    if d.min() < clearance:
        raise AssertionError(f"route passes {d.min():.2f} m from a wall (< {clearance})")


# ---------------------------------------------------------------------------- tours


def virtual_tour(
    seed: int = 0,
    opts: _Opts | None = None,
    *,
    frames_per_lap: int = 150,
    hz: float = 1.0,
    session2_start: float = 0.873,
) -> _Build:
    """Ellipse (24 x 14 m) in a 36 x 26 m hall (multisession paper, Fig. 5)."""
    o = opts or _Opts()
    _positive(frames_per_lap=frames_per_lap - 3, hz=hz)
    if isinstance(session2_start, bool) or not 0.75 < float(session2_start) < 1.0:
        raise InputError(
            f"tour option session2_start={session2_start!r}: session 2 starts in the quarter "
            "session 1 leaves unmapped, between 0.75 and 1 lap (exclusive; default 0.873)"
        )
    route = Route.ellipse(12.0, 7.0, start_deg=-90.0)
    # smooth textures (the paper's virtual world has smooth imagery): turning by one
    # template column (2.8 degrees) changes a view far less than vt_match_threshold, so
    # the published vt_step_match = 2 works; the far hall walls get 3x wider features
    wb = WorldBuilder(seed=seed, wall_height=5.0, style="smooth")
    wb.polyline([(-18, -13), (18, -13), (18, 13), (-18, 13)], scale=3.0)
    wb.box(0.0, 0.0, 10.0, 4.0, height=3.0)
    for cx, cy, w, h in (
        (-7.5, 0.0, 1.0, 1.0),
        (7.5, 0.5, 1.2, 1.2),
        (0.0, 10.0, 2.0, 1.0),
        (-9.0, -9.5, 1.5, 1.5),
        (10.0, -9.0, 1.0, 2.0),
        (14.5, 2.0, 1.0, 1.0),
        (-14.5, -3.0, 1.0, 1.5),
        (4.0, -10.5, 1.0, 1.0),
    ):
        wb.box(cx, cy, w, h, height=2.5)
    world = wb.build(name="virtual_tour")
    _check_clear(world, route, 1.5)
    ds = route.length / frames_per_lap
    n1 = round(0.75 * frames_per_lap) + 1
    start2 = round(float(session2_start) * frames_per_lap)
    if not n1 - 1 < start2 < frames_per_lap:
        raise InputError(
            f"tour option session2_start={session2_start!r} rounds to frame {start2} of "
            f"{frames_per_lap}, outside the unmapped quarter; move it away from its ends"
        )
    n2 = round(2.9 * frames_per_lap) + 1
    return _Build(
        world=world,
        routes={"ellipse": route},
        plan=[("session1", route, 0.0, n1, ds, hz), ("session2", route, start2 * ds, n2, ds, hz)],
        camera=_camera(o, kind="panoramic", width=256, height=64, cam_height=1.0),
        noise=_noise(
            o,
            scale_error=0.03,
            rot_scale_error=0.01,
            heading_bias=0.001,
            trans_noise=0.01,
            rot_noise=0.005,
        ),
        lasers=_lasers(o, False),
        main_route=route,
        obstacle_offset=2.5,
        description="multisession Fig. 5: ellipse, 3/4 lap, then 2.9 laps from an unmapped point",
        # continuous run: on along the ellipse through the unmapped quarter to session 2
        bridges=[[(route, None, None)]],
        clearance=1.5,
    )


def lab_tour(
    seed: int = 0, opts: _Opts | None = None, *, speed: float = 0.25, hz: float = 1.0
) -> _Build:
    """Two rectangles sharing three sides and a middle bar, a digital '8' (Fig. 6)."""
    o = opts or _Opts()
    _positive(speed=speed, hz=hz)
    small = Route.polygon([(0, 4), (6, 4), (6, 8), (0, 8)], radius=0.6)
    large = Route.polygon([(0, 0), (6, 0), (6, 8), (0, 8)], radius=0.6)
    wb = WorldBuilder(seed=seed, wall_height=2.5)
    wb.polyline([(-2.5, -2.5), (8.5, -2.5), (8.5, 10.5), (-2.5, 10.5)])
    wb.box(3.0, 6.0, 4.0, 2.0)  # desks inside the small loop
    wb.box(3.0, 2.0, 4.0, 2.0)  # desks inside the lower loop
    for cx, cy, w, h in (
        (-2.0, 2.0, 0.8, 2.0),
        (8.0, 6.5, 0.8, 1.6),
        (4.0, 10.0, 2.0, 0.8),
        (1.0, -2.0, 1.6, 0.8),
        (7.5, -1.5, 1.0, 1.0),
        (-1.7, 9.5, 1.2, 1.2),
    ):
        wb.box(cx, cy, w, h, height=1.2)
    world = wb.build(name="lab_tour")
    _check_clear(world, small, 0.8)
    _check_clear(world, large, 0.8)
    ds = speed / hz
    # small loop starts mid-bar heading +x; the large one mid-bottom heading +x
    s1 = _arc_of(small, (3.0, 4.0))
    s2 = _arc_of(large, (3.0, 0.0))
    n1 = round(2 * small.length / ds) + 1
    n2 = round(1.9 * large.length / ds) + 1
    return _Build(
        world=world,
        routes={"small": small, "large": large},
        plan=[("session1", small, s1, n1, ds, hz), ("session2", large, s2, n2, ds, hz)],
        camera=_camera(o, kind="forward", width=640, height=480, fov_deg=50.0, cam_height=0.3),
        noise=_noise(
            o,
            scale_error=0.03,
            rot_scale_error=0.02,
            heading_bias=0.002,
            trans_noise=0.01,
            rot_noise=0.01,
        ),
        lasers=_lasers(o, False),
        main_route=large,
        obstacle_size=0.6,
        obstacle_offset=0.9,
        pedestrian_offset=0.6,
        obstacle_height=1.0,
        description="multisession Fig. 6: two CCW laps of the small rectangle, 1.9 of the large",
        # continuous run: on round the small rectangle to its left side (shared with the
        # large one, same direction), then down the large one to session 2's start
        bridges=[[(small, None, (0.0, 6.0)), (large, (0.0, 6.0), None)]],
        clearance=0.8,
    )


def irat_like(
    seed: int = 0, opts: _Opts | None = None, *, speed: float = 0.2, hz: float = 10.0
) -> _Build:
    """A 2 x 2 block road network, iRat scale (Fig. 7): four inner loops and the outer loop."""
    o = opts or _Opts()
    _positive(speed=speed, hz=hz)
    k = 0.1  # built at 10x, scaled down to iRat size
    gx, gy, half = 12.0, 8.0, 1.5
    wb = WorldBuilder(seed=seed, wall_height=3.0)
    # outer wall with an opening on the left road where a spur (driveway) joins
    wb.polyline(
        [
            (-half, gy - half),
            (-half, -half),
            (2 * gx + half, -half),
            (2 * gx + half, 2 * gy + half),
            (-half, 2 * gy + half),
            (-half, gy + half),
        ],
        closed=False,
    )
    spur = 6.0
    wb.polyline(
        [
            (-half, gy - half),
            (-half - spur, gy - half),
            (-half - spur, gy + half),
            (-half, gy + half),
        ],
        closed=False,
    )
    for bx in range(2):
        for by in range(2):
            wb.box(gx * (bx + 0.5), gy * (by + 0.5), gx - 2 * half, gy - 2 * half)
    world = wb.build(name="irat_like").scaled(k)
    r = 0.8 * k
    blocks = [(0, 0), (1, 0), (1, 1), (0, 1)]
    routes = {}
    for i, (bx, by) in enumerate(blocks):
        x0, y0 = gx * bx * k, gy * by * k
        routes[f"block{i + 1}"] = Route.polygon(
            [(x0, y0), (x0 + gx * k, y0), (x0 + gx * k, y0 + gy * k), (x0, y0 + gy * k)], radius=r
        )
    outer = Route.polygon(
        [(0, 0), (2 * gx * k, 0), (2 * gx * k, 2 * gy * k), (0, 2 * gy * k)], radius=r
    )
    # session 5 comes in along the spur (unmapped), turns south, drives the outer loop
    # and passes the junction again
    fifth = Route.polygon(
        [
            (-(half + spur - 1.5) * k, gy * k),
            (0, gy * k),
            (0, 0),
            (2 * gx * k, 0),
            (2 * gx * k, 2 * gy * k),
            (0, 2 * gy * k),
            (0, gy * k - 1.5 * half * k),
        ],
        radius=r,
        closed=False,
    )
    routes["outer"] = outer
    routes["session5"] = fifth
    for rt in routes.values():
        _check_clear(world, rt, 0.1)
    # continuous run: sessions 1-4 end where the next begins along the outer loop's
    # straight roads; after session 4 the robot drives down the left road, turns into the
    # spur, drives out to session 5's start and turns on the spot
    into_spur = Route.polygon(
        [(0.0, gy * k + 4 * r), (0.0, gy * k), (-(half + spur - 1.5) * k, gy * k)],
        radius=r,
        closed=False,
    )
    bridges: list[list[tuple[Route, Point | None, Point | None]]]
    bridges = [[(outer, None, None)] for _ in range(3)]
    bridges.append([(outer, None, (0.0, gy * k + 4 * r)), (into_spur, (0.0, gy * k + 4 * r), None)])
    ds = speed / hz
    plan = []
    starts = [
        (gx * k / 2, 0.0),
        (1.5 * gx * k, 0.0),
        (1.5 * gx * k, 2 * gy * k),
        (gx * k / 2, 2 * gy * k),
    ]
    for i in range(4):
        rt = routes[f"block{i + 1}"]
        plan.append(
            (f"session{i + 1}", rt, _arc_of(rt, starts[i]), round(rt.length / ds) + 1, ds, hz)
        )
    plan.append(("session5", fifth, 0.0, int(fifth.length / ds) + 1, ds, hz))
    return _Build(
        world=world,
        routes=routes,
        plan=plan,
        camera=_camera(o, kind="forward", width=160, height=96, fov_deg=75.0, cam_height=0.06),
        noise=_noise(
            o,
            scale_error=0.03,
            rot_scale_error=0.02,
            heading_bias=0.005,
            trans_noise=0.005,
            rot_noise=0.02,
        ),
        lasers=_lasers(o, False),
        main_route=outer,
        obstacle_size=0.06,
        obstacle_offset=0.09,
        pedestrian_offset=0.07,
        obstacle_height=0.15,
        scale=k,
        description="multisession Fig. 7: four inner loops, then the outer loop joining them",
        bridges=bridges,
        clearance=0.1,
    )


def loop(
    seed: int = 0,
    opts: _Opts | None = None,
    *,
    laps: float = 6.0,
    frames: int | None = None,
    hz: float = 5.0,
) -> _Build:
    """A corridor loop (12 x 8 m centre line, 2.5 m wide) driven several times."""
    o = opts or _Opts()
    _positive(laps=laps, hz=hz, frames=(frames - 1) if frames is not None else 1)
    route = Route.polygon([(0, 0), (12, 0), (12, 8), (0, 8)], radius=1.0)
    wb = WorldBuilder(seed=seed, wall_height=2.5)
    wb.polyline([(-1.25, -1.25), (13.25, -1.25), (13.25, 9.25), (-1.25, 9.25)])
    wb.polyline([(1.25, 1.25), (10.75, 1.25), (10.75, 6.75), (1.25, 6.75)])
    # cabinets, pillars and recess frames along the walls (laser and visual landmarks)
    for cx, cy, w, h in (
        (3.0, -1.0, 1.6, 0.5),
        (8.5, -1.0, 0.5, 0.5),
        (13.0, 3.0, 0.5, 1.2),
        (6.0, 9.0, 2.0, 0.5),
        (-1.0, 5.5, 0.5, 1.8),
        (1.0, 4.0, 0.5, 0.5),
        (6.0, 1.0, 1.0, 0.5),
        (11.0, 5.0, 0.5, 0.8),
        (9.5, 9.0, 0.6, 0.5),
        (-1.0, 1.5, 0.5, 0.6),
        (4.0, 7.0, 0.8, 0.5),
    ):
        wb.box(cx, cy, w, h, height=1.8)
    world = wb.build(name="loop")
    _check_clear(world, route, 0.7)
    n = int(frames) if frames is not None else round(laps * 1780 / 6) + 1
    ds = laps * route.length / max(n - 1, 1)
    return _Build(
        world=world,
        routes={"corridor": route},
        plan=[("session1", route, 0.0, n, ds, hz)],
        camera=_camera(o, kind="panoramic", width=256, height=64, cam_height=1.0),
        noise=_noise(
            o,
            scale_error=0.02,
            rot_scale_error=0.008,
            heading_bias=0.001,
            trans_noise=0.02,
            rot_noise=0.02,
        ),
        lasers=_lasers(o, True),
        main_route=route,
        obstacle_size=0.5,
        obstacle_offset=0.8,
        pedestrian_offset=0.7,
        obstacle_height=1.2,
        description="single-session corridor loop (the classic loop-closure test), lasers on",
    )


def _grid_drive(
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


def suburb(
    seed: int = 0,
    opts: _Opts | None = None,
    *,
    blocks: int = 8,
    block_size: float = 40.0,
    street_width: float = 12.0,
    frames: int = 20000,
    speed: float = 10.0,
    hz: float = 10.0,
) -> _Build:
    """A street grid of ``blocks`` x ``blocks`` city blocks driven by a car (St Lucia-like).

    Every block is a row of buildings of varied heights and facades (each side of a block
    is split into three to five houses, each with its own texture); a forward camera at
    car height (1.5 m) looks down the street. The route drives most streets several
    times in both directions and closes many loops (see :func:`_grid_drive`).
    """
    o = opts or _Opts()
    _positive(blocks=blocks, block_size=block_size, street_width=street_width, speed=speed, hz=hz)
    _positive(frames=frames - 1)
    pitch = block_size + street_width
    n_nodes = int(blocks) + 1
    wb = WorldBuilder(seed=seed, wall_height=8.0)
    g = np.random.default_rng([seed, 4242])
    half = block_size / 2
    for bx in range(int(blocks)):
        for by in range(int(blocks)):
            cx, cy = (bx + 0.5) * pitch, (by + 0.5) * pitch
            corners = [(cx - half, cy - half), (cx + half, cy - half)]
            corners += [(cx + half, cy + half), (cx - half, cy + half)]
            for i in range(4):
                p, q = np.array(corners[i]), np.array(corners[(i + 1) % 4])
                cuts = np.sort(g.uniform(0.15, 0.85, int(g.integers(2, 5))))
                ts = np.r_[0.0, cuts, 1.0]
                for a, b in itertools.pairwise(ts):
                    wb.segment(
                        tuple(p + a * (q - p)),
                        tuple(p + b * (q - p)),
                        height=float(g.uniform(5.0, 14.0)),
                    )
    edge = street_width / 2 + 3.0  # the city's outer edge: a row of walls past the outer streets
    far = int(blocks) * pitch
    wb.polyline(
        [(-edge, -edge), (far + edge, -edge), (far + edge, far + edge), (-edge, far + edge)],
        height=10.0,
    )
    world = wb.build(name="suburb", floor=0.4, ceiling=0.9)
    ds = speed / hz
    n = int(frames)
    drive = _grid_drive(np.random.default_rng([seed, 31]), n_nodes, (n - 1) * ds + 2 * pitch, pitch)
    corners = [(i * pitch, j * pitch) for i, j in drive]
    route = Route.polygon(corners, radius=street_width / 3, closed=False)
    _check_clear(world, route, street_width / 2 - 0.5)
    return _Build(
        world=world,
        routes={"drive": route},
        plan=[("session1", route, 0.0, n, ds, hz)],
        camera=_camera(o, kind="forward", width=128, height=64, fov_deg=60.0, cam_height=1.5),
        noise=_noise(
            o,
            scale_error=0.02,
            rot_scale_error=0.01,
            heading_bias=0.001,
            trans_noise=0.05,
            rot_noise=0.01,
        ),
        lasers=_lasers(o, False),
        main_route=route,
        obstacle_size=2.0,
        obstacle_offset=street_width / 2 - 1.5,
        pedestrian_offset=street_width / 2 - 1.0,
        obstacle_height=1.5,
        scale=4.0,
        description=(
            f"suburb: {blocks} x {blocks} city blocks, a car drives most streets several "
            "times both ways (St Lucia-like)"
        ),
        clearance=street_width / 2 - 0.5,
    )


def _positive(**values: float) -> None:
    for key, v in values.items():
        if not isinstance(v, (int, float)) or not v > 0:
            raise InputError(f"tour option {key} is too small or not a number; give a larger value")


def _arc_of(route: Route, point: tuple[float, float]) -> float:
    """Arc length of the route point nearest to ``point`` (projected onto the polyline)."""
    a, b = route.points[:-1], route.points[1:]
    ab = b - a
    p = np.asarray(point, np.float64)
    t = np.clip(((p - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-18), 0.0, 1.0)
    d = np.linalg.norm(a + t[:, None] * ab - p, axis=1)
    i = int(np.argmin(d))
    return float(route.s[i] + t[i] * (route.s[i + 1] - route.s[i]))


TOURS: dict[str, Callable[..., _Build]] = {
    "virtual_tour": virtual_tour,
    "lab_tour": lab_tour,
    "irat_like": irat_like,
    "loop": loop,
    "suburb": suburb,
}

#: The shipped config preset (``configs/NAME.yaml``) that suits each tour; ``torchratslam
#: simulate`` writes it beside the data as an OpenRatSLAM ``config.txt``.
TOUR_PRESETS: dict[str, str] = {
    "virtual_tour": "virtual_tour",
    "lab_tour": "lab_tour",
    "irat_like": "irat",
    "suburb": "suburb",
}


def get_tour(name: str, *, seed: int = 0, **options) -> Tour:
    """Build a tour by name.

    Args:
        name: one of ``TOURS`` (virtual_tour, lab_tour, irat_like, loop).
        seed: seed of the textures, odometry noise and obstacles.
        **options: common options (module docstring) and the tour's own (``hz``,
            ``speed``, ``frames_per_lap``, ``laps``, ``frames``).

    Returns:
        The tour, with its sessions ready to iterate (frames render lazily).

    Raises:
        InputError: unknown tour or option, or an invalid option value.
    """
    if name not in TOURS:
        raise InputError(unknown_name_message("simulator tour", name, TOURS))
    builder = TOURS[name]
    o, own = _split_options(name, options, builder)
    try:
        b = builder(int(seed), o, **own)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"tour {name!r}: bad option value ({exc})") from exc
    return _assemble(name, b, o, int(seed), options)
