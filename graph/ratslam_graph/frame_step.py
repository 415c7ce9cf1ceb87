"""The experience map's frame as one compiled call: odometry, action, relaxation.

:meth:`ratslam_graph.experience_map.ExperienceMap.step_frame` comes here when the map's
settings are those the compiled frame (``_frame_step.py``, numba, imported lazily)
reproduces: the alpha rule in OpenRatSLAM's order (``exp_backend="alpha"``,
``exp_relax_order="openratslam"``) with no relaxation budget, no link averaging, no
link removal by confidence and the pose cells' create rule, OpenRatSLAM's settings and
the default's, and no subclass's own ``on_odometry``, ``apply`` or ``iterate``. The map
is then the Python path's bit for bit (the same operations in the
same order, tested against it and the C++ traces); what is left here is bookkeeping that
costs no loop: the counters, a new experience's attributes. Anything else, and any
action the Python path would refuse, goes the Python way.

What the compiled call is given of a map (its arrays, the links in OpenRatSLAM's order,
the settings' flags) is kept on the map (:class:`FrameArgs`, :func:`frame_args`) while
its store's ``layout``, its ``params`` and its backend are the same objects, so a frame
costs the call and a few attribute reads: :func:`stage_frame` (which :func:`step_frame`
and :func:`run_frame` call, and the pipeline's stage directly) and, for the pipeline's
frames without action, :func:`odometry_frame`. The kernel itself refuses an action whose
target does not exist and asks for room when an array is full, before it changes
anything.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ratslam_graph import relaxation
from ratslam_graph.messages import Action, ActionKind

if TYPE_CHECKING:
    from ratslam_graph.experience_map import ExperienceMap

__all__ = [
    "FrameArgs",
    "compiled_frame",
    "frame_args",
    "odometry_frame",
    "run_frame",
    "stage_frame",
    "step_frame",
]


_KERNEL: Any = None
_NO_ODOMETRY = (0.0, 0.0, 0.0)
_CREATE = int(ActionKind.CREATE)
_log = relaxation.log  # its "did not converge" lines
_DEBUG = logging.DEBUG

# The compiled frame's result: what changed (bits), or one of the negative codes.
NODE_ADDED = 1
LINK_ADDED = 2
RELAXED = 4
FIXED = 8
FALLBACK = -1
"""A value the Python path would refuse (not finite) was met before anything but the
odometry changed: the caller runs the Python path for the action."""
GROW = -2
"""Nothing changed: the action needs a row that an array lacks; the caller makes room
and calls again."""
REFUSED = -3
"""Nothing changed: the action's target does not exist (the Python path raises)."""


def _kernel() -> Any:
    """The compiled module (numba), imported on first use and kept."""
    global _KERNEL
    from ratslam_graph import _frame_step

    _KERNEL = _frame_step
    return _KERNEL


def compiled_frame(em: ExperienceMap) -> bool:
    """True if ``em``'s settings are those the compiled frame reproduces."""
    p = em.params
    key = (id(p), id(em._backend))
    cached = em._compiled_for
    if cached is not None and cached[0] == key:
        return cached[1]
    from ratslam_graph.experience_map import ExperienceMap

    cls = type(em)
    ok = (
        # a subclass's own on_odometry / apply / iterate are called, one by one
        all(
            getattr(cls, m) is getattr(ExperienceMap, m)
            for m in ("on_odometry", "apply", "iterate")
        )
        and p.exp_backend == "alpha"
        and p.exp_relax_budget == 0
        and not p.exp_link_averaging
        and not p.exp_link_directed
        and p.exp_link_confidence_threshold <= 0.0
        and p.exp_create_rule != "activity"
        and getattr(em.backend, "schedule", None) == "openratslam"
    )
    em._compiled_for = ((id(p), id(em._backend)), ok)
    return ok


