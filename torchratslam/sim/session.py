"""Sessions and tours: ground-truth poses, odometry and lazily rendered frames.

A :class:`Tour` (built by :func:`torchratslam.sim.tours.get_tour`) is a world and the
:class:`Session` s recorded in it; :meth:`Tour.full` concatenates them with kidnaps,
:meth:`Tour.continuous` joins them with drives along the roads.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ratslam_graph.errors import unknown_name_message
from ratslam_graph.geometry import dead_reckoning
from torchratslam.errors import InputError
from torchratslam.messages import Frame
from torchratslam.sim.laser import Laser, scan
from torchratslam.sim.motion import OdometryNoise, Route, odometry_from_poses
from torchratslam.sim.render import Camera, render
from torchratslam.sim.world import World

__all__ = ["BRIDGE_KEY", "Obstacles", "Session", "Tour"]


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
                    if self.keys[k, 1] < BRIDGE_KEY
                    else f"bridge{self.keys[k, 1] - BRIDGE_KEY}"
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


BRIDGE_KEY = 1000
"""Noise keys of bridge frames use session number ``BRIDGE_KEY + i`` (bridge i)."""


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
                        [np.full(m, self.seed), np.full(m, BRIDGE_KEY + i), np.arange(m)]
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
