"""Merging two RatSLAM maps into one structure (the multisession paper, Section 3,
Eqs. 9-17, Algorithm 1).

The *partial* map is the one being built in the current session; its template ``z``
(normally its last, just learnt) matches template ``u`` of the *loaded* map. The merge

i. appends the partial templates except ``z`` after the loaded ones (Eq. 9); partial
   template ``i`` gets id ``n_vl + i`` (``i < z``), ``z`` becomes ``u``;
ii. moves the pose-cell activity from the partial packet ``P_z`` to the loaded
    ``P_u``: the activity array is rolled by the rounded shift;
iii. shifts every partial template's pose-cell association by ``Delta = P_u - P_z``
     modulo the network size (Eqs. 10-12). The paper's Eq. 10 prints a ``+``; the
     working definition, used by the authors' code, is the difference. The partial
     experiences' pose-cell coordinates are shifted too: by default as the authors'
     code does, by the difference of the two matched *experiences'* coordinates
     (``exp_pc_shift="experiences"``); ``exp_pc_shift="templates"`` is the paper's
     reading of Eq. 15 (one shift, the templates', for both). ``shift_pose_cells=False``
     skips this step (the Fig. 12 ablation);
iv. moves every partial experience by the rigid 2D transform that maps the partial
    matching experience ``e_z`` onto the loaded ``e_u``, with ``dth = th_u - th_z +
    relative view angle`` (Eqs. 13-14 are garbled in print; this is the arithmetic of
    the authors' code, see ``reference-save-format.md``), drops ``e_z``, re-points the
    links that ended (or started) at it to ``e_u`` and appends the rest (Eqs. 15-17).
    Link measurements are relative to their source experience and stay valid.

Which experiences are matched: by default as the authors' code, ``e_u`` is the *first*
experience of the loaded template ``u`` and ``e_z`` the partial map's last experience
(``match_exp="first"``); ``match_exp="nearest"`` (this project's earlier choice) takes,
for both, the experience of the matched template closest in pose cells to the
template's own association.

Everything is vectorised: the cost is linear in the sizes of both maps (Section 3.5).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ratslam_graph.geometry import pc_distance, wrap_angle
from torchratslam.errors import GraphError
from torchratslam.maps.compat import check_compatible, require_templates
from torchratslam.maps.state import EM_ACCUM, INT_FIELDS, PC_BEST, PER_ENTITY, MapState

__all__ = [
    "EXP_PC_SHIFTS",
    "MATCH_EXPS",
    "MergeResult",
    "append_place",
    "first_experience",
    "fuse_templates",
    "merge_maps",
    "pc_distance",
    "pick_experience",
    "shift_activity",
]

EXP_PC_SHIFTS = ("experiences", "templates")
"""``merge_maps(exp_pc_shift=...)``: how the partial experiences' pose-cell coordinates
are shifted. ``"experiences"`` (default, the authors' code): by ``exp_pc[e_u] -
exp_pc[e_z]``; ``"templates"`` (the paper's Eq. 15 read literally): by the templates'
``template_pc[u] - template_pc[z]``, like the template associations."""
MATCH_EXPS = ("first", "nearest")
"""``merge_maps(match_exp=...)``: which experiences are matched. ``"first"`` (default, the
authors' code): ``e_u`` the first experience of ``u``, ``e_z`` the partial map's last
experience; ``"nearest"``: for both, the matched template's experience nearest in pose
cells to the template's association (:func:`pick_experience`)."""
# per-experience extras whose "none" value is not 0 (reference-format goal fields)
_FILL = {"exp:ref_goal_to_current": -1.0, "exp:ref_current_to_goal": -1.0}
_DROP_SCALARS = "ref.tail."  # the secondary tails of a reference save: stale after a merge

log = logging.getLogger(__name__)


def pick_experience(state: MapState, template_id: int, pc: np.ndarray | None = None) -> int:
    """The experience of ``template_id`` whose pose-cell coordinates are closest to ``pc``
    (default: the template's own association); -1 if the template has no experience.
    Ties go to the lowest id."""
    cand = np.flatnonzero(state.exp_template == template_id)
    if cand.size == 0:
        return -1
    ref = state.template_pc[template_id] if pc is None else np.asarray(pc, np.float64)
    d = pc_distance(state.exp_pc[cand], ref, state.pc_dims)
    return int(cand[int(np.argmin(d))])


def first_experience(state: MapState, template_id: int) -> int:
    """The first (lowest-id) experience of ``template_id``, -1 if it has none: the one
    the authors' code merges at (a template's ``exps[0]``)."""
    cand = np.flatnonzero(state.exp_template == template_id)
    return int(cand[0]) if cand.size else -1


def shift_activity(
    activity: np.ndarray, shift_xyz: np.ndarray, src: np.ndarray | None = None
) -> np.ndarray:
    """Roll a ``(TH, Y, X)`` activity by whole cells, with wrap.

    Without ``src`` the roll is the rounded ``shift_xyz``; with ``src`` (the packet's
    cell coordinates) it is ``rint(src + shift) - rint(src)``, so a packet peaked at
    the cell nearest ``src`` lands on the cell nearest ``src + shift``.

    Shape:
        activity: ``(TH, Y, X)``; shift_xyz, src: ``(3,)`` (x, y, th cells).
    """
    if activity.size == 0:
        return activity.copy()
    shift = np.asarray(shift_xyz, np.float64)
    if src is None:
        s = np.rint(shift).astype(np.int64)
    else:
        src = np.asarray(src, np.float64)
        s = (np.rint(src + shift) - np.rint(src)).astype(np.int64)
    return np.roll(activity, shift=(int(s[2]), int(s[1]), int(s[0])), axis=(0, 1, 2))


def _remap(n: int, drop: int, target: int, offset: int) -> np.ndarray:
    """Id map of a partial entity list: ``i -> offset + i`` (``i < drop``),
    ``drop -> target``, ``i -> offset + i - 1`` (``i > drop``); ``-1`` stays ``-1``
    (index ``n`` of the returned array, for ``ids[-1]`` lookups use ``_apply``)."""
    ids = np.arange(n, dtype=np.int64)
    out = offset + ids - (ids > drop)
    if 0 <= drop < n:
        out[drop] = target
    return out


def _apply(idmap: np.ndarray, ids: np.ndarray | int) -> np.ndarray:
    ids = np.asarray(ids, np.int64)
    safe = np.where(ids >= 0, ids, 0)
    return np.where(ids >= 0, idmap[safe] if idmap.size else -1, -1)


@dataclass
class MergeResult:
    """The merged map and what the merge did.

    Attributes:
        state: the merged map (in the loaded map's frame and pose-cell coordinates).
        info: ``loaded_template`` u, ``partial_template`` z, ``loaded_exp`` e_u,
            ``partial_exp`` e_z (dropped), ``pc_shift`` (dx, dy, dth cells),
            ``transform`` (dth rad, tx m, ty m: x' = R(dth) x + t), ``template_ids``
            and ``exp_ids`` (old partial id -> merged id), counts added.
    """

    state: MapState
    info: dict[str, Any]

    def transform_poses(self, poses: np.ndarray) -> np.ndarray:
        """Apply the merge's rigid transform to partial-map poses.

        Shape:
            poses: ``(..., 3)`` [x, y, th] or ``(..., 2)`` [x, y]; returns the same shape.
        """
        dth, tx, ty = self.info["transform"]
        return rigid_transform(np.asarray(poses, np.float64), dth, tx, ty)


def rigid_transform(poses: np.ndarray, dth: float, tx: float, ty: float) -> np.ndarray:
    """``x' = R(dth) [x, y] + [tx, ty]``, ``th' = wrap(th + dth)``.

    Shape:
        poses: ``(..., 2)`` or ``(..., 3)``; returns the same shape.
    """
    p = np.array(poses, dtype=np.float64, copy=True)
    c, s = math.cos(dth), math.sin(dth)
    x, y = p[..., 0].copy(), p[..., 1].copy()
    p[..., 0] = c * x - s * y + tx
    p[..., 1] = s * x + c * y + ty
    if p.shape[-1] > 2:
        p[..., 2] = wrap_angle(p[..., 2] + dth, include_pi=True)
    return p


def _rotate_shift(
    pcs: np.ndarray, src: np.ndarray, dst: np.ndarray, dims: np.ndarray, axis: str = "math"
) -> np.ndarray:
    """Move pose-cell coordinates so that ``src`` lands on ``dst``, rotating the (x, y)
    offsets from ``src`` (the shorter way round the torus) by the heading shift
    ``(dst_th - src_th) * 2 pi / n_th``; th is shifted as in Eq. 10.

    ``axis`` is the network's ``pc_axis``: with ``"math"`` layer ``k`` moves along
    ``(cos, sin)(k 2 pi / TH)``, so a heading shift of ``a`` turns the offsets by ``a``;
    with ``"openratslam"`` it moves along ``(sin, cos)`` (x and y swapped, a mirror), so
    the same heading shift turns them by ``-a``.

    Shape:
        pcs: ``(N, 3)``; src, dst, dims: ``(3,)``; returns ``(N, 3)``.
    """
    pcs = np.asarray(pcs, np.float64).reshape(-1, 3)
    rel = pcs - src
    half = dims[:2] / 2.0
    rel[:, :2] = np.mod(rel[:, :2] + half, dims[:2]) - half
    a = float(dst[2] - src[2]) * 2.0 * math.pi / float(dims[2])
    if axis == "openratslam":
        a = -a
    c, s = math.cos(a), math.sin(a)
    x, y = rel[:, 0].copy(), rel[:, 1].copy()
    rel[:, 0], rel[:, 1] = c * x - s * y, s * x + c * y
    return np.mod(dst + rel, dims)


def merge_maps(
    loaded: MapState,
    partial: MapState,
    loaded_template: int,
    *,
    partial_template: int | None = None,
    relative_rad: float = 0.0,
    loaded_exp: int | None = None,
    partial_exp: int | None = None,
    shift_pose_cells: bool = True,
    exp_pc_shift: str = "experiences",
    match_exp: str = "first",
    pc_shift_rotate: bool = False,
) -> MergeResult:
    """Merge ``partial`` into ``loaded`` (Algorithm 1), given the template match.

    Args:
        loaded: the stored map (its frame and pose-cell coordinates are kept).
        partial: the current session's map.
        loaded_template: ``u``, the loaded template matched.
        partial_template: ``z``, the partial template that matched (default: the last).
        relative_rad: relative view angle of the match (panoramic mode; 0 otherwise).
        loaded_exp: ``e_u`` (default: chosen by ``match_exp``).
        partial_exp: ``e_z``, the partial experience to drop (default: chosen by
            ``match_exp``; the partial current experience when ``z`` has none).
        shift_pose_cells: False skips step (iii) (the paper's Fig. 12 ablation).
        exp_pc_shift: ``"experiences"`` (default, the authors' code) or ``"templates"``
            (the paper's single shift), see :data:`EXP_PC_SHIFTS`.
        match_exp: ``"first"`` (default, the authors' code) or ``"nearest"``, see
            :data:`MATCH_EXPS`.
        pc_shift_rotate: also rotate the partial map's pose-cell coordinates about the
            matched ones by the heading shift (``delta_th`` cells), so that the
            displacements between partial templates, laid down in the partial
            network's heading frame, point the same way in the loaded network's frame
            after the activity is rolled in ``th`` (default False: the paper's pure
            translation, Eq. 10). A deviation.

    Returns:
        A :class:`MergeResult`. The inputs are not modified.

    Raises:
        MapFormatError: the maps have different pose-cell or template sizes, or one was
            read without its templates.
        GraphError: ``u`` or ``z`` is out of range, ``u`` has no experience, or an
            unknown option.
    """
    if exp_pc_shift not in EXP_PC_SHIFTS:
        raise GraphError(f"exp_pc_shift must be one of {EXP_PC_SHIFTS}, got {exp_pc_shift!r}")
    if match_exp not in MATCH_EXPS:
        raise GraphError(f"match_exp must be one of {MATCH_EXPS}, got {match_exp!r}")
    require_templates(loaded, what="the loaded map")
    require_templates(partial, what="the partial map")
    check_compatible(loaded, partial.config, what="loaded map")
    n_vl, n_vp = loaded.n_templates, partial.n_templates
    n_el, n_ep = loaded.n_experiences, partial.n_experiences
    z = n_vp - 1 if partial_template is None else int(partial_template)
    u = int(loaded_template)
    if not 0 <= u < n_vl:
        raise GraphError(f"loaded template {u} does not exist (the loaded map has {n_vl})")
    if not 0 <= z < n_vp:
        raise GraphError(f"partial template {z} does not exist (the partial map has {n_vp})")
    if loaded_exp is not None:
        e_u = int(loaded_exp)
    elif match_exp == "first":
        e_u = first_experience(loaded, u)
    else:
        e_u = pick_experience(loaded, u)
    if not 0 <= e_u < n_el:
        raise GraphError(
            f"loaded template {u} has no experience to merge at; match another "
            "template or let the stored map create one"
        )
    if partial_exp is None:
        e_z = n_ep - 1 if match_exp == "first" else pick_experience(partial, z)
        if e_z < 0:
            e_z = partial.current_exp
    else:
        e_z = int(partial_exp)
    if not -1 <= e_z < n_ep:
        raise GraphError(f"partial experience {e_z} does not exist (the partial map has {n_ep})")
    dims = np.asarray(partial.pc_dims, np.float64)
    axis = str(partial.config.get("pc_axis", "openratslam"))  # OpenRatSLAM's when unsaid

    # (i) templates, Eq. 9
    keep_t = np.ones(n_vp, bool)
    keep_t[z] = False
    tmap = _remap(n_vp, z, u, n_vl)
    # (ii)/(iii) pose cells, Eqs. 10-12
    delta = loaded.template_pc[u] - partial.template_pc[z]
    assoc_shift = delta if shift_pose_cells else np.zeros(3)
    if shift_pose_cells and pc_shift_rotate:
        t_pc = _rotate_shift(
            partial.template_pc[keep_t], partial.template_pc[z], loaded.template_pc[u], dims, axis
        )
    else:
        t_pc = np.mod(partial.template_pc[keep_t] + assoc_shift, dims)
    # (iv) experiences, Eqs. 13-17
    if e_z >= 0:
        dth = float(
            wrap_angle(
                loaded.exp_pose[e_u, 2] - partial.exp_pose[e_z, 2] + relative_rad, include_pi=True
            )
        )
        c, s = math.cos(dth), math.sin(dth)
        pz = partial.exp_pose[e_z, :2]
        tx = loaded.exp_pose[e_u, 0] - (c * pz[0] - s * pz[1])
        ty = loaded.exp_pose[e_u, 1] - (s * pz[0] + c * pz[1])
    else:  # a partial map without experiences: nothing to move
        dth, tx, ty = 0.0, 0.0, 0.0
    keep_e = np.ones(n_ep, bool)
    if e_z >= 0:
        keep_e[e_z] = False
    emap = _remap(n_ep, e_z, e_u, n_el)
    new_pose = rigid_transform(partial.exp_pose[keep_e], dth, tx, ty)
    if not shift_pose_cells:
        exp_shift = np.zeros(3)
    elif exp_pc_shift == "experiences" and e_z >= 0:
        exp_shift = loaded.exp_pc[e_u] - partial.exp_pc[e_z]
    else:
        exp_shift = delta
    if shift_pose_cells and pc_shift_rotate:
        by_exp = exp_pc_shift == "experiences" and e_z >= 0
        src = partial.exp_pc[e_z] if by_exp else partial.template_pc[z]
        new_pc = _rotate_shift(partial.exp_pc[keep_e], src, src + exp_shift, dims, axis)
    else:
        new_pc = np.mod(partial.exp_pc[keep_e] + exp_shift, dims)
    new_tpl = _apply(tmap, partial.exp_template[keep_e])
    lf, lt = _apply(emap, partial.link_from), _apply(emap, partial.link_to)
    keep_l = lf != lt  # a link between e_z and e_u cannot exist; guard anyway

    def cat(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.concatenate([a, b.astype(a.dtype, copy=False)])

    extra: dict[str, np.ndarray] = {}
    keep_of = {"template": keep_t, "exp": keep_e, "link": keep_l}
    for key in sorted(set(loaded.extra) | set(partial.extra)):
        prefix = key.split(":", 1)[0] if ":" in key else ""
        if prefix in PER_ENTITY:
            a, b = loaded.extra.get(key), partial.extra.get(key)
            n_a = getattr(loaded, PER_ENTITY[prefix]).shape[0]
            n_b = getattr(partial, PER_ENTITY[prefix]).shape[0]
            ref = a if a is not None else b
            assert ref is not None  # the key comes from one of the two maps
            fill = _FILL.get(key, 0)
            if a is None:
                a = np.full((n_a, *ref.shape[1:]), fill, ref.dtype)
            if b is None:
                b = np.full((n_b, *ref.shape[1:]), fill, ref.dtype)
            extra[key] = cat(a, b[keep_of[prefix]])
        elif key == "ref.goal_list":  # goal experience ids of both maps, in merged ids
            goals = [np.asarray(loaded.extra.get(key, np.zeros(0)), np.int64)]
            if key in partial.extra:
                goals.append(_apply(emap, np.asarray(partial.extra[key], np.int64)))
            extra[key] = np.concatenate(goals)
        elif key in partial.extra:
            extra[key] = np.array(partial.extra[key], copy=True)
    # the session's running values move with the robot into the loaded map
    if EM_ACCUM in extra:  # [x, y, facing, time] accumulated in the partial map's frame
        acc = np.array(extra[EM_ACCUM], np.float64, copy=True)
        acc[:2] = rigid_transform(acc[:2], dth, 0.0, 0.0)
        acc[2] = float(wrap_angle(acc[2] + dth, include_pi=True))
        extra[EM_ACCUM] = acc
    if PC_BEST in extra:  # the decoded packet centre moves with the activity roll
        src = partial.template_pc[z]
        roll = np.rint(src + delta) - np.rint(src)
        extra[PC_BEST] = np.mod(np.asarray(extra[PC_BEST], np.float64) + roll, dims)
    ids: dict[str, Any] = {k: int(getattr(partial, k)) for k in INT_FIELDS}
    ids["current_vt"] = int(_apply(tmap, ids["current_vt"]))
    ids["prev_vt"] = int(_apply(tmap, ids["prev_vt"]))
    ids["current_exp"] = int(_apply(emap, ids["current_exp"])) if ids["current_exp"] >= 0 else e_u
    ids["prev_exp"] = int(_apply(emap, ids["prev_exp"]))

    merged = MapState(
        config=dict(partial.config),
        templates=cat(loaded.templates, partial.templates[keep_t]),
        template_mean=cat(loaded.template_mean, partial.template_mean[keep_t]),
        template_frame=cat(loaded.template_frame, partial.template_frame[keep_t]),
        template_pc=cat(loaded.template_pc, t_pc),
        template_decay=cat(loaded.template_decay, partial.template_decay[keep_t]),
        exp_pose=cat(loaded.exp_pose, new_pose),
        exp_pc=cat(loaded.exp_pc, new_pc),
        exp_template=cat(loaded.exp_template, new_tpl),
        exp_frame=cat(loaded.exp_frame, partial.exp_frame[keep_e]),
        exp_t=cat(loaded.exp_t, partial.exp_t[keep_e]),
        link_from=cat(loaded.link_from, lf[keep_l]),
        link_to=cat(loaded.link_to, lt[keep_l]),
        link_d=cat(loaded.link_d, partial.link_d[keep_l]),
        link_heading=cat(loaded.link_heading, partial.link_heading[keep_l]),
        link_facing=cat(loaded.link_facing, partial.link_facing[keep_l]),
        link_dt=cat(loaded.link_dt, partial.link_dt[keep_l]),
        activity=shift_activity(partial.activity, delta, partial.template_pc[z]),
        extra=extra,
        scalars={k: v for k, v in partial.scalars.items() if not k.startswith(_DROP_SCALARS)},
        current_vt=ids["current_vt"],
        prev_vt=ids["prev_vt"],
        current_exp=ids["current_exp"],
        prev_exp=ids["prev_exp"],
        frame_index=ids["frame_index"],
    )
    info = {
        "loaded_template": u,
        "partial_template": z,
        "loaded_exp": e_u,
        "partial_exp": e_z,
        "pc_shift": [float(v) for v in delta],
        "pc_shift_applied": bool(shift_pose_cells),
        "exp_pc_shift": [float(v) for v in exp_shift],
        "exp_pc_shift_mode": exp_pc_shift,
        "match_exp": match_exp,
        "transform": [dth, float(tx), float(ty)],
        "template_ids": tmap,
        "exp_ids": emap,
        "templates_added": int(keep_t.sum()),
        "experiences_added": int(keep_e.sum()),
        "links_added": int(keep_l.sum()),
    }
    log.info(
        "merged maps at loaded template %d / partial template %d: %d templates, %d "
        "experiences and %d links added; pose-cell shift %s%s",
        u,
        z,
        info["templates_added"],
        info["experiences_added"],
        info["links_added"],
        [round(float(v), 3) for v in delta],
        "" if shift_pose_cells else " (not applied)",
    )
    return MergeResult(state=dataclasses.replace(merged), info=info)


def append_place(
    state: MapState,
    view: np.ndarray,
    *,
    at_accum: np.ndarray,
    at_pc: np.ndarray,
    frame: int,
    t: float,
) -> MapState:
    """Add a place the robot passed since its current experience: a template holding
    ``view``, associated with the packet ``at_pc``, and an experience at the current
    experience's pose plus ``at_accum``, linked from the current experience, made current.

    This is what RatSLAM itself does when a view is new (``CREATE``), done afterwards for
    a view that matched a stored map (:class:`~torchratslam.multisession.session.
    MultiSessionRatSLAM` with ``merge_anchor="view"``): the merge then identifies this
    template and experience with the stored ones, at the place where the view matched
    best. The odometry accumulated since ``at_accum`` stays accumulated (relative to the
    new experience).

    Args:
        state: the partial map (with its ``EM_ACCUM`` and ``PC_BEST`` extras).
        view: the preprocessed view. Shape: ``(Y, X)``.
        at_accum: the experience map's accumulators ``[x, y, facing, time]`` when the
            view was seen (map frame, as ``EM_ACCUM``).
        at_pc: the packet centre ``(x, y, th)`` cells when the view was seen.
        frame: the frame the view was seen at; ``t``: its time (s).

    Returns:
        The map with one template, one experience and one link more.

    Raises:
        GraphError: the map has no current experience.
    """
    cur = int(state.current_exp)
    if not 0 <= cur < state.n_experiences:
        raise GraphError("append_place needs a map with a current experience")
    acc = np.asarray(at_accum, np.float64).reshape(4)
    pc = np.mod(np.asarray(at_pc, np.float64).reshape(3), np.asarray(state.pc_dims, np.float64))
    now = np.asarray(state.extra.get(EM_ACCUM, acc), np.float64).reshape(4)
    th_src = float(state.exp_pose[cur, 2])
    facing = float(wrap_angle(acc[2], include_pi=True))
    pose = np.array([state.exp_pose[cur, 0] + acc[0], state.exp_pose[cur, 1] + acc[1], facing])
    link = (
        math.hypot(acc[0], acc[1]),
        float(wrap_angle(math.atan2(acc[1], acc[0]) - th_src, include_pi=True)),
        float(wrap_angle(facing - th_src, include_pi=True)),
    )
    per_link = str(state.config.get("exp_link_time", "per_link")) == "per_link"
    n_t, n_e = state.n_templates, state.n_experiences
    view = np.asarray(view, state.templates.dtype).reshape(state.templates.shape[1:])
    fill = {"exp:pc_template": n_t, "exp:em_pc": pc}
    extra: dict[str, np.ndarray] = {}
    for key, val in state.extra.items():
        prefix = key.split(":", 1)[0] if ":" in key else ""
        arr = np.asarray(val)
        if prefix in PER_ENTITY:
            row = np.broadcast_to(
                np.asarray(fill.get(key, _FILL.get(key, 0)), arr.dtype), arr.shape[1:]
            )
            extra[key] = np.concatenate([arr, row[None]])
        else:
            extra[key] = np.array(arr, copy=True)
    extra[EM_ACCUM] = np.array(
        [now[0] - acc[0], now[1] - acc[1], now[2], now[3] - acc[3] if per_link else now[3]],
        np.float64,
    )
    scalars = {k: v for k, v in state.scalars.items() if k != "pc.current_exp"}
    decay = float(state.config.get("vt_active_decay", 1.0))
    out = dataclasses.replace(
        state,
        templates=np.concatenate([state.templates, view[None]]),
        template_mean=np.r_[state.template_mean, float(view.mean())],
        template_frame=np.r_[state.template_frame, int(frame)].astype(np.int64),
        template_pc=np.concatenate([state.template_pc, pc[None]]),
        template_decay=np.r_[state.template_decay, decay],
        exp_pose=np.concatenate([state.exp_pose, pose[None]]),
        exp_pc=np.concatenate([state.exp_pc, pc[None]]),
        exp_template=np.r_[state.exp_template, n_t].astype(np.int64),
        exp_frame=np.r_[state.exp_frame, int(frame)].astype(np.int64),
        exp_t=np.r_[state.exp_t, float(t)],
        link_from=np.r_[state.link_from, cur].astype(np.int64),
        link_to=np.r_[state.link_to, n_e].astype(np.int64),
        link_d=np.r_[state.link_d, link[0]],
        link_heading=np.r_[state.link_heading, link[1]],
        link_facing=np.r_[state.link_facing, link[2]],
        link_dt=np.r_[state.link_dt, acc[3]],
        extra=extra,
        scalars=scalars,
        current_vt=n_t,
        prev_vt=int(state.current_vt),
        current_exp=n_e,
        prev_exp=cur,
    )
    return out.validate(source="append_place")


def fuse_templates(
    state: MapState, pairs: list[tuple[int, int]]
) -> tuple[MapState, np.ndarray, list[tuple[int, int]]]:
    """Identify templates of one map with others, as the merge identifies ``z`` with ``u``.

    For every ``(drop, keep)`` pair, template ``drop`` is removed; each of its
    experiences is removed too and the links that ended or started at it are re-pointed
    at ``keep``'s first experience (link measurements are relative and stay valid; a
    link that would join an experience to itself, or a pair already linked, is dropped). Used by
    :class:`~torchratslam.multisession.session.MultiSessionRatSLAM` with
    ``merge_absorb=True``: the partial templates that had already matched the stored
    map before a delayed merge are the stored map's places seen again.

    Args:
        state: the map (normally just merged).
        pairs: ``(drop, keep)`` template ids; a pair whose ``keep`` has no experience,
            or whose ``drop`` is also a ``keep``, is skipped.

    Returns:
        ``(fused map, old -> new experience id map (-1 never happens: a removed
        experience maps to its replacement), the pairs applied)``.
    """
    n_t, n_e = state.n_templates, state.n_experiences
    keeps = {int(k) for _, k in pairs}
    tgt_t = np.arange(n_t, dtype=np.int64)
    tgt_e = np.arange(n_e, dtype=np.int64)
    applied: list[tuple[int, int]] = []
    for d, k in pairs:
        d, k = int(d), int(k)
        if d == k or d in keeps or not (0 <= d < n_t and 0 <= k < n_t):
            continue
        e_k = first_experience(state, k)
        if e_k < 0:
            continue
        tgt_t[d] = k
        tgt_e[state.exp_template == d] = e_k
        applied.append((d, k))
    keep_t = tgt_t == np.arange(n_t)
    keep_e = tgt_e == np.arange(n_e)
    if keep_t.all() and keep_e.all():
        return state, np.arange(n_e, dtype=np.int64), applied
    new_t = np.cumsum(keep_t) - 1  # new id of every kept template
    new_e = np.cumsum(keep_e) - 1
    tmap = new_t[tgt_t]
    emap = new_e[tgt_e]
    lf, lt = _apply(emap, state.link_from), _apply(emap, state.link_to)
    keep_l = lf != lt
    # one link per pair of experiences: a re-pointed link that duplicates one the map
    # already has is dropped, the earlier one kept
    pair = np.stack([lf, lt], axis=1)
    _, first = np.unique(pair, axis=0, return_index=True)
    unique = np.zeros(lf.shape[0], bool)
    unique[first] = True
    keep_l &= unique
    keep_of = {"template": keep_t, "exp": keep_e, "link": keep_l}
    extra: dict[str, np.ndarray] = {}
    for key, val in state.extra.items():
        prefix = key.split(":", 1)[0] if ":" in key else ""
        if prefix in PER_ENTITY:
            extra[key] = np.asarray(val)[keep_of[prefix]]
        elif key == "ref.goal_list":
            extra[key] = _apply(emap, np.asarray(val, np.int64))
        else:
            extra[key] = val
    fused = dataclasses.replace(
        state,
        templates=state.templates[keep_t],
        template_mean=state.template_mean[keep_t],
        template_frame=state.template_frame[keep_t],
        template_pc=state.template_pc[keep_t],
        template_decay=state.template_decay[keep_t],
        exp_pose=state.exp_pose[keep_e],
        exp_pc=state.exp_pc[keep_e],
        exp_template=_apply(tmap, state.exp_template[keep_e]),
        exp_frame=state.exp_frame[keep_e],
        exp_t=state.exp_t[keep_e],
        link_from=lf[keep_l],
        link_to=lt[keep_l],
        link_d=state.link_d[keep_l],
        link_heading=state.link_heading[keep_l],
        link_facing=state.link_facing[keep_l],
        link_dt=state.link_dt[keep_l],
        extra=extra,
        current_vt=int(_apply(tmap, state.current_vt)),
        prev_vt=int(_apply(tmap, state.prev_vt)),
        current_exp=int(_apply(emap, state.current_exp)),
        prev_exp=int(_apply(emap, state.prev_exp)),
    )
    log.info(
        "fused %d templates and %d experiences into the stored map's",
        int((~keep_t).sum()),
        int((~keep_e).sum()),
    )
    return fused, emap, applied
