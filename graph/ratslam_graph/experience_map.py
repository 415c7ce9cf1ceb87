"""The RatSLAM experience map: a networkx graph with array views, relaxed by a backend.

Behaviour follows OpenRatSLAM's ``ExperienceMap`` (``shared/reference/ratslam-algorithm.md``)
plus the experience-map paper's features (``ratslam_graph.features``):

* odometry accumulates ``(x, y, facing, time)`` since the current experience, the facing
  starting at ``exp_initial_em_deg``;
* ``CREATE`` places a new experience at current pose + accumulated displacement and links
  the current experience to it; ``LINK`` links the current experience to an existing one
  (one link per pair, either direction) and makes it current; ``SET`` only makes it
  current. A link stores ``(d, heading, facing)`` relative to its source's orientation
  and a time: OpenRatSLAM's ``accum_delta_time_s``, which it never resets (the time
  since the start of the run; ``exp_link_time="since_start"``), or the time since the
  previous link (``"per_link"``, the project's choice);
* :meth:`ExperienceMap.iterate` runs ``exp_loops`` passes of the configured backend
  (``exp_backend``) on :meth:`ExperienceMap.posegraph` and writes the poses back.

Node poses, pose-cell coordinates, link endpoints and measurements live in preallocated
numpy arrays (grown by doubling) kept in sync with the :class:`networkx.DiGraph`, so
building the pose graph and relaxing never loops over links or nodes in Python; the
graph's node poses are refreshed lazily when :attr:`ExperienceMap.graph` is read.

Example:
    >>> from ratslam_graph.experience_map import ExperienceMap
    >>> from ratslam_graph.messages import Action, ActionKind
    >>> from ratslam_graph.params import ExperienceMapParams
    >>> em = ExperienceMap(ExperienceMapParams(exp_initial_em_deg=0.0))
    >>> em.apply(Action(ActionKind.CREATE, dest_id=0))
    >>> em.on_odometry(1.0, 0.0, 2.0)
    >>> em.apply(Action(ActionKind.CREATE, dest_id=1))
    >>> em.poses[1].tolist()
    [2.0, 0.0, 0.0]
"""

from __future__ import annotations

import itertools
import logging
import math
from typing import Any

import networkx as nx
import numpy as np
from ratslam_graph.errors import GraphError, InputError, MapFormatError
from ratslam_graph.features import (
    Route,
    average_transition,
    experience_activity,
    link_confidence,
    peak_experience,
    rotate_link_components,
    temporal_map,
)
from ratslam_graph.geometry import inverse, wrap_angle
from ratslam_graph.messages import Action, ActionKind
from ratslam_graph.params import ExperienceMapParams
from ratslam_graph.posegraph import PoseGraph
from ratslam_graph.protocols import RelaxationBackend

__all__ = ["ExperienceMap", "Route"]

log = logging.getLogger(__name__)

STATE_FORMAT = "ratslam_graph.experience_map"
STATE_VERSION = 1


def _grow(a: np.ndarray, need: int) -> np.ndarray:
    """Return ``a`` with at least ``need`` rows (doubling), keeping its content."""
    if need <= len(a):
        return a
    cap = max(need, 2 * len(a), 16)
    out = np.zeros((cap, *a.shape[1:]), dtype=a.dtype)
    out[: len(a)] = a
    return out


def _measurement_of(d: float, heading: float, facing: float) -> tuple[float, float, float]:
    """A RatSLAM link ``(d, heading, facing)`` as a Pose2 between ``[dx, dy, dth]``."""
    return d * math.cos(heading), d * math.sin(heading), facing


