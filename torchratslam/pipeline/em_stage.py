"""The pipeline's experience-map stage: a frame's odometry, action and relaxation.

:func:`experience_map_step` is what :class:`~torchratslam.pipeline.RatSLAM` does with the
experience map each frame: one compiled call (``step_frame``) where the module has it and
the pose cells' action stands, else odometry, the action (the experience map's own
under ``exp_create_rule="activity"``, Eqs. 1-4) and the relaxation, one by one. An
:class:`~ratslam_graph.experience_map.ExperienceMap` that keeps the class's own frame
takes a frame without action or relaxation (about half of OpenRatSLAM's frames) as its
odometry alone (one compiled call, ``ratslam_graph._frame_step.odometry``), and a frame
with an action as the compiled frame
(:func:`ratslam_graph.frame_step.step_frame`) without the layers between: what its
``step_frame`` would do.
"""

from __future__ import annotations

from typing import Any

from ratslam_graph import frame_step
from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.frame_step import compiled_frame
from ratslam_graph.messages import Action, ActionKind
from torchratslam.protocols import ExperienceMapModule

__all__ = ["experience_map_step"]


def _plan(em: ExperienceMapModule) -> tuple[Any, Any, bool, bool, bool]:
    """``(params, backend, compiled, relax every frame, activity rule)`` of ``em``: whether
    the class's own compiled frame takes its frames (see the module's text); kept on an
    :class:`~ratslam_graph.experience_map.ExperienceMap` for as long as its ``params``
    and backend are the same objects."""
    params = getattr(em, "params", None)
    relax_every = getattr(params, "exp_relax", "every_frame") == "every_frame"
    activity = getattr(params, "exp_create_rule", "pc_distance") == "activity"
    compiled = (
        not activity
        and isinstance(em, ExperienceMap)
        and type(em).step_frame is ExperienceMap.step_frame
        and compiled_frame(em)
    )
    plan = (params, getattr(em, "_backend", None), compiled, relax_every, activity)
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
    plan = em.__dict__.get("_stage_plan") if isinstance(em, ExperienceMap) else None
    if plan is None or plan[0] is not em.params or plan[1] is not em._backend:  # type: ignore[attr-defined]
        plan = _plan(em)
    compiled, relax_every, activity = plan[2], plan[3], plan[4]
    relax = relax_every or action.kind != ActionKind.NONE
    if compiled and isinstance(em, ExperienceMap):  # the class's step_frame, without layers
        if not relax and odo is not None:  # no action, no relaxation: the odometry alone
            (frame_step._KERNEL or frame_step._kernel()).odometry(em._fs, *odo)
            return em._ist.item(0)  # current_id
        if frame_step.step_frame(
            em,
            odo,
            action,
            frame=frame,
            t=t,
            pc=pc,
            template_id=template_id,
            behaviour=0 if behaviour is None else int(behaviour),
            relax=relax,
        ):
            return em._ist.item(0)
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
