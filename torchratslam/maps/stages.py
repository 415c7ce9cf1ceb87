"""A map as the stage records it is made of, and back.

:func:`compose` builds a :class:`~torchratslam.maps.state.MapState` from the typed state
records of the three stages (:class:`~torchratslam.local_view.state.LocalViewState`,
:class:`~torchratslam.pose_cells.state.PoseCellState`,
:class:`~ratslam_graph.state.ExperienceMapState`), the session record and the odometry
source's state; :func:`decompose` gives them back. Keys a stage holds beyond the
canonical fields are kept in ``extra`` / ``scalars`` under the stage's prefix (``lv.``,
``pc.``, ``em.``, ``vo.``), per-entity ones under ``template:``, ``exp:``, ``link:``, so a
round trip gives each stage back exactly what it gave.

Example:
    >>> from torchratslam.maps.stages import decompose  # doctest: +SKIP
    >>> parts = decompose(stored)  # doctest: +SKIP
    >>> parts.pose_cells.activity.shape  # doctest: +SKIP
    (36, 21, 21)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ratslam_graph.state import ExperienceMapState
from torchratslam.errors import MapFormatError
from torchratslam.local_view.state import LocalViewState
from torchratslam.maps.state import EM_ACCUM, PC_BEST, MapState
from torchratslam.messages import SessionState
from torchratslam.pose_cells.state import PoseCellState

__all__ = ["MapParts", "compose", "decompose", "experience_map_record", "experience_map_state"]

_LV_KNOWN = {"templates", "means", "frames", "current_id", "previous_id", "template_shape"}
PC_OWN = "pc_own."
"""Prefix of the pose cells' own experiences when they are not the map's (the activity rule)."""

_PC_KNOWN = {
    "activity",
    "template_pc",
    "template_decay",
    "exp_pc",
    "exp_template",
    "current_exp",
    "current_vt",
    "prev_vt",
    "best",
}
_EM_KNOWN = {
    "poses",
    "pc",
    "template_id",
    "frame",
    "t",
    "link_ends",
    "link_values",
    "link_counts",
    "link_behaviour",
    "current_id",
    "prev_id",
    "accum_x",
    "accum_y",
    "accum_facing",
    "accum_time",
}


@dataclass(frozen=True)
class MapParts:
    """The stage records of a map (see :func:`decompose`).

    Attributes:
        local_view, pose_cells, experience_map: the stages' records.
        odometry: the odometry source's state (empty: none saved).
        session: the session record (frames processed, last time stamp).
    """

    local_view: LocalViewState
    pose_cells: PoseCellState
    experience_map: ExperienceMapState
    odometry: dict[str, Any]
    session: SessionState


def _split_extras(prefix: str, d: Mapping[str, Any], known: set[str], out: MapState) -> None:
    for k, v in d.items():
        if k in known:
            continue
        if v is None:
            out.scalars[f"{prefix}.{k}.none"] = True
        elif isinstance(v, (bool, int, float, str)) and not isinstance(v, np.generic):
            out.scalars[f"{prefix}.{k}"] = v
        elif isinstance(v, np.generic):
            out.scalars[f"{prefix}.{k}"] = v.item()
        else:
            arr = np.asarray(v.detach().cpu().numpy() if hasattr(v, "detach") else v)
            if arr.dtype == object:
                raise MapFormatError(
                    f"module state {prefix}.{k} holds Python objects; "
                    "it cannot be saved without pickle"
                )
            out.extra[f"{prefix}.{k}"] = arr


def _collect(prefix: str, state: MapState) -> dict[str, Any]:
    """The prefix's extras and scalars back as a module-state dict (without the prefix)."""
    out: dict[str, Any] = {}
    p = prefix + "."
    for k, v in state.extra.items():
        if k.startswith(p):
            out[k[len(p) :]] = np.array(v, copy=True)
    for k, v in state.scalars.items():
        if k.startswith(p):
            if k.endswith(".none"):
                out[k[len(p) : -5]] = None
            else:
                out[k[len(p) :]] = v
    return out


