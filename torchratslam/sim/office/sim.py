"""A closed-loop office simulation at 7 Hz with ground truth on every step.

:class:`OfficeSim` drives the robot along the office's passages with the local movement
behaviours of :mod:`torchratslam.sim.office.motion`, senses the world (camera, range
scan, odometry, :mod:`torchratslam.sim.office.sensors`) and reports the ground-truth
pose. Obstacles (boxes) can be placed and removed mid-run: the renderer and the range
sensor see them, and the robot's local obstacle avoidance turns it around when the range
scan shows something closer than ``stop_distance`` ahead.

Example:
    >>> from torchratslam.sim.office.sim import OfficeSim
    >>> sim = OfficeSim(seed=0)
    >>> obs = sim.reset()
    >>> obs.image.shape, obs.scan.shape
    ((8, 12), (91,))
    >>> sim.step(0).pose.shape
    (3,)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ratslam_graph.geometry import wrap_angle
from torchratslam.errors import InputError
from torchratslam.sim.office.builder import Office, build_office
from torchratslam.sim.office.explore import edge_index, explore_behaviour
from torchratslam.sim.office.motion import (
    Behaviour,
    MotionParams,
    MotionState,
    advance,
    local_paths,
    turn_around,
)
from torchratslam.sim.office.sensors import SensorParams, odometry, range_scan, small_image
from torchratslam.sim.world import World, WorldBuilder

__all__ = ["OfficeParams", "OfficeSim", "OfficeStep"]


@dataclass(frozen=True)
class OfficeParams:
    """The simulation's settings.

    Attributes:
        motion: kinematics and rate.
        sensors: camera, range sensor and odometry models.
        stop_distance: obstacle avoidance turns around below this range ahead (m).
        front_deg: half-width of the sector "ahead" of the range scan (deg).
        texture_seed: seed of the wall textures.
    """

    motion: MotionParams = field(default_factory=MotionParams)
    sensors: SensorParams = field(default_factory=SensorParams)
    stop_distance: float = 0.6
    front_deg: float = 20.0
    texture_seed: int = 0


@dataclass(frozen=True)
class OfficeStep:
    """One tick's observation and ground truth.

    Attributes:
        image: the reduced forward camera image.
        odometry: ``[vtrans, vrot, dt]`` of the tick (noisy).
        scan: the range scan (m).
        pose: ground truth ``[x, y, heading]``.
        time: simulated time (s).
        node: the node reached this tick (-1 if none).
        behaviour: the behaviour executed at that node, or ``TURN_AROUND`` when the robot
            reversed mid-passage (-1 if neither).
        blocked: obstacle avoidance turned the robot around this tick.

    Shape:
        image: (rows, cols) uint8; odometry: (3,); scan: (beams,) float32; pose: (3,).
    """

    image: np.ndarray
    odometry: np.ndarray
    scan: np.ndarray
    pose: np.ndarray
    time: float
    node: int = -1
    behaviour: int = -1
    blocked: bool = False


class OfficeSim:
    """The office robot in closed loop.

    Args:
        office: the built floor (default: :data:`~torchratslam.sim.office.plan.OFFICE_FLOOR`).
        params: the settings.
        seed: seed of the sensor noise and of exploration's tie breaks.
    """

    def __init__(
        self, office: Office | None = None, params: OfficeParams | None = None, *, seed: int = 0
    ) -> None:
        self.params = params if params is not None else OfficeParams()
        self.office = office if office is not None else build_office(seed=self.params.texture_seed)
        self._obstacles: dict[int, tuple[float, float, float, float]] = {}
        self._next_id = 0
        self._world: World | None = None
        self.reset(seed)

    # ------------------------------------------------------------------ world
    @property
    def world(self) -> World:
        """The walls plus the obstacles in place now."""
        if self._world is None:
            extra = None
            if self._obstacles:
                wb = WorldBuilder(seed=1000 + self._next_id, wall_height=1.0)
                for cx, cy, w, h in self._obstacles.values():
                    wb.box(cx, cy, w, h, kind="obstacle")
                extra = wb.build()
            self._world = self.office.world.extended(extra)
        return self._world

    @property
    def obstacles(self) -> dict[int, tuple[float, float, float, float]]:
        """Obstacles in place: ``id -> (cx, cy, w, h)`` (m)."""
        return dict(self._obstacles)

    def place_obstacle(self, cx: float, cy: float, w: float, h: float) -> int:
        """Put an axis-aligned box on the floor; returns its id."""
        if w <= 0 or h <= 0:
            raise InputError(f"obstacle size {w} x {h} must be > 0")
        i = self._next_id
        self._next_id += 1
        self._obstacles[i] = (float(cx), float(cy), float(w), float(h))
        self._world = None
        return i

    def remove_obstacle(self, obstacle_id: int) -> None:
        """Take an obstacle away."""
        if obstacle_id not in self._obstacles:
            raise InputError(f"there is no obstacle {obstacle_id}")
        del self._obstacles[obstacle_id]
        self._world = None

    def path_blocked(self, path: np.ndarray, clearance: float = 0.3) -> bool:
        """Whether a path's points come within ``clearance`` of an obstacle (ground truth).

        Shape:
            path: (P, 2).
        """
        if not self._obstacles:
            return False
        b = np.array(list(self._obstacles.values()))  # (O, 4)
        p = np.asarray(path, np.float64).reshape(-1, 1, 2)
        dx = np.abs(p[..., 0] - b[:, 0]) - b[:, 2] / 2
        dy = np.abs(p[..., 1] - b[:, 1]) - b[:, 3] / 2
        d = np.hypot(np.maximum(dx, 0.0), np.maximum(dy, 0.0))
        return bool((d < clearance).any())

    # ------------------------------------------------------------------ state
    @property
    def state(self) -> MotionState:
        """Where the robot is on the passage graph."""
        return self._m

    @property
    def pose(self) -> np.ndarray:
        """Ground truth ``[x, y, heading]``, (3,)."""
        xy = self._m.position(self.office)
        return np.array([xy[0], xy[1], self._m.heading])

    @property
    def edge_visits(self) -> np.ndarray:
        """How often each passage has been driven end to end, (K,)."""
        return self._visits.copy()

    def local_paths(self) -> dict[Behaviour, np.ndarray]:
        """The path each available behaviour would take from here (for arbitration)."""
        return local_paths(self.office, self._m, self.params.motion)

    def explore(self) -> Behaviour:
        """Exploration's behaviour for the node ahead (least-driven way out)."""
        return explore_behaviour(self.office, self._m, self._visits, self._rng)

    def _observe(
        self, prev: np.ndarray, node: int = -1, behaviour: int = -1, blocked: bool = False
    ) -> OfficeStep:
        pose = self.pose
        sp, world = self.params.sensors, self.world
        dt = self.params.motion.dt if self.time > 0 else 0.0
        odo = odometry(prev, pose, self.params.motion.dt, sp, self._rng)
        odo[2] = dt
        if dt == 0.0:
            odo[:2] = 0.0
        self._scan = range_scan(world, pose, sp, self._rng)
        image = small_image(world, pose, sp, self._rng)
        return OfficeStep(image, odo, self._scan, pose, self.time, node, behaviour, blocked)

    def reset(self, seed: int | None = None) -> OfficeStep:
        """Put the robot at the plan's start node; obstacles stay where they are."""
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        o = self.office
        name, deg = o.plan.start
        u = o.node(name)
        v = int(o.neighbours(u)[0])
        self._m = MotionState(u=u, v=v, s=0.0, heading=math.radians(deg))
        self._visits = np.zeros(len(o.edges), np.int64)
        self.time = 0.0
        return self._observe(self.pose)

    def _ahead_clear(self) -> bool:
        laser = self.params.sensors.laser
        front = np.abs(laser.beam_angles) <= math.radians(self.params.front_deg)
        return bool(self._scan[front].min() >= self.params.stop_distance)

    def step(self, behaviour: int) -> OfficeStep:
        """One tick with ``behaviour`` held for the node ahead (``TURN_AROUND`` reverses
        at once)."""
        try:
            b = Behaviour(int(behaviour))
        except ValueError:
            raise InputError(
                f"behaviour {behaviour} is not one of {[int(x) for x in Behaviour]}"
            ) from None
        prev = self.pose
        o, m = self.office, self._m
        node, done, blocked = -1, -1, False
        if b is Behaviour.TURN_AROUND:
            m, done = turn_around(o, m), int(b)
        else:
            m = MotionState(m.u, m.v, m.s, m.heading, b)
            want = math.atan2(*(o.nodes[m.v] - o.nodes[m.u])[::-1])
            aligned = abs(wrap_angle(want - m.heading)) <= 1e-9
            if aligned and not self._ahead_clear():
                m, done, blocked = turn_around(o, m), int(Behaviour.TURN_AROUND), True
            else:
                before = m.v
                m, executed = advance(o, m, self.params.motion)
                if executed is not None:
                    node, done = before, int(executed)
                    self._visits[edge_index(o, self._m.u, before)] += 1
        self._m = m
        self.time += self.params.motion.dt
        return self._observe(prev, node, done, blocked)
