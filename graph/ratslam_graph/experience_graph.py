"""The experiences and links of an experience map: growable arrays mirrored by networkx.

:class:`ExperienceGraph` holds node poses, pose-cell coordinates, link endpoints and
measurements in preallocated numpy arrays (grown by doubling) mirrored by a
:class:`networkx.DiGraph` (:class:`~ratslam_graph.graph_mirror.GraphMirror`, brought up
to date when :attr:`ExperienceGraph.graph` is read), so building the pose graph and
relaxing never loops over links or nodes in Python.
:class:`ratslam_graph.experience_map.ExperienceMap` drives it (odometry, pose-cell actions,
relaxation).

Example:
    >>> from ratslam_graph.experience_graph import ExperienceGraph
    >>> g = ExperienceGraph()
    >>> g.add_experience(0.0, 0.0, 0.0), g.add_experience(1.0, 0.0, 0.0)
    (0, 1)
    >>> g.add_link(0, 1, 1.0, 0.0, 0.0, 2.0)
    True
    >>> g.links()["d"].tolist()
    [1.0]
"""

from __future__ import annotations

import itertools
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ratslam_graph import relaxation
from ratslam_graph.errors import GraphError, InputError
from ratslam_graph.features import link_confidence
from ratslam_graph.geometry import wrap_angle
from ratslam_graph.graph_mirror import GraphMirror
from ratslam_graph.posegraph import PoseGraph
from ratslam_graph.queries import MapView

if TYPE_CHECKING:
    import networkx as nx

__all__ = ["ExperienceGraph"]

_LAYOUTS = itertools.count(1)
"""Layout stamps, unique in the process (see :attr:`ExperienceGraph.layout`)."""


def _grow(a: np.ndarray, need: int, fill: int = 0) -> np.ndarray:
    """Return ``a`` with at least ``need`` rows (doubling), keeping its content; new
    rows hold ``fill``."""
    if need <= len(a):
        return a
    cap = max(need, 2 * len(a), 16)
    out = np.full((cap, *a.shape[1:]), fill, dtype=a.dtype)
    out[: len(a)] = a
    return out


