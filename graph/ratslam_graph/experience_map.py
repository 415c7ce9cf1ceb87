"""The RatSLAM experience map: experiences and links in arrays, mirrored by a networkx graph.

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
  (``exp_backend``) and writes the poses back (:mod:`ratslam_graph.relaxation`).

Questions asked of the map (activity, link components, temporal map, routes) are the
functions of :mod:`ratslam_graph.queries`, on :meth:`ExperienceMap.view`.

The experiences and links live in :attr:`ExperienceMap.store`, an
:class:`~ratslam_graph.experience_graph.ExperienceGraph` (numpy arrays mirrored by a
:class:`networkx.DiGraph`), so building the pose graph and relaxing never loops over
links or nodes in Python.

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

import logging
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ratslam_graph import frame_step, link_learning, queries, relaxation
from ratslam_graph.errors import GraphError
from ratslam_graph.experience_graph import ExperienceGraph
from ratslam_graph.geometry import wrap_angle
from ratslam_graph.map_state import map_state, read_map_state
from ratslam_graph.messages import Action, ActionKind
from ratslam_graph.params import ExperienceMapParams
from ratslam_graph.posegraph import PoseGraph
from ratslam_graph.protocols import RelaxationBackend
from ratslam_graph.queries import MapView

if TYPE_CHECKING:
    import networkx as nx

__all__ = ["ExperienceMap"]

log = logging.getLogger(__name__)


def _link_of(x: float, y: float, facing: float, th: float) -> tuple[float, float, float]:
    """An accumulated displacement ``(x, y)`` and facing as a link ``(d, heading, facing)``
    of a source facing ``th``."""
    d = math.hypot(x, y)
    # wrap_angle's float path (no numpy): bit-identical to the reference's clip_rad_180
    heading = wrap_angle(math.atan2(y, x) - th, include_pi=True)
    facing = wrap_angle(wrap_angle(facing, include_pi=True) - th, include_pi=True)
    return d, float(heading), float(facing)


class _Slot:
    """An attribute kept in a float64 (``_fs``) or int64 (``_ist``) array of the map,
    which the compiled frame updates in place; read as a Python float or int."""

    def __init__(self, array: str, index: int) -> None:
        self.array, self.index, self.cast = array, index, float if array == "_fs" else int

    def __get__(self, obj: Any, owner: Any = None) -> Any:
        return self if obj is None else self.cast(getattr(obj, self.array)[self.index])

    def __set__(self, obj: Any, value: float) -> None:
        getattr(obj, self.array)[self.index] = value


class ExperienceMap:
    """RatSLAM experience map (OpenRatSLAM behaviour + the experience-map paper's features).

    Args:
        params: experience-map parameters (default: OpenRatSLAM's).
        backend: a relaxation backend object with ``relax(pg, *, passes, correction)``;
            None builds ``ratslam_graph.backends.make_backend(params.exp_backend)`` on
            first use.

    Attributes:
        params: the parameters.
        store: the experiences and links (add and remove them there directly when
            merging or importing maps).
        current_id: the current experience (-1 before the first one).
        prev_id: the previous current experience (-1 if none).
        accum_x, accum_y, accum_facing, accum_time: odometry accumulated since the
            current experience (m, m, rad, s).
        relative_rad: relative view angle given with the last set-current.
    """

    current_id = _Slot("_ist", 0)
    prev_id = _Slot("_ist", 1)
    accum_x = _Slot("_fs", 0)
    accum_y = _Slot("_fs", 1)
    accum_facing = _Slot("_fs", 2)
    accum_time = _Slot("_fs", 3)
    relative_rad = _Slot("_fs", 4)

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
        self.store = ExperienceGraph()
        self._compiled_for: tuple[tuple[int, int], bool] | None = None
        self._frame_args: frame_step.FrameArgs | None = None  # (frame_step.frame_args)
        self._clear()

    def __getstate__(self) -> dict[str, Any]:
        # a copy or a pickle has arrays of its own: the compiled frame's are made again
        return {**self.__dict__, "_frame_args": None}

    def _clear(self) -> None:
        self.store.clear()  # (a new layout: the compiled frame's arguments are made again)
        self._frame_args = None
        self._relax_cursor = 0  # exp_relax_budget: the link the next relaxation starts at
        self._fixed_at: tuple | None = None  # (version, params, backend) of a fixed point
        self._fs = np.zeros(5)  # accum_x, accum_y, accum_facing, accum_time, relative_rad
        self._ist = np.zeros(2, dtype=np.int64)  # current_id, prev_id
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

    # ------------------------------------------------------------------- the map
    def __len__(self) -> int:
        return self.store.n

    @property
    def num_links(self) -> int:
        """Number of links."""
        return self.store.e

    @property
    def poses(self) -> np.ndarray:
        """Experience poses ``[x, y, th]`` (read-only view; row = experience id).

        Shape:
            (N, 3).
        """
        return self.store.poses

    @property
    def graph(self) -> nx.DiGraph:
        """The map as a :class:`networkx.DiGraph` (:attr:`store`'s); treat it as read-only."""
        return self.store.graph

    def posegraph(self, order: str = "creation") -> PoseGraph:
        """The map as a :class:`~ratslam_graph.posegraph.PoseGraph` (:attr:`store`'s)."""
        return self.store.posegraph(order)

    def links(self) -> dict[str, np.ndarray]:
        """Every link as arrays, each (E,) (:attr:`store`'s :meth:`links`)."""
        return self.store.links()

    def view(self) -> MapView:
        """The map's arrays, read-only, for :mod:`ratslam_graph.queries` (views, no copies;
        take a new one after the map changes)."""
        p = self.params
        return self.store.view(self.current_id, p.exp_activity_zone_xy, p.exp_activity_zone_th)

    # ------------------------------------------------------------- odometry
    def on_odometry(self, vtrans: float, vrot: float, dt: float) -> None:
        """Accumulate odometry since the current experience (OpenRatSLAM's ``on_odo``).

        Args:
            vtrans: forward speed (m/s).
            vrot: turn rate (rad/s, counter-clockwise).
            dt: interval (s).
        """
        fs = self._fs  # the accumulators' array (see the slots above), read once
        step = vtrans * dt
        facing = float(wrap_angle(fs.item(2) + vrot * dt, include_pi=True))
        fs[2] = facing
        fs[0] = fs.item(0) + step * math.cos(facing)
        fs[1] = fs.item(1) + step * math.sin(facing)
        fs[3] = fs.item(3) + dt

    def _measurement(self, src: int, relative_rad: float) -> tuple[float, float, float]:
        """The accumulated transition as a link of ``src``: ``(d, heading, facing)``."""
        th = float(self.store.pose[src, 2])
        return _link_of(self.accum_x, self.accum_y, self.accum_facing + relative_rad, th)

    # --------------------------------------------------------------- actions
    def step_frame(
        self,
        odometry: tuple[float, float, float] | None,
        action: Action,
        *,
        frame: int = -1,
        t: float = 0.0,
        pc: tuple[float, float, float] | np.ndarray = (0.0, 0.0, 0.0),
        template_id: int = -1,
        behaviour: int = 0,
        relax: bool = True,
    ) -> None:
        """A whole frame: :meth:`on_odometry` (unless ``odometry`` is None),
        :meth:`apply` and, if ``relax``, :meth:`iterate`; one compiled call when the
        settings allow it (:mod:`ratslam_graph.frame_step`), the same map bit for bit.
        """
        frame_step.run_frame(
            self,
            odometry,
            action,
            frame=frame,
            t=t,
            pc=pc,
            template_id=template_id,
            behaviour=behaviour,
            relax=relax,
        )

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
            if action.dest_id not in (-1, len(self)):
                raise GraphError(
                    f"CREATE asks for experience {action.dest_id} but the next id is {len(self)}; "
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
            x = float(self.store.pose[cur, 0]) + self.accum_x
            y = float(self.store.pose[cur, 1]) + self.accum_y
        new = self.store.add_experience(
            x,
            y,
            wrap_angle(self.accum_facing, include_pi=True),
            pc=pc,
            template_id=template_id,
            frame=frame,
            t=t,
        )
        if cur >= 0:
            link_learning.count_transition(self.store, self.params, cur, new, behaviour)
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
        added = self.store.add_link(
            src,
            dst,
            d,
            heading,
            facing,
            self.accum_time,
            behaviour=behaviour,
            directed=self.params.exp_link_directed,
        )
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
        dest = self.store.check_id(dest, "LINK target")
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
        dest = self.store.check_id(dest, "SET target")
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
        self.accum_facing = wrap_angle(
            float(self.store.pose[dest, 2]) + relative_rad, include_pi=True
        )
        self.relative_rad = float(relative_rad)

    def _repeat_or_count(self, cur: int, dest: int, relative_rad: float, behaviour: int) -> None:
        """Bookkeeping of a transition ``cur -> dest`` between existing experiences."""
        p = self.params
        k = self.store.link_index(cur, dest, directed=p.exp_link_directed)
        if k >= 0 and p.exp_link_averaging:
            m = self._measurement(cur, relative_rad)
            link_learning.average_into(self.store, k, cur, m, self.accum_time)
            if p.exp_link_time == "per_link":
                self.accum_time = 0.0
        link_learning.count_transition(self.store, p, cur, dest, behaviour)

    def activity_action(
        self,
        pc: tuple[float, float, float] | np.ndarray,
        template_id: int,
        *,
        dims: tuple[float, ...] | None = None,
        relative_rad: float = 0.0,
    ) -> Action:
        """The action of ``exp_create_rule="activity"`` (Eqs. 1-4 of the experience-map
        paper; :func:`ratslam_graph.queries.activity_action` with ``exp_activity_threshold``)."""
        return queries.activity_action(
            self.view(),
            pc,
            template_id,
            threshold=self.params.exp_activity_threshold,
            dims=dims,
            relative_rad=relative_rad,
        )

    # ------------------------------------------------------------ relaxation
    @property
    def backend(self) -> RelaxationBackend:
        """The relaxation backend (built from ``exp_backend`` on first use)."""
        if self._backend is None:
            p = self.params
            self._backend = relaxation.make_map_backend(p.exp_backend, p.exp_relax_order)
        return self._backend

    def iterate(self) -> None:
        """Relax the map: ``exp_loops`` passes of the backend, poses written back.

        A map with fewer than two experiences or no link is left as it is, and so is
        every map when ``exp_loops`` is 0 and the backend is the alpha rule. The paths
        (OpenRatSLAM's compiled loop in place, ``relax_inplace`` backends, any other
        backend on :meth:`posegraph`) and their early stops are
        :mod:`ratslam_graph.relaxation`'s.
        """
        p, s = self.params, self.store
        if s.n < 2 or s.e == 0 or (p.exp_loops == 0 and p.exp_backend.startswith("alpha")):
            return
        backend = self.backend
        if self._fixed_at == (s.version, id(p), id(backend)):
            return
        self._relax_cursor, fixed = relaxation.relax_map(
            s, p, backend, cursor=self._relax_cursor, relax_tol=self.relax_tol
        )
        if fixed:
            self._fixed_at = (s.version, id(p), id(backend))

    def _not_converged(self) -> None:
        p = self.params
        relaxation.log_not_converged(p.exp_loops, p.exp_backend, self.store.n)

    # ---------------------------------------------------------------- state
    def get_state(self) -> dict[str, Any]:
        """Everything needed to restore the map exactly: numpy arrays and Python scalars
        (:func:`ratslam_graph.map_state.map_state`)."""
        return map_state(self.store, self._ist, self._fs, self._relax_cursor)

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a :meth:`get_state` dictionary (replaces the whole map).

        ``format``, ``version`` and ``relative_rad`` may be absent (importers); every
        other key is required.

        Raises:
            MapFormatError: a key is missing, an array has the wrong shape, a link points
                at a missing experience, or the format/version is not this one
                (:func:`ratslam_graph.map_state.read_map_state`). The map is left unchanged.
        """
        st = read_map_state(state)
        self._clear()
        self._reset_backend()
        self.store.load(st)
        self.current_id, self.prev_id = st["current_id"], st["prev_id"]
        self.accum_x, self.accum_y = st["accum_x"], st["accum_y"]
        self.accum_facing, self.accum_time = st["accum_facing"], st["accum_time"]
        self.relative_rad = st["relative_rad"]
        self._relax_cursor = st["relax_cursor"]