def compose(
    config: dict[str, Any],
    local_view: LocalViewState,
    pose_cells: PoseCellState,
    experience_map: ExperienceMapState,
    session: SessionState,
    odometry: Mapping[str, Any] | None = None,
) -> MapState:
    """The map made of the stages' records (checked).

    Args:
        config: the flat config (``RatSLAMConfig.to_flat()``).
        local_view, pose_cells, experience_map: the stages' records.
        session: frames processed and the last time stamp.
        odometry: the odometry source's state (None: it has none).

    Raises:
        MapFormatError: the records do not make a valid map.
    """
    lv, pc, em = local_view, pose_cells, experience_map
    ends, vals = em.link_ends, em.link_values
    own = pc.exp_pc.shape[0] != em.poses.shape[0]
    if own:
        # exp_create_rule="activity": the map learns its experiences from their activity
        # and the pose cells keep their own list (their distance rule gives only the
        # action's angle); the map's cells are the map's, the pose cells' are kept apart
        pc_own = (pc.exp_pc, pc.exp_template, pc.current_exp)
        pc = pc.replace(exp_pc=em.pc, exp_template=em.template_id, current_exp=None)
    state = MapState(
        config=config,
        templates=np.ascontiguousarray(lv.templates),
        template_mean=lv.means.astype(np.float64),
        template_frame=lv.frames.astype(np.int64),
        template_pc=pc.template_pc,
        template_decay=pc.template_decay,
        exp_pose=em.poses,
        exp_pc=pc.exp_pc,
        exp_template=em.template_id,
        exp_frame=em.frame,
        exp_t=em.t,
        link_from=ends[:, 0].astype(np.int64),
        link_to=ends[:, 1].astype(np.int64),
        link_d=vals[:, 0].copy(),
        link_heading=vals[:, 1].copy(),
        link_facing=vals[:, 2].copy(),
        link_dt=vals[:, 3].copy(),
        activity=np.ascontiguousarray(pc.activity),
        current_vt=int(pc.current_vt if pc.current_vt is not None else lv.current_id),
        prev_vt=int(pc.prev_vt if pc.prev_vt is not None else lv.previous_id),
        current_exp=int(em.current_id),
        prev_exp=int(em.prev_id),
        frame_index=int(session.frame_index),
    )
    state.extra[EM_ACCUM] = np.array(
        [em.accum_x, em.accum_y, em.accum_facing, em.accum_time], np.float64
    )
    state.extra["link:counts"] = em.link_counts
    state.extra["link:behaviour"] = em.link_behaviour
    if pc.best is not None:
        state.extra[PC_BEST] = pc.best
    if not np.array_equal(em.pc, pc.exp_pc):
        state.extra["exp:em_pc"] = em.pc
    if not np.array_equal(pc.exp_template, state.exp_template):
        state.extra["exp:pc_template"] = pc.exp_template
    if pc.current_exp is not None and pc.current_exp != state.current_exp:
        state.scalars["pc.current_exp"] = int(pc.current_exp)
    if own:
        state.extra[PC_OWN + "exp_pc"] = np.asarray(pc_own[0], np.float64)
        state.extra[PC_OWN + "exp_template"] = np.asarray(pc_own[1], np.int64)
        if pc_own[2] is not None:
            state.scalars[PC_OWN + "current_exp"] = int(pc_own[2])
    _split_extras("lv", lv.to_dict(), _LV_KNOWN, state)
    _split_extras("pc", pc.to_dict(), _PC_KNOWN, state)
    _split_extras("em", em.to_dict(), _EM_KNOWN, state)
    if odometry is not None:
        _split_extras("vo", odometry, set(), state)
    state.scalars["slam.last_t"] = float(session.last_t)
    return state.validate(source="running map")