def out_lists(src: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Each experience's out-links as a list threaded through the link rows, in creation
    order: the first and last link leaving each experience (-1: none) and each link's
    next link of the same source (-1: the last). Built with numpy, no loop.

    Shape:
        src: (E,). Returns (N, 2) and (E,), int64.
    """
    e = len(src)
    out_ends = np.full((n, 2), -1, dtype=np.int64)
    out_next = np.full(e, -1, dtype=np.int64)
    if e:
        o = np.argsort(src, kind="stable")
        ss = src[o]
        same = ss[1:] == ss[:-1]
        out_next[o[:-1][same]] = o[1:][same]
        first = np.concatenate([[True], ~same])
        last = np.concatenate([~same, [True]])
        out_ends[ss[first], 0] = o[first]
        out_ends[ss[last], 1] = o[last]
    return out_ends, out_next


def _measurement_of(d: float, heading: float, facing: float) -> tuple[float, float, float]:
    """A RatSLAM link ``(d, heading, facing)`` as a Pose2 between ``[dx, dy, dth]``."""
    return d * math.cos(heading), d * math.sin(heading), facing


class ExperienceGraph:
    """Experiences and links in growable arrays, mirrored by a :class:`networkx.DiGraph`.

    The arrays are public for the experience map and the relaxation, which write poses
    and link values in place: rows ``[:n]`` (experiences) and ``[:e]`` (links) are in
    use, the rest is spare capacity. Change the structure (experiences, links) through
    the methods so the index and the graph stay in sync, and call
    :meth:`poses_changed` after writing poses.

    Attributes:
        n, e: number of experiences and of links.
        pose, pc: ``[x, y, th]`` and pose-cell coordinates ``(x', y', th')`` of each
            experience; vt, frame, t: its template, frame index and time at creation.
        src, dst: link ends; link: ``[d, heading, facing, dt]``; meas: ``[dx, dy, dth]``
            in the source's frame; counts: ``(traversals, successes, trials)``;
            behaviour: the movement behaviour label.
        out_ends, out_next: each experience's out-links (:func:`out_lists`).
        edge_dirty: 1 where a link's graph attributes are stale.
        version: bumped by every change of poses or links.
        layout: a stamp unique in the process, renewed when an array is replaced (grown,
            cleared, loaded) or a link is made or changed other than by the compiled
            frame: what is kept of the arrays (the compiled frame's) is valid while it is.
    """

    LINK_FIELDS = ("src", "dst", "link", "meas", "counts", "behaviour", "edge_dirty", "out_next")

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """Forget every experience and link."""
        self.n = 0
        self.e = 0
        self.pose = np.zeros((0, 3))
        self.pc = np.zeros((0, 3))
        self.vt = np.zeros(0, dtype=np.int64)
        self.frame = np.zeros(0, dtype=np.int64)
        self.t = np.zeros(0)
        self.src = np.zeros(0, dtype=np.int64)
        self.dst = np.zeros(0, dtype=np.int64)
        self.link = np.zeros((0, 4))  # d, heading, facing, dt
        self.meas = np.zeros((0, 3))  # dx, dy, dth in the source's frame
        self.counts = np.zeros((0, 3), dtype=np.int64)  # traversals, successes, trials
        self.behaviour = np.zeros(0, dtype=np.int64)
        self.edge_dirty = np.zeros(0, dtype=np.uint8)
        self.out_next = np.zeros(0, dtype=np.int64)
        self.out_ends = np.zeros((0, 2), dtype=np.int64)
        self.version = 0
        self.layout = next(_LAYOUTS)
        self._mirror = GraphMirror()  # the networkx view, updated when read
        self._links_version = 0  # bumped by every change of the links
        # (links version, the links in OpenRatSLAM's order)
        self._ref: tuple[int, relaxation.ReferenceOrder] | None = None

    def __len__(self) -> int:
        return self.n

    def __setstate__(self, state: dict[str, Any]) -> None:
        # a copy or an unpickled graph has arrays of its own: a layout of its own
        self.__dict__.update(state)
        self.layout = next(_LAYOUTS)

    @property
    def poses(self) -> np.ndarray:
        """Experience poses ``[x, y, th]`` (read-only view; row = experience id).

        Shape:
            (N, 3).
        """
        v = self.pose[: self.n].view()
        v.flags.writeable = False
        return v

    def poses_changed(self) -> None:
        """Say that :attr:`pose` was written in place (the graph's poses are stale)."""
        self._mirror.poses_dirty = True
        self.version += 1

    @property
    def graph(self) -> nx.DiGraph:
        """The map as a :class:`networkx.DiGraph` (nodes: experiences; edges: links).

        Node attributes: ``x, y, th, pc (x', y', th' cells), template_id, frame, t``.
        Edge attributes: ``d, heading, facing, dt, traversals, successes, trials,
        behaviour, confidence``. Treat it as read-only: change the map through the
        methods so the arrays stay in sync.
        """
        return self._mirror.read(self)

    def check_id(self, i: int, what: str) -> int:
        """``i`` as an existing experience id (``what`` names it in the error)."""
        i = int(i)
        if not 0 <= i < self.n:
            raise GraphError(
                f"{what} experience {i} does not exist (the map has {self.n}); "
                "the pose cells and the experience map are out of sync"
            )
        return i

    def add_experience(
        self,
        x: float,
        y: float,
        th: float,
        *,
        pc: tuple[float, float, float] | np.ndarray = (0.0, 0.0, 0.0),
        template_id: int = -1,
        frame: int = -1,
        t: float = 0.0,
    ) -> int:
        """Append an experience (no link, current experience unchanged).

        Args:
            x, y, th: map pose (m, m, rad; ``th`` is wrapped to ``(-pi, pi]``).
            pc: pose-cell coordinates ``(x', y', th')`` (cells).
            template_id: the visual template of the experience.
            frame: frame index at creation.
            t: timestamp at creation (s).

        Returns:
            The new experience id (= its row).
        """
        pose = (float(x), float(y), wrap_angle(float(th), include_pi=True))
        if isinstance(pc, tuple) and len(pc) == 3:
            pcv = tuple(map(float, pc))
        else:
            pcv = tuple(np.asarray(pc, dtype=np.float64).reshape(-1).tolist())
        if len(pcv) != 3 or not all(map(math.isfinite, (*pose, *pcv))):
            raise InputError(
                f"experience needs finite x, y, th and 3 pose-cell coordinates, got {pose}, "
                f"{np.asarray(pcv)}"
            )
        i = self.n
        self.reserve(1, 0)
        self.pose[i] = pose
        self.node_added(pcv, template_id, frame, t)
        return i

    def node_added(self, pc: tuple[float, ...], template_id: int, frame: int, t: float) -> None:
        """Record experience ``n`` (its pose already written): its attributes and the
        count (the graph gets the node and its attributes when read)."""
        i = self.n
        self.pc[i] = pc
        self.vt[i] = int(template_id)
        self.frame[i] = int(frame)
        self.t[i] = float(t)
        self.n = i + 1
        self.version += 1

    def link_added(self, ref: relaxation.ReferenceOrder) -> None:
        """Record link ``e``, written with its out-list entry and reference-order place by
        the compiled frame (``ref``, the order it updated, one row longer): the count and
        the cached order, still current (the graph gets the edge when read)."""
        self.e += 1
        self.version += 1
        self._links_version += 1
        ref.n += 1
        self._ref = (self._links_version, ref)

    def reserve(self, nodes: int, links: int) -> None:
        """Make room for ``nodes`` more experiences and ``links`` more links."""
        n, e = self.n + nodes, self.e + links
        for names, need, fill in (
            (("pose", "pc", "vt", "frame", "t"), n, 0),
            (("out_ends",), n, -1),
            (self.LINK_FIELDS, e, 0),
        ):
            if need > len(getattr(self, names[0])):
                for name in names:
                    setattr(self, name, _grow(getattr(self, name), need, fill))
                self.layout = next(_LAYOUTS)

    def reserve_frame(self) -> None:
        """Room for one more experience and link, in the links' OpenRatSLAM order too."""
        self.reserve(1, 1)
        ref = self._reference()
        if ref.n == len(ref.buffers[0]):
            ref.reserve()
            self.layout = next(_LAYOUTS)

    def set_link(self, k: int, d: float, heading: float, facing: float, dt: float) -> None:
        """Write link ``k``'s ``(d, heading, facing, dt)`` and its measurement."""
        self.link[k] = (d, heading, facing, dt)
        self.meas[k] = _measurement_of(d, heading, facing)
        self.edge_dirty[k] = 1
        self.version += 1
        self._links_version += 1
        self.layout = next(_LAYOUTS)  # the cached order is stale, or made current below

    def out_links(self, a: int) -> list[int]:
        """Rows of the links leaving ``a``, in creation order (a node's few links)."""
        rows: list[int] = []
        k = int(self.out_ends[a, 0]) if 0 <= a < self.n else -1
        nxt = self.out_next
        while k >= 0:
            rows.append(k)
            k = int(nxt[k])
        return rows

    def _find(self, a: int, b: int) -> int:
        """Row of the link ``a -> b`` (that direction), or -1."""
        for k in self.out_links(a):
            if self.dst[k] == b:
                return k
        return -1

    def link_index(self, a: int, b: int, *, directed: bool = False) -> int:
        """Row of the link between ``a`` and ``b`` in either direction (``directed``:
        ``a -> b`` only), or -1."""
        k = self._find(int(a), int(b))
        return k if k >= 0 or directed else self._find(int(b), int(a))

    def add_link(
        self,
        src: int,
        dst: int,
        d: float,
        heading: float,
        facing: float,
        dt: float,
        *,
        behaviour: int = 0,
        counts: tuple[int, int, int] = (1, 1, 1),
        directed: bool = False,
    ) -> bool:
        """Add a link ``src -> dst`` unless the pair is already linked (either direction;
        ``directed``: unless ``src -> dst`` is).

        Args:
            src, dst: experience ids.
            d: distance (m); heading, facing: relative to ``src``'s orientation (rad).
            dt: elapsed time of the transition (s).
            behaviour: movement behaviour label ``beta_ij`` of Eq. 9.
            counts: initial ``(traversals, successes, trials)`` (Eq. 9's ``n_ij`` and
                ``n_i,beta``).
            directed: ``exp_link_directed``.

        Returns:
            True if a link was added, False if the pair was already linked.
        """
        src = self.check_id(src, "link source")
        dst = self.check_id(dst, "link target")
        if src == dst:
            raise GraphError(f"cannot link experience {src} to itself")
        if self.link_index(src, dst, directed=directed) >= 0:
            return False
        vals = (float(d), float(heading), float(facing), float(dt))
        if not all(map(math.isfinite, vals)) or vals[0] < 0:
            raise InputError(f"link needs finite d >= 0, heading, facing and dt, got {list(vals)}")
        k = self.e
        before = self._links_version
        self.reserve(0, 1)
        self.src[k] = src
        self.dst[k] = dst
        self.set_link(
            k,
            vals[0],
            wrap_angle(vals[1], include_pi=True),
            wrap_angle(vals[2], include_pi=True),
            vals[3],
        )
        self.counts[k] = counts
        self.behaviour[k] = int(behaviour)
        self.e = k + 1
        ends, self.out_next[k] = self.out_ends, -1
        if ends[src, 0] < 0:
            ends[src, 0] = k
        else:
            self.out_next[ends[src, 1]] = k
        ends[src, 1] = k
        # keep the cached reference order current when it was current before the link
        cached = self._ref
        if cached is None or cached[0] != before or cached[1].n != k:
            self._ref = None
        else:
            cached[1].insert(k, src, dst, self.link[k])
            self._ref = (self._links_version, cached[1])
        return True

    def remove_link(self, src: int, dst: int) -> None:
        """Delete the link ``src -> dst`` (exact direction); later links shift down one row."""
        k = self._find(int(src), int(dst)) if 0 <= int(src) < self.n else -1
        if k < 0:
            raise GraphError(f"there is no link {src} -> {dst} to remove")
        self._mirror.flush_edges(self)  # rows shift below (and the graph holds every link)
        e = self.e
        for name in self.LINK_FIELDS:
            a = getattr(self, name)
            a[k : e - 1] = a[k + 1 : e]
        self.e = e - 1
        self._mirror.remove_edge(src, dst)
        self.version += 1
        self._links_version += 1
        self.layout = next(_LAYOUTS)
        ends, nxt = out_lists(self.src[: self.e], self.n)
        self.out_ends[: self.n] = ends
        self.out_next[: self.e] = nxt
        self._ref = None

    def posegraph(self, order: str = "creation") -> PoseGraph:
        """The map as a :class:`~ratslam_graph.posegraph.PoseGraph`.

        Built from the arrays, no loops.

        Args:
            order: ``"creation"`` lists links as they were made: append-only, which
                incremental backends (iSAM2, the cached colouring of "alpha") rely on;
                the alpha backends sort by source themselves to visit links in
                OpenRatSLAM's order. ``"reference"`` lists them in that order (by
                source experience, then creation).
        """
        e = self.e
        if order == "reference":
            src, dst, _ = self.reference_links()
            edges = np.stack([src, dst], axis=1)
            meas = self.meas[:e][self._reference().order]
        elif order == "creation":
            edges = np.stack([self.src[:e], self.dst[:e]], axis=1)
            meas = self.meas[:e]
        else:
            raise InputError(f"order must be 'reference' or 'creation', got {order!r}")
        return PoseGraph(self.pose[: self.n], edges, meas, np.arange(self.n, dtype=np.int64))

    def reference_links(self) -> relaxation.ReferenceLinks:
        """Link sources, targets and ``(d, heading, facing)`` in OpenRatSLAM's order
        (:func:`ratslam_graph.relaxation.reference_order`; cached, kept current as links
        are added): read-only views, valid until the next change of the links.

        Shape:
            Returns (E,), (E,), (E, 3).
        """
        return self._reference().links

    def _reference(self) -> relaxation.ReferenceOrder:
        cached = self._ref
        if cached is None or cached[0] != self._links_version or cached[1].n != self.e:
            e = self.e
            ref = relaxation.ReferenceOrder(self.src[:e], self.dst[:e], self.link[:e])
            cached = self._ref = (self._links_version, ref)
            self.layout = next(_LAYOUTS)
        return cached[1]

    def links(self) -> dict[str, np.ndarray]:
        """Every link as arrays (creation order): ``src, dst, d, heading, facing, dt,
        traversals, successes, trials, behaviour, confidence``, each (E,)."""
        e = self.e
        c = self.counts[:e]
        return {
            "src": self.src[:e].copy(),
            "dst": self.dst[:e].copy(),
            "d": self.link[:e, 0].copy(),
            "heading": self.link[:e, 1].copy(),
            "facing": self.link[:e, 2].copy(),
            "dt": self.link[:e, 3].copy(),
            "traversals": c[:, 0].copy(),
            "successes": c[:, 1].copy(),
            "trials": c[:, 2].copy(),
            "behaviour": self.behaviour[:e].copy(),
            "confidence": link_confidence(c[:, 1], c[:, 2]),
        }

    def view(self, current_id: int, zone_xy: float, zone_th: float) -> MapView:
        """The arrays in use, read-only (views, no copies), with the map's current
        experience and activity zone constants."""
        n, e = self.n, self.e
        ro = [
            a.view() for a in (self.pose[:n], self.pc[:n], self.vt[:n], self.src[:e], self.dst[:e])
        ] + [self.link[:e].view(), self.meas[:e].view()]
        for v in ro:
            v.flags.writeable = False
        poses, pc, vt, src, dst, link, meas = ro
        return MapView(
            poses=poses,
            pc=pc,
            template_id=vt,
            src=src,
            dst=dst,
            link=link,
            meas=meas,
            current_id=int(current_id),
            zone_xy=float(zone_xy),
            zone_th=float(zone_th),
        )

    def load(self, arrays: dict[str, Any]) -> None:
        """Replace everything with checked state arrays (``poses, pc, template_id, frame,
        t, link_ends, link_values, link_counts, link_behaviour``; the caller has checked
        one link per pair); the out-lists and the graph are rebuilt."""
        self.clear()
        ends, vals = arrays["link_ends"], arrays["link_values"]
        n, e = len(arrays["poses"]), len(ends)
        self.n, self.e = n, e
        self.pose, self.pc, self.vt = arrays["poses"], arrays["pc"], arrays["template_id"]
        self.frame, self.t = arrays["frame"], arrays["t"]
        self.src, self.dst = ends[:, 0].copy(), ends[:, 1].copy()
        self.link = vals
        # the same scalar formula as at link creation, so measurements round-trip bit for bit
        self.meas = np.array([_measurement_of(*v) for v in vals[:, :3].tolist()]).reshape(e, 3)
        self.counts, self.behaviour = arrays["link_counts"], arrays["link_behaviour"]
        self.edge_dirty = np.zeros(e, dtype=np.uint8)
        self.out_ends, self.out_next = out_lists(self.src, n)
        self.layout = next(_LAYOUTS)
        self._mirror.load(self)
