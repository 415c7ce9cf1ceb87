"""The vocabulary of tour specifications: walls, routes, sessions, sensors and bridges.

A tour is a :class:`TourSpec` (its instances live in :mod:`torchratslam.sim.tour_data`);
:func:`torchratslam.sim.tour_builder.build_tour` reads one and builds the
:class:`~torchratslam.sim.session.Tour`. Lengths are metres, angles degrees, rates Hz.
Numbers that depend on a tour option are written :class:`Opt` (``option / div + add``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "Box",
    "CameraSpec",
    "EllipseRoute",
    "GridDriveRoute",
    "LapFraction",
    "Leg",
    "NoiseSpec",
    "Opt",
    "PolygonRoute",
    "Polyline",
    "SessionSpec",
    "Spacing",
    "StreetGrid",
    "TourSpec",
    "WorldSpec",
]

Point = tuple[float, float]


@dataclass(frozen=True)
class Opt:
    """A number read from a tour option: ``options[name] / div + add``."""

    name: str
    div: float = 1.0
    add: float = 0.0

    def value(self, options: Mapping[str, Any]) -> float:
        """The number for these option values."""
        return options[self.name] / self.div + self.add


Number = float | Opt


def resolve(v: Number, options: Mapping[str, Any]) -> float:
    """``v`` itself, or the option value it names."""
    return v.value(options) if isinstance(v, Opt) else v


@dataclass(frozen=True)
class Polyline:
    """Walls along a polyline (closed by default), one texture strip per side."""

    points: tuple[Point, ...]
    closed: bool = True
    height: float | None = None
    scale: float = 1.0


@dataclass(frozen=True)
class Box:
    """An axis-aligned box centred at ``(cx, cy)`` of size ``w`` x ``h``."""

    cx: float
    cy: float
    w: float
    h: float
    height: float | None = None


@dataclass(frozen=True)
class StreetGrid:
    """A street grid of ``blocks`` x ``blocks`` city blocks (options ``blocks``,
    ``block_size``, ``street_width``) inside an outer wall.

    Every side of a block is split at ``houses`` (low, high-exclusive) random cuts drawn
    in ``cut_range`` into houses of heights drawn in ``house_heights``; the generator is
    seeded ``[seed, seed_key]``. The outer wall runs ``edge_margin`` past the outer
    streets' middle, ``edge_height`` high.
    """

    seed_key: int = 4242
    houses: tuple[int, int] = (2, 5)
    cut_range: tuple[float, float] = (0.15, 0.85)
    house_heights: tuple[float, float] = (5.0, 14.0)
    edge_margin: float = 3.0
    edge_height: float = 10.0


WallSpec = Polyline | Box | StreetGrid


@dataclass(frozen=True)
class WorldSpec:
    """The floor plan: walls in drawing order (textures are drawn in this order)."""

    walls: tuple[WallSpec, ...]
    wall_height: float
    style: str = "default"
    floor: float = 0.35
    ceiling: float = 0.8
    scale: float = 1.0
    """Every length multiplied by this after building (textures follow)."""


@dataclass(frozen=True)
class PolygonRoute:
    """A polygon with rounded corners (:meth:`Route.polygon`), each arc drawn through
    ``arc_points`` points (a turn of ``a`` degrees turns in steps of ``a / (arc_points -
    1)`` degrees)."""

    corners: tuple[Point, ...]
    radius: Number
    closed: bool = True
    arc_points: Number = 24.0


@dataclass(frozen=True)
class EllipseRoute:
    """An ellipse of half axes ``a``, ``b`` starting at ``start_deg``."""

    a: float
    b: float
    start_deg: float = 0.0


@dataclass(frozen=True)
class GridDriveRoute:
    """A drive through the :class:`StreetGrid` (see ``tour_builder.grid_drive``), long
    enough for the session's frames plus two blocks; corners rounded at ``radius``."""

    radius: Number
    seed_key: int = 31


RouteSpec = PolygonRoute | EllipseRoute | GridDriveRoute


@dataclass(frozen=True)
class LapFraction:
    """A session start given by a tour option in laps from the route's start, strictly
    between ``low`` and ``high`` and after the previous session's last frame."""

    option: str
    low: float
    high: float
    default: float


@dataclass(frozen=True)
class SessionSpec:
    """One session: ``laps`` laps along ``route`` from ``start``.

    ``start``: the route point nearest a point, a :class:`LapFraction`, or None (the
    route's start). ``count``: how ``laps`` becomes a frame count, ``"round"`` or
    ``"floor"`` (plus the first frame).
    """

    name: str
    route: str
    laps: float = 1.0
    start: Point | LapFraction | None = None
    count: str = "round"


@dataclass(frozen=True)
class Spacing:
    """How frames are spaced along the routes.

    * ``"per_lap"``: option ``frames_per_lap`` frames per lap of each session's route;
    * ``"speed"``: ``speed / hz`` metres apart;
    * ``"laps"``: the ``frames`` option (default ``round(laps * frames_per / laps_per)
      + 1``) spread evenly over ``laps`` laps;
    * ``"frames"``: ``speed / hz`` metres apart, ``frames`` frames.
    """

    kind: str
    frames_per: int = 0
    laps_per: int = 1


@dataclass(frozen=True)
class CameraSpec:
    """The tour's default camera (the common options override it)."""

    kind: str
    width: int
    height: int
    cam_height: float
    fov_deg: float | None = None


@dataclass(frozen=True)
class NoiseSpec:
    """The tour's default odometry error model (the common options override it)."""

    scale_error: float
    rot_scale_error: float
    heading_bias: float
    trans_noise: float
    rot_noise: float


@dataclass(frozen=True)
class Leg:
    """A bridge leg driven forward along ``route`` from ``start`` to ``stop`` (None: the
    previous session's end / the next session's start)."""

    route: str
    start: Point | None = None
    stop: Point | None = None


@dataclass(frozen=True)
class TourSpec:
    """A tour as data.

    Attributes:
        name: the tour's name.
        description: one line on what it reproduces (``str.format``-ed with the options).
        options: the tour's own options and their defaults.
        positive: ``(option, offset)``: ``option - offset`` must be positive (None skips).
        world: the floor plan.
        routes: the named routes (shown in plots).
        sessions: the sessions, in the paper's order.
        spacing: how frames are spaced.
        camera, noise: sensor defaults; ``lasers``: lasers on by default.
        main_route: the route pedestrians walk and obstacles stand beside.
        obstacle_size, obstacle_offset, pedestrian_offset, obstacle_height: obstacles (m).
        scale: the world's length scale (pedestrians are ``0.4 * scale`` wide).
        clearance: the least distance from a route or bridge to a wall.
        bridge_routes: routes driven only by bridges.
        bridges: per gap between consecutive sessions, the legs driven.
    """

    name: str
    description: str
    options: Mapping[str, Any]
    positive: tuple[tuple[str, float], ...]
    world: WorldSpec
    routes: Mapping[str, RouteSpec]
    sessions: tuple[SessionSpec, ...]
    spacing: Spacing
    camera: CameraSpec
    noise: NoiseSpec
    lasers: bool
    main_route: str
    obstacle_size: Number = 1.0
    obstacle_offset: Number = 2.0
    pedestrian_offset: Number = 0.7
    obstacle_height: float = 1.8
    scale: float = 1.0
    clearance: Number = 0.1
    bridge_routes: Mapping[str, RouteSpec] = field(default_factory=dict)
    bridges: tuple[tuple[Leg, ...], ...] = ()