class FrameArgs:
    """What the compiled frame is given of one map, kept on it (``em._frame_args``) and
    valid while its store's ``layout``, its ``params`` and its backend are the same
    (:func:`frame_args` checks).

    Attributes:
        layout, params, backend: what it was made for.
        compiled: :func:`compiled_frame`.
        own_step: the map's class keeps :meth:`ExperienceMap.step_frame` (the pipeline may
            take its frames here without calling it).
        relax_every: ``exp_relax == "every_frame"``.
        arrays: the kernel's array arguments (accumulators, ids, the store's arrays, the
            links in OpenRatSLAM's order).
        ref: that order (current; None, and no arrays, when not ``compiled``).
        flags: the settings' bits of the kernel's ``flags``.
        tail: the kernel's last arguments, ``(exp_loops, exp_correction)``.
        ids: ``(id(params), id(backend))``, the tail of the map's fixed-point stamp.
    """

    __slots__ = (
        "arrays",
        "backend",
        "compiled",
        "flags",
        "ids",
        "layout",
        "own_step",
        "params",
        "ref",
        "relax_every",
        "tail",
    )

    def __init__(self, em: ExperienceMap) -> None:
        from ratslam_graph.experience_map import ExperienceMap

        self.compiled = compiled = compiled_frame(em)  # (may make the backend)
        p, s = em.params, em.store
        self.params, self.backend = p, em._backend
        self.ids = (id(p), id(self.backend))
        self.own_step = compiled and type(em).step_frame is ExperienceMap.step_frame
        self.relax_every = p.exp_relax == "every_frame"
        self.flags = p.exp_first_at_origin << 3 | (p.exp_link_time == "per_link") << 4
        self.tail = (int(p.exp_loops), float(p.exp_correction))
        self.ref: relaxation.ReferenceOrder | None = None
        self.arrays: tuple[np.ndarray, ...] = ()
        if compiled:
            self._arrays(em)
        self.layout = s.layout  # (after the order: making it renews the layout)

    def _arrays(self, em: ExperienceMap) -> None:
        s = em.store
        self.ref = ref = s._reference()
        self.arrays = (
            em._fs,
            em._ist,
            s.pose,
            s.src,
            s.dst,
            s.link,
            s.meas,
            s.counts,
            s.behaviour,
            s.edge_dirty,
            s.out_ends,
            s.out_next,
            *ref.buffers,
        )


def frame_args(em: ExperienceMap) -> FrameArgs:
    """``em``'s :class:`FrameArgs`, made again when it is stale."""
    c = em._frame_args
    if (
        c is None
        or c.layout != em.store.layout
        or c.params is not em.params
        or c.backend is not em._backend
    ):
        c = em._frame_args = FrameArgs(em)
    return c


def run_frame(
    em: ExperienceMap,
    odo: tuple[float, float, float] | None,
    action: Action,
    *,
    frame: int,
    t: float,
    pc: Any,
    template_id: int,
    behaviour: int,
    relax: bool,
) -> None:
    """:meth:`ExperienceMap.step_frame`: the compiled call when :func:`compiled_frame`
    allows it and the action is one it takes, else ``on_odometry``, ``apply`` and
    ``iterate``."""
    if stage_frame(em, odo, action, frame, t, pc, template_id, behaviour, relax) is not None:
        return
    if odo is not None:
        em.on_odometry(*odo)
    em.apply(action, frame=frame, t=t, pc=pc, template_id=template_id, behaviour=behaviour)
    if relax:
        em.iterate()


def step_frame(
    em: ExperienceMap,
    odo: tuple[float, float, float] | None,
    action: Action,
    *,
    frame: int,
    t: float,
    pc: Any,
    template_id: int,
    behaviour: int,
    relax: bool,
) -> bool:
    """One frame in one compiled call; False (nothing done) when the Python path must
    take it (see the module's text)."""
    return stage_frame(em, odo, action, frame, t, pc, template_id, behaviour, relax) is not None


def _created_pc(pc: Any) -> tuple[float, float, float] | None:
    """A created experience's pose-cell coordinates as floats if the Python path takes
    them without complaint (three finite values in a tuple); None otherwise."""
    if not isinstance(pc, tuple) or len(pc) != 3:
        return None
    pcv = (float(pc[0]), float(pc[1]), float(pc[2]))
    return pcv if all(map(math.isfinite, pcv)) else None