class ExperienceMap:
    """RatSLAM experience map (OpenRatSLAM behaviour + the experience-map paper's features).

    Args:
        params: experience-map parameters (default: OpenRatSLAM's).
        backend: a relaxation backend object with ``relax(pg, *, passes, correction)``;
            None builds
                ``ratslam_graph.backends.make_backend(params.exp_backend)`` on first use.

    Attributes:
        params: the parameters.
        current_id: the current experience (-1 before the first one).
        prev_id: the previous current experience (-1 if none).
        accum_x, accum_y, accum_facing, accum_time: odometry accumulated since the
            current experience (m, m, rad, s).
        relative_rad: relative view angle given with the last set-current.
    """

    _LINK_FIELDS = ("src", "dst", "link", "meas", "counts", "behaviour")

    relax_tol = 1e-12
    """Relative early-stop tolerance for backends that take ``tol`` (the alpha rule):
    a relaxation whose first pass moves no coordinate by more than ``relax_tol`` times
    the map's extent (at least 1 m) stops there, and the next relaxations are skipped
    until the map changes. 0 stops only on bit-identical fixed points."""

    def __init__(
        self,
        params: ExperienceMapParams | None = None,
        *,
        backend: RelaxationBackend | None = None,
    ) -> None:
        self.params = params if params is not None else ExperienceMapParams()
        self._backend = backend
        self._clear()

    # ------------------------------------------------------------------ storage
    def _clear(self) -> None:
        self._n = 0
        self._relax_cursor = 0  # exp_relax_budget: the link the next relaxation starts at
        self._e = 0
        self._pose = np.zeros((0, 3))
        self._pc = np.zeros((0, 3))
        self._vt = np.zeros(0, dtype=np.int64)
        self._frame = np.zeros(0, dtype=np.int64)
        self._t = np.zeros(0)
        self._src = np.zeros(0, dtype=np.int64)
        self._dst = np.zeros(0, dtype=np.int64)
        self._link = np.zeros((0, 4))  # d, heading, facing, dt
        self._meas = np.zeros((0, 3))  # dx, dy, dth in the source's frame
        self._counts = np.zeros((0, 3), dtype=np.int64)  # traversals, successes, trials
        self._behaviour = np.zeros(0, dtype=np.int64)
        self._eidx: dict[tuple[int, int], int] = {}
        self._g = nx.DiGraph()
        self._dirty_edges: set[int] = set()  # links whose graph attributes are stale
        self._dirty_nodes: set[int] = set()  # experiences whose graph attributes are stale
        self._poses_dirty = False
        self._order: np.ndarray | None = None
        self._links_version = 0  # bumped by every change of the links
        self._ref_links: tuple | None = None  # (links version, src, dst, link) in ref order
        self._version = 0  # bumped by every change of poses or links
        self._fixed_at: tuple | None = None  # (version, params, backend) of a fixed point
        self.current_id = -1
        self.prev_id = -1
        self.accum_x = 0.0
        self.accum_y = 0.0
        self.accum_facing = math.radians(self.params.exp_initial_em_deg)
        self.accum_time = 0.0
        self.relative_rad = 0.0

    def reset(self) -> None:
        """Forget every experience and link; accumulators back to their initial values."""
        self._clear()
        self._reset_backend()

    def _reset_backend(self) -> None:
        reset = getattr(self._backend, "reset", None)
        if callable(reset):
            reset()

    def __len__(self) -> int:
        return self._n

    @property
    def num_links(self) -> int:
        """Number of links."""
        return self._e

    @property
    def poses(self) -> np.ndarray:
        """Experience poses ``[x, y, th]`` (read-only view; row = experience id).

        Shape:
            (N, 3).
        """
        v = self._pose[: self._n].view()
        v.flags.writeable = False
        return v

    @property
    def graph(self) -> nx.DiGraph:
        """The map as a :class:`networkx.DiGraph` (nodes: experiences; edges: links).

        Node attributes: ``x, y, th, pc (x', y', th' cells), template_id, frame, t``.
        Edge attributes: ``d, heading, facing, dt, traversals, successes, trials,
        behaviour, confidence``. Treat it as read-only: change the map through the
        methods so the arrays stay in sync.
        """
        if self._dirty_nodes:
            nodes = self._g.nodes
            for i in sorted(self._dirty_nodes):
                nodes[i].update(self._node_attrs(i))
            self._dirty_nodes.clear()
        if self._dirty_edges:
            self._flush_edges()
        if self._poses_dirty:
            p = self._pose[: self._n].tolist()
            nx.set_node_attributes(
                self._g, {i: {"x": x, "y": y, "th": th} for i, (x, y, th) in enumerate(p)}
            )
            self._poses_dirty = False
        return self._g

    def _check_id(self, i: int, what: str) -> int:
        i = int(i)
        if not 0 <= i < self._n:
            raise GraphError(
                f"{what} experience {i} does not exist (the map has {self._n}); "
                "the pose cells and the experience map are out of sync"
            )
        return i

    # ------------------------------------------------------------- low level
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
        pcv = np.asarray(pc, dtype=np.float64).reshape(-1)
        if pcv.shape != (3,) or not (
            all(map(math.isfinite, pose)) and all(map(math.isfinite, pcv.tolist()))
        ):
            raise InputError(
                f"experience needs finite x, y, th and 3 pose-cell coordinates, got {pose}, {pcv}"
            )
        i = self._n
        need = i + 1
        self._pose = _grow(self._pose, need)
        self._pc = _grow(self._pc, need)
        self._vt = _grow(self._vt, need)
        self._frame = _grow(self._frame, need)
        self._t = _grow(self._t, need)
        self._pose[i] = pose
        self._pc[i] = pcv
        self._vt[i] = int(template_id)
        self._frame[i] = int(frame)
        self._t[i] = float(t)
        self._n = need
        self._version += 1
        self._g.add_node(i)  # its attributes are written when the graph is read
        self._dirty_nodes.add(i)
        return i

    def _node_attrs(self, i: int) -> dict[str, Any]:
        x, y, th = self._pose[i].tolist()
        return {
            "x": x,
            "y": y,
            "th": th,
            "pc": tuple(self._pc[i].tolist()),
            "template_id": int(self._vt[i]),
            "frame": int(self._frame[i]),
            "t": float(self._t[i]),
        }

    def _edge_attrs(self, k: int) -> dict[str, Any]:
        d, heading, facing, dt = self._link[k].tolist()
        trav, succ, trials = self._counts[k].tolist()
        return {
            "d": d,
            "heading": heading,
            "facing": facing,
            "dt": dt,
            "traversals": trav,
            "successes": succ,
            "trials": trials,
            "behaviour": int(self._behaviour[k]),
            "confidence": float(link_confidence(succ, trials)),
        }

    def _set_link_values(self, k: int, d: float, heading: float, facing: float, dt: float) -> None:
        self._link[k] = (d, heading, facing, dt)
        self._meas[k] = _measurement_of(d, heading, facing)
        self._version += 1
        self._links_version += 1

    def _sync_edge(self, k: int) -> None:
        """Mark link ``k``'s attributes for the graph (written when :attr:`graph` is read)."""
        self._dirty_edges.add(k)

    def _flush_edges(self) -> None:
        for k in sorted(self._dirty_edges):
            self._g.edges[int(self._src[k]), int(self._dst[k])].update(self._edge_attrs(k))
        self._dirty_edges.clear()

    def link_index(self, a: int, b: int) -> int:
        """Row of the link between ``a`` and ``b`` in either direction, or -1."""
        k = self._eidx.get((int(a), int(b)))
        if k is None:
            k = self._eidx.get((int(b), int(a)), -1)
        return k

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
    ) -> bool:
        """Add a link ``src -> dst`` unless the pair is already linked (either direction).

        Args:
            src, dst: experience ids.
            d: distance (m); heading, facing: relative to ``src``'s orientation (rad).
            dt: elapsed time of the transition (s).
            behaviour: movement behaviour label ``beta_ij`` of Eq. 9.
            counts: initial ``(traversals, successes, trials)`` (Eq. 9's ``n_ij`` and
                ``n_i,beta``).

        Returns:
            True if a link was added, False if the pair was already linked.
        """
        src = self._check_id(src, "link source")
        dst = self._check_id(dst, "link target")
        if src == dst:
            raise GraphError(f"cannot link experience {src} to itself")
        if self.link_index(src, dst) >= 0:
            return False
        vals = np.array([d, heading, facing, dt], dtype=np.float64)
        if not np.all(np.isfinite(vals)) or d < 0:
            raise InputError(
                f"link needs finite d >= 0, heading, facing and dt, got {vals.tolist()}"
            )
        k = self._e
        need = k + 1
        before = self._links_version
        for name in self._LINK_FIELDS:
            setattr(self, f"_{name}", _grow(getattr(self, f"_{name}"), need))
        self._src[k] = src
        self._dst[k] = dst
        self._set_link_values(
            k,
            float(d),
            wrap_angle(float(heading), include_pi=True),
            wrap_angle(float(facing), include_pi=True),
            float(dt),
        )
        self._counts[k] = counts
        self._behaviour[k] = int(behaviour)
        self._e = need
        self._eidx[(src, dst)] = k
        self._g.add_edge(src, dst)  # its attributes are written when the graph is read
        self._dirty_edges.add(k)
        self._append_reference(k, before)
        return True

    def _append_reference(self, k: int, before: int) -> None:
        """Insert new link ``k`` into the cached reference order (by source, then
        creation) instead of sorting again: O(E) copies, no sort; the cache is dropped
        when it was not current before the link was added."""
        cached = self._ref_links
        order = self._order
        if cached is None or order is None or cached[0] != before or len(order) != k:
            self._order = None
            return
        src = int(self._src[k])
        # after every link of a source <= src: creation order within a source
        at = int(np.searchsorted(cached[1], src, side="right"))
        self._order = np.insert(order, at, k)
        self._ref_links = (
            self._links_version,
            np.insert(cached[1], at, src),
            np.insert(cached[2], at, int(self._dst[k])),
            np.insert(cached[3], at, self._link[k, :3], axis=0),
        )

    def remove_link(self, src: int, dst: int) -> None:
        """Delete the link ``src -> dst`` (exact direction); later links shift down one row."""
        k = self._eidx.get((int(src), int(dst)))
        if k is None:
            raise GraphError(f"there is no link {src} -> {dst} to remove")
        self._flush_edges()  # rows shift below
        e = self._e
        for name in self._LINK_FIELDS:
            a = getattr(self, f"_{name}")
            a[k : e - 1] = a[k + 1 : e]
        self._e = e - 1
        self._g.remove_edge(int(src), int(dst))
        self._version += 1
        self._links_version += 1
        s, d = self._src[: self._e].tolist(), self._dst[: self._e].tolist()
        self._eidx = {(a, b): i for i, (a, b) in enumerate(zip(s, d))}
        self._order = None

    # ------------------------------------------------------------- odometry
    def on_odometry(self, vtrans: float, vrot: float, dt: float) -> None:
        """Accumulate odometry since the current experience (OpenRatSLAM's ``on_odo``).

        Args:
            vtrans: forward speed (m/s).
            vrot: turn rate (rad/s, counter-clockwise).
            dt: interval (s).
        """
        step = vtrans * dt
        self.accum_facing = wrap_angle(self.accum_facing + vrot * dt, include_pi=True)
        self.accum_x += step * math.cos(self.accum_facing)
        self.accum_y += step * math.sin(self.accum_facing)
        self.accum_time += dt

    def _measurement(self, src: int, relative_rad: float) -> tuple[float, float, float]:
        """The accumulated transition as a link of ``src``: ``(d, heading, facing)``."""
        th = float(self._pose[src, 2])
        d = math.hypot(self.accum_x, self.accum_y)
        # wrap_angle's float path (no numpy): bit-identical to the reference's clip_rad_180
        heading = wrap_angle(math.atan2(self.accum_y, self.accum_x) - th, include_pi=True)
        facing = wrap_angle(
            wrap_angle(self.accum_facing + relative_rad, include_pi=True) - th, include_pi=True
        )
        return d, float(heading), float(facing)

    # --------------------------------------------------------------- actions
    def apply(
        self,
        action: Action,
        *,
        frame: int = -1,
        t: float = 0.0,
        pc: tuple[float, float, float] | np.ndarray = (0.0, 0.0, 0.0),
        template_id: int = -1,
        behaviour: int = 0,
    ) -> None:
        """Execute a pose-cell action (create / link / set), as OpenRatSLAM does.

        Args:
            action: the pose cells' decision.
            frame, t: frame index and time, stored on a created experience.
            pc: pose-cell coordinates of a created experience (cells).
            template_id: template of a created experience.
            behaviour: movement behaviour of the transition (Eq. 9); 0 when unused.
        """
        kind = ActionKind(action.kind)
        if kind == ActionKind.NONE:
            return
        if kind == ActionKind.CREATE:
            if action.dest_id not in (-1, self._n):
                raise GraphError(
                    f"CREATE asks for experience {action.dest_id} but the next id is {self._n}; "
                    "the pose cells and the experience map are out of sync"
                )
            self.create_experience(
                pc=pc, template_id=template_id, frame=frame, t=t, behaviour=behaviour
            )
        elif kind == ActionKind.LINK:
            self.link_to(action.dest_id, action.relative_rad, behaviour=behaviour)
        else:
            self.set_current(action.dest_id, action.relative_rad, behaviour=behaviour)

    def create_experience(
        self,
        *,
        pc: tuple[float, float, float] | np.ndarray = (0.0, 0.0, 0.0),
        template_id: int = -1,
        frame: int = -1,
        t: float = 0.0,
        behaviour: int = 0,
    ) -> int:
        """``CREATE``: new experience at current pose + accumulated delta, linked, current.

        The first experience sits at the accumulated ``(accum_x, accum_y,
        wrap(accum_facing))`` and the accumulators run on (OpenRatSLAM, whose
        ``on_set_experience(0, 0)`` returns early), or with ``exp_first_at_origin`` at
        ``(0, 0, wrap(accum_facing))`` with the accumulators restarted there. Later ones at
        ``(x_cur + accum_x, y_cur + accum_y, wrap(accum_facing))`` with a link from the
        current experience (measured from the accumulators; its time as
        ``exp_link_time`` says).

        Returns:
            The new experience id.
        """
        cur = self.current_id
        first_at_origin = self.params.exp_first_at_origin
        if cur < 0:
            x, y = (0.0, 0.0) if first_at_origin else (self.accum_x, self.accum_y)
        else:
            x = float(self._pose[cur, 0]) + self.accum_x
            y = float(self._pose[cur, 1]) + self.accum_y
        new = self.add_experience(
            x,
            y,
            wrap_angle(self.accum_facing, include_pi=True),
            pc=pc,
            template_id=template_id,
            frame=frame,
            t=t,
        )
        if cur >= 0:
            self._transition(cur, new, behaviour)
            self._link_from_accumulators(cur, new, 0.0, behaviour)
        elif not first_at_origin:
            # OpenRatSLAM: its current id starts at 0, so on_set_experience(0, 0) returns
            # at once and the accumulators run on from where they are
            self.current_id = new
            return new
        self._make_current(new, 0.0)
        return new

    def _link_from_accumulators(
        self, src: int, dst: int, relative_rad: float, behaviour: int
    ) -> bool:
        d, heading, facing = self._measurement(src, relative_rad)
        added = self.add_link(src, dst, d, heading, facing, self.accum_time, behaviour=behaviour)
        if added and self.params.exp_link_time == "per_link":
            self.accum_time = 0.0
        return added

    def link_to(self, dest: int, relative_rad: float = 0.0, *, behaviour: int = 0) -> bool:
        """``LINK``: link current -> ``dest`` (unless the pair is linked) and make it current.

        With ``exp_link_averaging`` a repeated transition is averaged into the existing
        link (Eq. 6).

        Returns:
            True if a new link was made.
        """
        dest = self._check_id(dest, "LINK target")
        cur = self.current_id
        added = False
        if cur >= 0 and cur != dest:
            self._repeat_or_count(cur, dest, relative_rad, behaviour)
            added = self._link_from_accumulators(cur, dest, relative_rad, behaviour)
        self._make_current(dest, relative_rad)
        return added

    def set_current(self, dest: int, relative_rad: float = 0.0, *, behaviour: int = 0) -> None:
        """``SET``: make ``dest`` current; accumulators restart from its pose.

        Nothing happens when ``dest`` is already current. Otherwise ``accum_x = accum_y
        = 0`` and ``accum_facing = wrap(th_dest + relative_rad)``; the elapsed time is
        kept (OpenRatSLAM never resets it; ``exp_link_time="per_link"`` restarts it when
        a link is made). The move counts as a
        transition for Eq. 9 and, with ``exp_link_averaging``, is averaged into the link
        between the two experiences if there is one (Eq. 6).
        """
        dest = self._check_id(dest, "SET target")
        if dest != self.current_id and self.current_id >= 0:
            self._repeat_or_count(self.current_id, dest, relative_rad, behaviour)
        self._make_current(dest, relative_rad)

    def _make_current(self, dest: int, relative_rad: float) -> None:
        """OpenRatSLAM's ``on_set_experience`` (no bookkeeping)."""
        if dest == self.current_id:
            return
        self.prev_id = self.current_id
        self.current_id = dest
        self.accum_x = 0.0
        self.accum_y = 0.0
        self.accum_facing = wrap_angle(float(self._pose[dest, 2]) + relative_rad, include_pi=True)
        self.relative_rad = float(relative_rad)

    def _repeat_or_count(self, cur: int, dest: int, relative_rad: float, behaviour: int) -> None:
        """Bookkeeping of a transition ``cur -> dest`` between existing experiences."""
        k = self.link_index(cur, dest)
        if k >= 0 and self.params.exp_link_averaging:
            self._average_into(k, cur, relative_rad)
        self._transition(cur, dest, behaviour)

    def _average_into(self, k: int, cur: int, relative_rad: float) -> None:
        """Average the accumulated transition into link ``k`` (Eq. 6)."""
        d, heading, facing = self._measurement(cur, relative_rad)
        meas = np.array([d * math.cos(heading), d * math.sin(heading), facing])
        if int(self._src[k]) != cur:  # the link runs the other way: express it from its source
            meas = inverse(meas, include_pi=True)
        new = average_transition(self._meas[k], meas)
        dt = 0.5 * (float(self._link[k, 3]) + self.accum_time)
        self._set_link_values(
            k, math.hypot(new[0], new[1]), math.atan2(new[1], new[0]), float(new[2]), dt
        )
        if self.params.exp_link_time == "per_link":
            self.accum_time = 0.0
        self._sync_edge(k)

    def _transition(self, src: int, dst: int, behaviour: int) -> None:
        """Count a transition for Eq. 9 and delete links whose confidence fell too low.

        Every link leaving ``src`` with the same behaviour had a trial; the one to
        ``dst`` succeeded, the others failed. The link between the pair (either
        direction) counts a traversal.
        """
        k_pair = self.link_index(src, dst)
        # the links leaving src (a node's few out-links, not the map's links)
        eidx, beh, dsts, counts = self._eidx, self._behaviour, self._dst, self._counts
        out = [eidx[(src, v)] for v in self._g.successors(src)]
        rows = [k for k in out if beh[k] == behaviour]
        for k in rows:
            counts[k, 2] += 1
            if dsts[k] == dst:
                counts[k, 1] += 1
        if k_pair >= 0:
            counts[k_pair, 0] += 1
            self._dirty_edges.add(k_pair)
        self._dirty_edges.update(rows)
        thr = self.params.exp_link_confidence_threshold
        if thr > 0.0 and rows:
            sel = np.array(rows, dtype=np.int64)
            conf = link_confidence(self._counts[sel, 1], self._counts[sel, 2])
            doomed = [(src, int(v)) for v in self._dst[sel[conf < thr]]]
            for a, b in doomed:
                self.remove_link(a, b)

    # ------------------------------------------------------------ relaxation
    def _reference_order(self) -> np.ndarray:
        """OpenRatSLAM's relaxation order: by source experience, then link creation (cached)."""
        if self._order is None or len(self._order) != self._e:
            self._order = np.argsort(self._src[: self._e], kind="stable")
        return self._order

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
        e = self._e
        if order == "reference":
            idx = self._reference_order()
            edges = np.stack([self._src[:e][idx], self._dst[:e][idx]], axis=1)
            meas = self._meas[:e][idx]
        elif order == "creation":
            edges = np.stack([self._src[:e], self._dst[:e]], axis=1)
            meas = self._meas[:e]
        else:
            raise InputError(f"order must be 'reference' or 'creation', got {order!r}")
        return PoseGraph(self._pose[: self._n], edges, meas, np.arange(self._n, dtype=np.int64))

    @property
    def backend(self) -> RelaxationBackend:
        """The relaxation backend (built from ``exp_backend`` on first use)."""
        if self._backend is None:
            from ratslam_graph.backends import make_backend

            name = self.params.exp_backend
            if name == "alpha":
                self._backend = make_backend(name, schedule=self.params.exp_relax_order)
            else:
                self._backend = make_backend(name)
        return self._backend

    def _reference_links(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Link ends and ``(d, heading, facing)`` in OpenRatSLAM's order (cached)."""
        cached = self._ref_links
        if cached is None or cached[0] != self._links_version or len(cached[1]) != self._e:
            idx = self._reference_order()
            e = self._e
            cached = (
                self._links_version,
                np.ascontiguousarray(self._src[:e][idx]),
                np.ascontiguousarray(self._dst[:e][idx]),
                np.ascontiguousarray(self._link[:e, :3][idx]),
            )
            self._ref_links = cached
        return cached[1], cached[2], cached[3]

    def iterate(self) -> None:
        """Relax the map: ``exp_loops`` passes of the backend, poses written back.

        A map with fewer than two experiences or no link is left as it is, and so is
        every map when ``exp_loops`` is 0 and the backend is the alpha rule.

        With ``exp_backend="alpha"`` and ``exp_relax_order="openratslam"`` (the
        defaults) this is OpenRatSLAM's ``iterate()``, compiled, in place: the links in
        its order, its arithmetic; a pass that changes nothing ends the relaxation and
        later calls are skipped until poses or links change (exact: the result is
        bit-identical to running every pass). With ``exp_relax_order="colour"`` a
        relaxation whose first pass moves nothing by more than :attr:`relax_tol`
        (relative) stops there (the map is at the sweep's fixed point to rounding), and
        later calls are skipped until poses or links change. This is a deliberate
        deviation from always running ``exp_loops`` passes: the map differs from the
        always-run one by rounding noise only (tested to 1e-9); set ``relax_tol = 0`` to
        disable it. With ``exp_backend="alpha_local"`` the backend's ``relax_inplace``
        relaxes the map's own arrays only where the map changed since its last call.
        """
        loops = self.params.exp_loops
        alpha = self.params.exp_backend.startswith("alpha")
        if self._n < 2 or self._e == 0 or (loops == 0 and alpha):
            return
        backend = self.backend
        key = (self._version, id(self.params), id(backend))
        if self._fixed_at == key:
            return
        if alpha and getattr(backend, "schedule", None) == "openratslam":
            # OpenRatSLAM's loop, compiled, in place on the map's own arrays
            # (the arrays are the map's own: float64, C-contiguous, int64 ends)
            from ratslam_graph.backends._sweep import sweep

            src, dst, link = self._reference_links()
            budget = self.params.exp_relax_budget
            if budget and loops * len(src) > budget:
                # a bounded number of updates, on round the links (exp_relax_budget)
                from ratslam_graph.backends._sweep import sweep_window

                self._relax_cursor, moved = sweep_window(
                    self._pose,
                    src,
                    dst,
                    link,
                    self._relax_cursor,
                    budget,
                    float(self.params.exp_correction),
                )
                self._poses_dirty = True
                self._version += 1
                if not moved and budget >= len(src):  # a whole pass changed nothing
                    self._fixed_at = (self._version, id(self.params), id(backend))
                return
            self._relax_cursor = 0
            ran = sweep(self._pose, src, dst, link, loops, float(self.params.exp_correction))
            self._poses_dirty = True
            self._version += 1
            if ran < loops:  # a pass changed nothing: the map is at its fixed point
                self._fixed_at = (self._version, id(self.params), id(backend))
            else:
                self._log_not_converged(loops)
            return
        relax_inplace = getattr(backend, "relax_inplace", None)
        if callable(relax_inplace):
            # alpha_local: the map's own arrays, relaxed only where the map changed, so
            # the cost follows the change, not the map's size (no O(N) work here)
            n, e = self._n, self._e
            relax_inplace(
                self._pose[:n],
                self._src[:e],
                self._dst[:e],
                self._link[:e],
                passes=loops,
                correction=self.params.exp_correction,
                budget=self.params.exp_relax_budget,
            )
            self._poses_dirty = True
            self._version += 1
            if getattr(backend, "last_converged", False):
                self._fixed_at = (self._version, id(self.params), id(backend))
            return
        pg = self.posegraph()
        kw: dict[str, float] = {"correction": self.params.exp_correction}
        if getattr(backend, "accepts_tol", False):
            extent = float(np.abs(self._pose[: self._n, :2]).max())
            kw["tol"] = self.relax_tol * max(1.0, extent)
        new = np.asarray(backend.relax(pg, passes=loops, **kw), dtype=np.float64)
        if new.shape != (self._n, 3) or not np.all(np.isfinite(new)):
            raise GraphError(
                f"backend {self.params.exp_backend!r} returned poses of shape {new.shape} "
                f"(expected ({self._n}, 3), finite); check the backend"
            )
        self._pose[: self._n, :2] = new[:, :2]
        self._pose[: self._n, 2] = wrap_angle(new[:, 2], include_pi=True)
        self._poses_dirty = True
        self._version += 1
        if getattr(backend, "last_converged", False):
            self._fixed_at = (self._version, id(self.params), id(backend))
        elif alpha:
            self._log_not_converged(loops)

    def _log_not_converged(self, loops: int) -> None:
        if log.isEnabledFor(logging.DEBUG):
            log.debug(
                "relaxation: %d passes of %r did not reach a fixed point (%d experiences)",
                loops,
                self.params.exp_backend,
                self._n,
            )

    # -------------------------------------------------------------- queries
    def links(self) -> dict[str, np.ndarray]:
        """Every link as arrays (creation order): ``src, dst, d, heading, facing, dt,
        traversals, successes, trials, behaviour, confidence``, each (E,)."""
        e = self._e
        c = self._counts[:e]
        return {
            "src": self._src[:e].copy(),
            "dst": self._dst[:e].copy(),
            "d": self._link[:e, 0].copy(),
            "heading": self._link[:e, 1].copy(),
            "facing": self._link[:e, 2].copy(),
            "dt": self._link[:e, 3].copy(),
            "traversals": c[:, 0].copy(),
            "successes": c[:, 1].copy(),
            "trials": c[:, 2].copy(),
            "behaviour": self._behaviour[:e].copy(),
            "confidence": link_confidence(c[:, 1], c[:, 2]),
        }

    def link_components(self, frame: str = "local") -> np.ndarray:
        """Link transitions ``[dx, dy, dth]`` (creation order).

        Args:
            frame: ``"local"``: in the source's frame (what is stored); ``"global"``: the
                paper's map-frame ``(dx, dy)``, i.e. the local one rotated by the source's
                current orientation. Map correction that turns a source by ``dth_i`` turns
                its global components by ``dth_i`` (Eq. 8).

        Shape:
            Returns (E, 3).
        """
        m = self._meas[: self._e].copy()
        if frame == "local":
            return m
        if frame == "global":
            return rotate_link_components(m, self._pose[self._src[: self._e], 2])
        raise InputError(f"frame must be 'local' or 'global', got {frame!r}")

    def pose_cells(self) -> np.ndarray:
        """Pose-cell coordinates ``(x', y', th')`` of every experience.

        Shape:
            Returns (N, 3).
        """
        return self._pc[: self._n].copy()

    def template_ids(self) -> np.ndarray:
        """Template id of every experience, (N,)."""
        return self._vt[: self._n].copy()

    def activity(
        self,
        pc: tuple[float, float, float] | np.ndarray,
        template_id: int,
        *,
        dims: tuple[float, float] | None = None,
    ) -> np.ndarray:
        """Experience activity (Eqs. 1-4) with the zone constants ``exp_activity_zone_*``.

        Args:
            pc: pose-cell coordinates of the dominant packet (cells).
            template_id: the current template.
            dims: ``(pc_dim_xy, pc_dim_th)`` to measure pose-cell distances around the
                wrapping network; None: plain differences as the paper prints them.

        Shape:
            pc: (3,). Returns (N,).
        """
        return experience_activity(
            self._pc[: self._n],
            self._vt[: self._n],
            np.asarray(pc, dtype=np.float64),
            int(template_id),
            zone_xy=self.params.exp_activity_zone_xy,
            zone_th=self.params.exp_activity_zone_th,
            dims=dims,
        )

    def peak_experience(
        self,
        pc: tuple[float, float, float] | np.ndarray,
        template_id: int,
        *,
        dims: tuple[float, float] | None = None,
    ) -> tuple[int, float]:
        """The most active experience and its activity (``(-1, 0.0)`` if none is active)."""
        return peak_experience(self.activity(pc, template_id, dims=dims))

    def _undirected(self) -> nx.Graph:
        g = nx.Graph()
        g.add_nodes_from(range(self._n))
        e = self._e
        w = self._link[:e, 3]
        # one link per pair: no parallel links to resolve
        g.add_weighted_edges_from(zip(self._src[:e].tolist(), self._dst[:e].tolist(), w.tolist()))
        return g

    def temporal_map(self, start: int | None = None, *, method: str = "dijkstra") -> np.ndarray:
        """Time from ``start`` to every experience over link times (Eqs. 10-11).

        Args:
            start: the seeded (peak) experience; default the current one.
            method: ``"dijkstra"`` (networkx) or ``"iterate"`` (the paper's synchronous
                iteration, :func:`ratslam_graph.features.temporal_map`); same result.

        Shape:
            Returns (N,) seconds, ``inf`` where unreachable.
        """
        start = self._check_id(self.current_id if start is None else start, "temporal-map start")
        if method == "iterate":
            edges = np.stack([self._src[: self._e], self._dst[: self._e]], axis=1)
            return temporal_map(self._n, edges, self._link[: self._e, 3], start)
        if method != "dijkstra":
            raise InputError(f"method must be 'dijkstra' or 'iterate', got {method!r}")
        dist = nx.single_source_dijkstra_path_length(self._undirected(), start, weight="weight")
        out = np.full(self._n, np.inf)
        out[np.fromiter(dist.keys(), dtype=np.int64)] = np.fromiter(dist.values(), dtype=np.float64)
        return out

    def route(self, goal: int, start: int | None = None) -> Route:
        """Fastest route from ``start`` (default: current experience) to ``goal``.

        Dijkstra over link times (links traversable both ways); the route lists the
        experiences from start to goal with the estimated time to reach each one.

        Raises:
            GraphError: if the goal cannot be reached from the start.
        """
        start = self._check_id(self.current_id if start is None else start, "route start")
        goal = self._check_id(goal, "route goal")
        g = self._undirected()
        try:
            _, path = nx.single_source_dijkstra(g, start, goal, weight="weight")
        except nx.NetworkXNoPath:
            raise GraphError(
                f"experience {goal} cannot be reached from {start}: no chain of links joins them"
            ) from None
        w = [g.edges[a, b]["weight"] for a, b in itertools.pairwise(path)]
        times = np.concatenate([[0.0], np.cumsum(w)]).tolist()
        return Route(ids=[int(i) for i in path], times=times)

    # ---------------------------------------------------------------- state
    def get_state(self) -> dict[str, Any]:
        """Everything needed to restore the map exactly: numpy arrays and Python scalars."""
        n, e = self._n, self._e
        return {
            "format": STATE_FORMAT,
            "version": STATE_VERSION,
            "poses": self._pose[:n].copy(),
            "pc": self._pc[:n].copy(),
            "template_id": self._vt[:n].copy(),
            "frame": self._frame[:n].copy(),
            "t": self._t[:n].copy(),
            "link_ends": np.stack([self._src[:e], self._dst[:e]], axis=1),
            "link_values": self._link[:e].copy(),
            "link_counts": self._counts[:e].copy(),
            "link_behaviour": self._behaviour[:e].copy(),
            "current_id": int(self.current_id),
            "prev_id": int(self.prev_id),
            "accum_x": float(self.accum_x),
            "accum_y": float(self.accum_y),
            "accum_facing": float(self.accum_facing),
            "accum_time": float(self.accum_time),
            "relative_rad": float(self.relative_rad),
            "relax_cursor": int(self._relax_cursor),
        }

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a :meth:`get_state` dictionary (replaces the whole map).

        ``format``, ``version`` and ``relative_rad`` may be absent (importers); every
        other key is required.

        Raises:
            MapFormatError: a key is missing, an array has the wrong shape, a link points
                at a missing experience, or the format/version is not this one. The map is
                left unchanged.
        """
        fmt, version = state.get("format", STATE_FORMAT), state.get("version", STATE_VERSION)
        if fmt != STATE_FORMAT or version != STATE_VERSION:
            raise MapFormatError(
                f"not an experience-map state of version {STATE_VERSION} "
                f"(format={fmt!r}, version={version!r}); save it again with this version"
            )
        try:
            poses = np.array(state["poses"], dtype=np.float64).reshape(-1, 3)
            n = len(poses)
            pc = np.array(state["pc"], dtype=np.float64).reshape(n, 3)
            vt = np.array(state["template_id"], dtype=np.int64).reshape(n)
            frame = np.array(state["frame"], dtype=np.int64).reshape(n)
            t = np.array(state["t"], dtype=np.float64).reshape(n)
            ends = np.array(state["link_ends"], dtype=np.int64).reshape(-1, 2)
            e = len(ends)
            vals = np.array(state["link_values"], dtype=np.float64).reshape(e, 4)
            counts = np.array(state["link_counts"], dtype=np.int64).reshape(e, 3)
            beh = np.array(state["link_behaviour"], dtype=np.int64).reshape(e)
            scalars = {
                k: state[k]
                for k in (
                    "current_id",
                    "prev_id",
                    "accum_x",
                    "accum_y",
                    "accum_facing",
                    "accum_time",
                )
            }
            scalars["relative_rad"] = state.get("relative_rad", 0.0)
        except (KeyError, ValueError) as exc:
            raise MapFormatError(
                f"experience-map state is incomplete or malformed: {exc}"
            ) from None
        if e and (ends.min() < 0 or ends.max() >= n or np.any(ends[:, 0] == ends[:, 1])):
            raise MapFormatError(
                "experience-map state has links to missing experiences or self-links"
            )
        try:
            ids = {k: int(scalars[k]) for k in ("current_id", "prev_id")}
            floats = {
                k: float(scalars[k])
                for k in ("accum_x", "accum_y", "accum_facing", "accum_time", "relative_rad")
            }
        except (TypeError, ValueError) as exc:
            raise MapFormatError(f"experience-map state has a malformed scalar: {exc}") from None
        if not all(-1 <= v < n for v in ids.values()):
            raise MapFormatError("experience-map state has a current/previous id out of range")
        s, d = ends[:, 0].tolist(), ends[:, 1].tolist()
        eidx = {(a, b): i for i, (a, b) in enumerate(zip(s, d))}
        if len(eidx) != e:
            raise MapFormatError(
                "experience-map state links a pair of experiences twice; keep one link per pair"
            )
        self._clear()
        self._reset_backend()
        self._n, self._e = n, e
        self._pose, self._pc, self._vt, self._frame, self._t = poses, pc, vt, frame, t
        self._src, self._dst = ends[:, 0].copy(), ends[:, 1].copy()
        self._link = vals
        # the same scalar formula as at link creation, so measurements round-trip bit for bit
        self._meas = np.array([_measurement_of(*v) for v in vals[:, :3].tolist()]).reshape(e, 3)
        self._counts, self._behaviour = counts, beh
        self._eidx = eidx
        self._g.add_nodes_from((i, self._node_attrs(i)) for i in range(n))
        self._g.add_edges_from((s[k], d[k], self._edge_attrs(k)) for k in range(e))
        self.current_id, self.prev_id = ids["current_id"], ids["prev_id"]
        self.accum_x = floats["accum_x"]
        self.accum_y = floats["accum_y"]
        self.accum_facing = floats["accum_facing"]
        self.accum_time = floats["accum_time"]
        self.relative_rad = floats["relative_rad"]
        self._relax_cursor = int(state.get("relax_cursor", 0))