def experience_map_record(state: MapState) -> ExperienceMapState:
    """The experience map's record of ``state``."""
    em = _collect("em", state)
    accum = np.asarray(state.extra.get(EM_ACCUM, np.zeros(4)), np.float64)
    n_l = state.n_links
    counts = state.extra.get("link:counts", np.zeros((n_l, 3), np.int64))
    behaviour = state.extra.get("link:behaviour", np.zeros(n_l, np.int64))
    em.pop("accum", None)
    em.update(
        {
            "poses": state.exp_pose.copy(),
            "pc": state.exp_pc.copy(),
            "template_id": state.exp_template.copy(),
            "frame": state.exp_frame.copy(),
            "t": state.exp_t.copy(),
            "link_ends": np.stack([state.link_from, state.link_to], axis=1).reshape(-1, 2),
            "link_values": np.stack(
                [state.link_d, state.link_heading, state.link_facing, state.link_dt], axis=1
            ).reshape(-1, 4),
            "link_counts": np.array(counts, dtype=np.int64, copy=True),
            "link_behaviour": np.array(behaviour, dtype=np.int64, copy=True),
            "current_id": int(state.current_exp),
            "prev_id": int(state.prev_exp),
            "accum_x": float(accum[0]),
            "accum_y": float(accum[1]),
            "accum_facing": float(accum[2]),
            "accum_time": float(accum[3]),
        }
    )
    em.setdefault("relative_rad", 0.0)
    em.setdefault("format", ExperienceMapState.FORMAT)  # maps imported from the reference format
    em.setdefault("version", ExperienceMapState.VERSION)
    return ExperienceMapState.from_dict(em)


def experience_map_state(state: MapState) -> dict[str, Any]:
    """The ``ratslam_graph.experience_map.ExperienceMap.set_state`` dictionary of ``state``."""
    return experience_map_record(state).to_dict()


def decompose(state: MapState) -> MapParts:
    """The stage records ``state`` is made of (the inverse of :func:`compose`).

    A map imported without a local view's ``kind`` / ``version`` gives a record without
    them (the running module's own apply).

    Raises:
        MapFormatError: an array has the wrong shape for its stage.
    """
    lv = _collect("lv", state)
    lv.update(
        {
            "templates": np.ascontiguousarray(state.templates),
            "means": state.template_mean.copy(),
            "frames": state.template_frame.copy(),
            "current_id": int(state.current_vt),
            "previous_id": int(state.prev_vt),
            "template_shape": np.asarray(state.templates.shape[1:], np.int64),
        }
    )
    lv.setdefault("frame_counter", int(state.frame_index))
    current_exp = int(state.scalars.get("pc.current_exp", state.current_exp))
    exp_pc = state.exp_pc
    exp_template = state.extra.get("exp:pc_template", state.exp_template)
    if PC_OWN + "exp_pc" in state.extra:  # the pose cells' own experiences (activity rule)
        exp_pc = state.extra[PC_OWN + "exp_pc"]
        exp_template = state.extra[PC_OWN + "exp_template"]
        current_exp = int(state.scalars.get(PC_OWN + "current_exp", len(exp_pc) - 1))
    pc = _collect("pc", state)
    pc.update(
        {
            "activity": state.activity.copy(),
            "template_pc": state.template_pc.copy(),
            "template_decay": state.template_decay.copy(),
            "exp_pc": np.array(exp_pc, np.float64, copy=True).reshape(-1, 3),
            "exp_template": np.array(exp_template, dtype=np.int64, copy=True),
            "current_exp": current_exp,
            "current_vt": int(state.current_vt),
            "prev_vt": int(state.prev_vt),
        }
    )
    if PC_BEST in state.extra:
        pc["best"] = np.array(state.extra[PC_BEST], np.float64, copy=True)
    em = experience_map_record(state)
    if "exp:em_pc" in state.extra:
        em = em.replace(pc=np.array(state.extra["exp:em_pc"], np.float64, copy=True))
    return MapParts(
        local_view=LocalViewState.from_dict(lv),
        pose_cells=PoseCellState.from_dict(pc),
        experience_map=em,
        odometry=_collect("vo", state),
        session=SessionState(
            frame_index=int(state.frame_index),
            last_t=float(state.scalars.get("slam.last_t", 0.0)),
        ),
    )