def odometry_frame(
    em: ExperienceMap, odo: tuple[float, float, float], action: Action
) -> int | None:
    """:func:`stage_frame` of a pipeline frame without action (``action`` NONE, ``odo``
    given, ``relax`` None), with less to pass and check: the odometry alone, one
    compiled call that returns the current experience, unless ``exp_relax`` is
    ``"every_frame"`` (then :func:`stage_frame`; a frame without action makes no
    experience, so its index, time, coordinates, template and behaviour are not
    needed). None, nothing done, as :func:`stage_frame`."""
    c = em._frame_args
    if c is None or c.params is not em.params or c.backend is not em._backend:
        c = frame_args(em)  # (the arrays are not needed: the layout is not checked)
    if not c.own_step:
        return None
    if c.relax_every:
        return stage_frame(em, odo, action, -1, 0.0, (), -1, None)
    return (_KERNEL or _kernel()).odometry_frame(em._fs, em._ist, *odo)


def stage_frame(
    em: ExperienceMap,
    odo: tuple[float, float, float] | None,
    action: Action,
    frame: int,
    t: float,
    pc: Any,
    template_id: int,
    behaviour: int | None,
    relax: bool | None = None,
) -> int | None:
    """One frame of ``em`` as its compiled frame (arguments by position: the pipeline's
    stage calls it directly).

    Args:
        em, odo, action, frame, t, pc, template_id, behaviour: as
            :meth:`ExperienceMap.step_frame`'s (``behaviour`` None: 0).
        relax: relax after the action; None: the pipeline's frame, relaxed when it has
            an action or ``exp_relax`` is ``"every_frame"``, taken here only when the
            map's class keeps :meth:`ExperienceMap.step_frame` (a frame without either
            is its odometry alone, one compiled call).

    Returns:
        The current experience after the frame, or None, nothing done, when the Python
        path must take it: settings the compiled frame does not reproduce, an action
        whose target does not exist, a created experience's coordinates that are not
        three finite values.
    """
    c = em._frame_args
    if (
        c is None
        or c.layout != em.store.layout
        or c.params is not em.params
        or c.backend is not em._backend
    ):
        c = frame_args(em)
    if relax is None:
        if not c.own_step:
            return None
        if not action.kind and not c.relax_every:  # the odometry alone
            if odo is None:
                return em._ist.item(0)  # current_id
            return (_KERNEL or _kernel()).odometry_frame(em._fs, em._ist, *odo)
        relax = True
    elif not c.compiled:
        return None
    kind = int(action.kind)
    pcv: tuple[float, ...] = ()
    if kind == _CREATE:
        checked = _created_pc(pc)
        if checked is None:
            return None
        pcv = checked
    s = em.store
    fixed_at = em._fixed_at  # (version, id(params), id(backend)) of a fixed point
    fixed = fixed_at is not None and fixed_at[0] == s.version and fixed_at[1:] == c.ids
    flags = c.flags | relax << 1 | fixed << 2 | (odo is not None)
    beh = 0 if behaviour is None else int(behaviour)
    k = _KERNEL or _kernel()
    out, current = k.frame_step(
        *c.arrays,
        *(_NO_ODOMETRY if odo is None else odo),
        kind,
        int(action.dest_id),
        float(action.relative_rad),
        beh,
        s.n,
        s.e,
        flags,
        *c.tail,
    )
    if out == RELAXED:  # the common outcome: poses moved, no fixed point
        s.poses_changed()
        if _log.isEnabledFor(_DEBUG):
            em._not_converged()
        return current
    if out < 0:
        if out == GROW:  # nothing changed: room for the action, and the frame again
            s.reserve_frame()
            return stage_frame(em, odo, action, frame, t, pc, template_id, beh, relax)
        if out == REFUSED:  # nothing changed
            return None
        # FALLBACK: the odometry is in; the Python path raises as it always has
        em.apply(action, frame=frame, t=t, pc=pc, template_id=template_id, behaviour=beh)
        if relax:
            em.iterate()
        return em._ist.item(0)
    if out & NODE_ADDED:
        s.node_added(pcv, template_id, frame, t)
    if out & LINK_ADDED:
        assert c.ref is not None  # (a compiled frame's arguments have it)
        s.link_added(c.ref)
    if out & RELAXED:
        s.poses_changed()
        if out & FIXED:
            em._fixed_at = (s.version, *c.ids)
        elif _log.isEnabledFor(_DEBUG):
            em._not_converged()
    return current
