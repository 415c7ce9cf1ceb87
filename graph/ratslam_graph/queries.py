"""Questions asked of an experience map: activity, link components, temporal map, routes.

Each function takes a :class:`MapView`, the read-only arrays of a map
(:meth:`ratslam_graph.experience_map.ExperienceMap.view`), and changes nothing:

    >>> from ratslam_graph.experience_map import ExperienceMap
    >>> from ratslam_graph.messages import Action, ActionKind
    >>> from ratslam_graph.queries import route
    >>> em = ExperienceMap()
    >>> em.apply(Action(ActionKind.CREATE, dest_id=0))
    >>> em.on_odometry(1.0, 0.0, 2.0)
    >>> em.apply(Action(ActionKind.CREATE, dest_id=1))
    >>> route(em.view(), goal=0).ids
    [1, 0]

The equations are the experience-map paper's (:mod:`ratslam_graph.features`).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ratslam_graph import features
from ratslam_graph.errors import GraphError, InputError
from ratslam_graph.features import Route
from ratslam_graph.messages import Action, ActionKind

if TYPE_CHECKING:
    import networkx as nx

__all__ = [
    "MapView",
    "activity",
    "activity_action",
    "link_components",
    "peak_experience",
    "route",
    "temporal_map",
]


@dataclass(frozen=True)
class MapView:
    """The read-only arrays of an experience map (views, not copies: take a new view
    after the map changes).

    Attributes:
        poses: experience poses ``[x, y, th]`` (m, m, rad).
        pc: pose-cell coordinates ``(x', y', th')`` of every experience (cells).
        template_id: the template of every experience.
        src, dst: link ends (creation order).
        link: ``[d, heading, facing, dt]`` of every link.
        meas: ``[dx, dy, dth]`` of every link in its source's frame.
        current_id: the current experience (-1 before the first one).
        zone_xy, zone_th: the activity zone constants (``exp_activity_zone_*``).

    Shape:
        poses, pc: (N, 3); template_id: (N,); src, dst: (E,); link: (E, 4); meas: (E, 3).
    """

    poses: np.ndarray
    pc: np.ndarray
    template_id: np.ndarray
    src: np.ndarray
    dst: np.ndarray
    link: np.ndarray
    meas: np.ndarray
    current_id: int
    zone_xy: float
    zone_th: float

    def check_id(self, i: int | None, what: str) -> int:
        """``i`` (default: the current experience) as an experience id of this map.

        Raises:
            GraphError: no such experience.
        """
        n = len(self.poses)
        i = int(self.current_id if i is None else i)
        if not 0 <= i < n:
            raise GraphError(
                f"{what} experience {i} does not exist (the map has {n}); "
                "the pose cells and the experience map are out of sync"
            )
        return i


def activity(
    view: MapView,
    pc: tuple[float, float, float] | np.ndarray,
    template_id: int,
    *,
    dims: tuple[float, ...] | None = None,
) -> np.ndarray:
    """Experience activity (Eqs. 1-4) with the map's zone constants.

    Args:
        view: the map.
        pc: pose-cell coordinates of the dominant packet (cells).
        template_id: the current template.
        dims: ``(X, Y, TH)`` (or ``(XY, TH)``, a square network) to measure pose-cell
            distances around the wrapping network; None: plain differences as the
            paper prints them.

    Shape:
        pc: (3,). Returns (N,).
    """
    return features.experience_activity(
        view.pc,
        view.template_id,
        np.asarray(pc, dtype=np.float64),
        int(template_id),
        zone_xy=view.zone_xy,
        zone_th=view.zone_th,
        dims=dims,
    )


def peak_experience(
    view: MapView,
    pc: tuple[float, float, float] | np.ndarray,
    template_id: int,
    *,
    dims: tuple[float, ...] | None = None,
) -> tuple[int, float]:
    """The most active experience and its activity (``(-1, 0.0)`` if none is active)."""
    return features.peak_experience(activity(view, pc, template_id, dims=dims))


def activity_action(
    view: MapView,
    pc: tuple[float, float, float] | np.ndarray,
    template_id: int,
    *,
    threshold: float,
    dims: tuple[float, ...] | None = None,
    relative_rad: float = 0.0,
) -> Action:
    """The action of ``exp_create_rule="activity"`` (Eqs. 1-4 of the experience-map paper).

    Every experience's activity comes from its pose-cell distance to the packet and its
    view (:func:`activity`); the most active is the peak experience. A peak below
    ``threshold`` (``exp_activity_threshold``; or no peak) learns a new experience
    (``CREATE``); a peak other than the current experience, and more active than it,
    becomes current (``LINK``); otherwise nothing happens.

    Args:
        view: the map.
        pc: pose-cell coordinates of the dominant packet (cells).
        template_id: the current view template.
        threshold: the activity below which a new experience is learnt.
        dims: ``(X, Y, TH)`` (or ``(XY, TH)``, a square network): distances the short
            way round the wrapping network (None: plain differences).
        relative_rad: the relative view angle the action carries.
    """
    a = activity(view, pc, template_id, dims=dims)
    peak, level = features.peak_experience(a)
    cur, n = view.current_id, len(view.poses)
    if peak < 0 or level < threshold:
        return Action(ActionKind.CREATE, dest_id=n, src_id=cur, relative_rad=relative_rad)
    if cur >= 0 and a[cur] >= level:
        return Action.none()
    return Action(ActionKind.LINK, dest_id=peak, src_id=cur, relative_rad=relative_rad)


def link_components(view: MapView, frame: str = "local") -> np.ndarray:
    """Link transitions ``[dx, dy, dth]`` (creation order).

    Args:
        view: the map.
        frame: ``"local"``: in the source's frame (what is stored); ``"global"``: the
            paper's map-frame ``(dx, dy)``, i.e. the local one rotated by the source's
            current orientation. Map correction that turns a source by ``dth_i`` turns
            its global components by ``dth_i`` (Eq. 8).

    Shape:
        Returns (E, 3).
    """
    m = view.meas.copy()
    if frame == "local":
        return m
    if frame == "global":
        return features.rotate_link_components(m, view.poses[view.src, 2])
    raise InputError(f"frame must be 'local' or 'global', got {frame!r}")


def _undirected(view: MapView) -> nx.Graph:
    import networkx as nx  # only the Dijkstra queries need it

    g = nx.Graph()
    g.add_nodes_from(range(len(view.poses)))
    # one link per pair: no parallel links to resolve
    g.add_weighted_edges_from(zip(view.src.tolist(), view.dst.tolist(), view.link[:, 3].tolist()))
    return g


def temporal_map(
    view: MapView, start: int | None = None, *, method: str = "dijkstra"
) -> np.ndarray:
    """Time from ``start`` to every experience over link times (Eqs. 10-11).

    Args:
        view: the map.
        start: the seeded (peak) experience; default the current one.
        method: ``"dijkstra"`` (networkx) or ``"iterate"`` (the paper's synchronous
            iteration, :func:`ratslam_graph.features.temporal_map`); same result.

    Shape:
        Returns (N,) seconds, ``inf`` where unreachable.
    """
    start = view.check_id(start, "temporal-map start")
    n = len(view.poses)
    if method == "iterate":
        edges = np.stack([view.src, view.dst], axis=1)
        return features.temporal_map(n, edges, view.link[:, 3], start)
    if method != "dijkstra":
        raise InputError(f"method must be 'dijkstra' or 'iterate', got {method!r}")
    import networkx as nx

    dist = nx.single_source_dijkstra_path_length(_undirected(view), start, weight="weight")
    out = np.full(n, np.inf)
    out[np.fromiter(dist.keys(), dtype=np.int64)] = np.fromiter(dist.values(), dtype=np.float64)
    return out


def route(view: MapView, goal: int, start: int | None = None) -> Route:
    """Fastest route from ``start`` (default: current experience) to ``goal``.

    Dijkstra over link times (links traversable both ways); the route lists the
    experiences from start to goal with the estimated time to reach each one.

    Raises:
        GraphError: if the goal cannot be reached from the start.
    """
    start = view.check_id(start, "route start")
    goal = view.check_id(goal, "route goal")
    import networkx as nx

    g = _undirected(view)
    try:
        _, path = nx.single_source_dijkstra(g, start, goal, weight="weight")
    except nx.NetworkXNoPath:
        raise GraphError(
            f"experience {goal} cannot be reached from {start}: no chain of links joins them"
        ) from None
    w = [g.edges[a, b]["weight"] for a, b in itertools.pairwise(path)]
    times = np.concatenate([[0.0], np.cumsum(w)]).tolist()
    return Route(ids=[int(i) for i in path], times=times)
