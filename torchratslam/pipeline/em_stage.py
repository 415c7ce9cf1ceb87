"""The pipeline's experience-map stage: a frame's odometry, action and relaxation.

:func:`experience_map_step` is what :class:`~torchratslam.pipeline.RatSLAM` does with the
experience map each frame: one compiled call (:func:`compiled_step`) where the map has it
and the pose cells' action stands, else (:func:`general_step`) odometry, the action (the
experience map's own under ``exp_create_rule="activity"``, Eqs. 1-4) and the relaxation,
one by one. :func:`compiled_step` is an
:class:`~ratslam_graph.experience_map.ExperienceMap`'s own frame, what its ``step_frame``
would do, without the layers between: a frame without action or relaxation (about half
of OpenRatSLAM's frames) as its odometry alone
(:func:`ratslam_graph.frame_step.odometry_frame`, one compiled call), a frame with an
action as the compiled frame (:func:`ratslam_graph.frame_step.stage_frame`, with the
arguments the map keeps for it). The pipeline's stage does what
:func:`experience_map_step` does, with :func:`compiled_step`'s two calls inline.
"""

from __future__ import annotations

from typing import Any

from ratslam_graph import frame_step
from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.messages import Action, ActionKind
from torchratslam.protocols import ExperienceMapModule

__all__ = ["compiled_step", "experience_map_step", "general_step"]


def compiled_step(
    em: ExperienceMapModule,
    odo: tuple[float, float, float] | None,
    action: Action,
    frame: int,
    t: float,
    pc: tuple[float, float, float],
    template_id: int,
    behaviour: int | None,
) -> int | None:
    """The frame as the map's own compiled frame
    (:func:`ratslam_graph.frame_step.stage_frame`), when the map is an
    :class:`~ratslam_graph.experience_map.ExperienceMap` that has one the pipeline may
    take without its ``step_frame`` and the action is one it takes; returns the current
    experience, or None, nothing done: the caller takes the frame the general way
    (:func:`general_step`). Arguments as :func:`experience_map_step`'s (``t`` and
    ``template_id`` as given, converted when an experience is made)."""
    if not isinstance(em, ExperienceMap):
        return None
    if action.kind or odo is None:
        return frame_step.stage_frame(em, odo, action, frame, t, pc, template_id, behaviour)
    return frame_step.odometry_frame(em, odo, action)


def _plan(em: ExperienceMapModule) -> tuple[Any, bool, bool]:
    """``(params, relax every frame, activity rule)`` of ``em``, kept on an
    :class:`~ratslam_graph.experience_map.ExperienceMap` for as long as its ``params``
    are the same object."""
    params = getattr(em, "params", None)
    relax_every = getattr(params, "exp_relax", "every_frame") == "every_frame"
    activity = getattr(params, "exp_create_rule", "pc_distance") == "activity"
    plan = (params, relax_every, activity)
    if isinstance(em, ExperienceMap):
        em.__dict__["_stage_plan"] = plan
    return plan


def experience_map_step(
    em: ExperienceMapModule,
    odo: tuple[float, float, float] | None,
    action: Action,
    *,
    frame: int,
    t: float,
    pc: tuple[float, float, float],
    template_id: int,
    pc_dims: tuple[float, ...],
    behaviour: int | None = None,
) -> int:
    """One frame of the experience map; returns its current experience.

    Args:
        em: the experience map.
        odo: ``(vtrans, vrot, dt)``, or None where the frame's odometry is skipped
            (OpenRatSLAM's first message).
        action: the pose cells' action.
        frame, t: the frame's index and time.
        pc: the dominant packet's centre (cells).
        template_id: the frame's view template.
        pc_dims: the pose-cell network's ``(X, Y, TH)``, for the activity rule's
            distances round the wrapping network.
        behaviour: the transition's movement label (Eq. 9), or None.
    """
    current = compiled_step(em, odo, action, frame, t, pc, template_id, behaviour)
    if current is not None:
        return current
    return general_step(
        em,
        odo,
        action,
        frame=frame,
        t=t,
        pc=pc,
        template_id=template_id,
        pc_dims=pc_dims,
        behaviour=behaviour,
    )


def general_step(
    em: ExperienceMapModule,
    odo: tuple[float, float, float] | None,
    action: Action,
    *,
    frame: int,
    t: float,
    pc: tuple[float, float, float],
    template_id: int,
    pc_dims: tuple[float, ...],
    behaviour: int | None = None,
) -> int:
    """:func:`experience_map_step` without :func:`compiled_step` (which did not take the
    frame): the map's ``step_frame``, or its calls one by one."""
    plan = em.__dict__.get("_stage_plan") if isinstance(em, ExperienceMap) else None
    if plan is None or plan[0] is not em.params:  # type: ignore[attr-defined]
        plan = _plan(em)
    relax_every, activity = plan[1], plan[2]
    relax = relax_every or action.kind != ActionKind.NONE
    extra = {} if behaviour is None else {"behaviour": int(behaviour)}
    step = getattr(em, "step_frame", None)
    if step is not None and not activity:  # one call: odometry, action, relaxation
        step(
            odo,
            action,
            frame=frame,
            t=t,
            pc=pc,
            template_id=template_id,
            relax=relax,
            **extra,
        )
        return int(em.current_id)
    if odo is not None:
        em.on_odometry(*odo)
        if activity:  # the experience map decides from experience activity (Eqs. 1-4)
            action = em.activity_action(  # type: ignore[attr-defined]
                pc, template_id, dims=pc_dims, relative_rad=float(action.relative_rad)
            )
    em.apply(action, frame=frame, t=t, pc=pc, template_id=template_id, **extra)
    if relax_every or action.kind != ActionKind.NONE:
        em.iterate()
    return int(em.current_id)
