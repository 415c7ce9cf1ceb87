"""The experience map's frame as one compiled call: odometry, action, relaxation.

:meth:`ratslam_graph.experience_map.ExperienceMap.step_frame` comes here when the map's
settings are those the compiled frame (``_frame_step.py``, numba, imported lazily)
reproduces: the alpha rule in OpenRatSLAM's order (``exp_backend="alpha"``,
``exp_relax_order="openratslam"``) with no relaxation budget, no link averaging, no
link removal by confidence and the pose cells' create rule, OpenRatSLAM's settings and
the default's, and no subclass's own ``on_odometry``, ``apply`` or ``iterate``. The map
is then the Python path's bit for bit (the same operations in the
same order, tested against it and the C++ traces); what is left here is bookkeeping that
costs no loop: counters, the graph's pending nodes and links. Anything else, and any
action the Python path would refuse, goes the Python way.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from ratslam_graph.messages import Action, ActionKind

if TYPE_CHECKING:
    from ratslam_graph.experience_map import ExperienceMap

__all__ = ["compiled_frame", "run_frame", "step_frame"]


_KERNEL: Any = None


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
    kw = {"frame": frame, "t": t, "pc": pc, "template_id": template_id, "behaviour": behaviour}
    if compiled_frame(em) and step_frame(em, odo, action, relax=relax, **kw):
        return
    if odo is not None:
        em.on_odometry(*odo)
    em.apply(action, **kw)
    if relax:
        em.iterate()


def _checked(em: ExperienceMap, action: Action, pc: Any) -> tuple[float, ...] | None:
    """The pose-cell coordinates as floats if the action is one the Python path takes
    without complaint (its target exists, a created experience's coordinates are
    finite); None otherwise."""
    kind, dest, n = int(action.kind), int(action.dest_id), em.store.n
    if kind == ActionKind.CREATE:
        if dest not in (-1, n) or not isinstance(pc, tuple) or len(pc) != 3:
            return None
        pcv = (float(pc[0]), float(pc[1]), float(pc[2]))
        return pcv if all(map(math.isfinite, pcv)) else None
    if kind != ActionKind.NONE and not 0 <= dest < n:
        return None
    return ()


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
    pcv = _checked(em, action, pc)
    if pcv is None:
        return False
    k = _KERNEL or _kernel()
    s, p, backend = em.store, em.params, em.backend
    n, e = s.n, s.e
    kind = int(action.kind)
    fixed = em._fixed_at == (s.version, id(p), id(backend))
    if not kind and (not relax or fixed or n < 2 or e == 0 or p.exp_loops == 0):
        if odo is not None:  # odometry alone: the Python path costs less than a call
            em.on_odometry(*odo)
        return True
    if kind:
        s.reserve(1, 1)
    ref = s._reference()
    ref.reserve()
    flags = (
        (odo is not None)
        | relax << 1
        | fixed << 2
        | p.exp_first_at_origin << 3
        | (p.exp_link_time == "per_link") << 4
    )
    out = k.frame_step(
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
        *((0.0, 0.0, 0.0) if odo is None else odo),
        kind,
        int(action.dest_id),
        float(action.relative_rad),
        int(behaviour),
        n,
        e,
        ref.n,
        flags,
        p.exp_loops,
        float(p.exp_correction),
    )
    if out == k.FALLBACK:  # the odometry is in; the Python path raises as it always has
        em.apply(action, frame=frame, t=t, pc=pc, template_id=template_id, behaviour=behaviour)
        if relax:
            em.iterate()
        return True
    if out & k.NODE_ADDED:
        s.node_added(pcv, template_id, frame, t)
    if out & k.LINK_ADDED:
        ref.n += 1
        s.link_added(ref)
    if out & k.RELAXED:
        s.poses_changed()
        if out & k.FIXED:
            em._fixed_at = (s.version, id(p), id(backend))
        else:
            em._not_converged()
    return True
