"""Multisession RatSLAM (the multisession paper, Section 3 and Algorithm 1).

:class:`MultiSessionRatSLAM` maps a new session like :class:`~torchratslam.pipeline.RatSLAM`
(the *partial map*) while holding one or more stored maps (kappa >= 1). Every NEW
template of the partial map is also matched against every still-separate stored map's
templates, with the local view's own matcher; on a match below ``vt_match_threshold``
the stored map and the partial map are merged (:func:`torchratslam.maps.merge.merge_maps`),
the running modules continue in the merged structure (the stored map's frame and
pose-cell coordinates), and the experience map relaxes with the configured backend.
Stored maps are merged one after another as the session meets them. When the very
first view of the session matches a stored map (scenario (i)), the same merge moves
nothing but the robot: mapping continues in that map from the matching experience.

Example:
    >>> from torchratslam.multisession.session import MultiSessionRatSLAM  # doctest: +SKIP
    >>> from torchratslam.maps.native import load_state  # doctest: +SKIP
    >>> slam = MultiSessionRatSLAM(config, [load_state("out/session1")])  # doctest: +SKIP
    >>> slam.run(open_sim("sim:virtual_tour/session2"))  # doctest: +SKIP
    >>> slam.merges  # doctest: +SKIP
    [{'frame': 19, 'map': 0, 'session': 'session', ...}]
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
import torch

from ratslam_graph.geometry import wrap_angle
from ratslam_graph.protocols import ExperienceMapModule
from torchratslam.config import RatSLAMConfig
from torchratslam.errors import ConfigError
from torchratslam.maps.compat import conform
from torchratslam.maps.merge import (
    append_place,
    first_experience,
    fuse_templates,
    merge_maps,
    pick_experience,
)
from torchratslam.maps.running import apply_state, state_from_slam
from torchratslam.maps.state import EM_ACCUM, PC_BEST, MapState
from torchratslam.messages import SessionState
from torchratslam.pipeline.ratslam import RatSLAM
from torchratslam.pipeline.results import RunResult, StepResult
from torchratslam.protocols import LocalViewModule, OdometrySource, PoseCellModule

__all__ = ["MERGE_ANCHORS", "MultiSessionRatSLAM"]

MERGE_ANCHORS = ("template", "view")
"""``MultiSessionRatSLAM(merge_anchor=...)``: where a merge joins the two maps.
``"template"`` (default, the paper): the partial template that matched is identified with
the stored one at once; ``"view"`` (a deviation): from that match on, every frame's view
is compared with the stored template ``u``; while the error falls the merge waits, and
when it rises (or after :data:`MAX_ANCHOR_FRAMES`, or when the partial map makes an
experience) the maps are joined at the frame of the smallest error, whose view becomes
the partial map's matching template (:func:`~torchratslam.maps.merge.append_place`).
With ``merge_persist`` > 1 the frames passed since the first match of the streak are
compared too (the best view can lie between the first matching template and the
confirming one); a passed place is linked from the experience current then.
Templates are learnt a few frames apart, so the template that matched can lie up to half
a template spacing from ``u``'s place; the view's best match lies within a frame."""
MAX_ANCHOR_FRAMES = 30
"""``merge_anchor="view"``: the merge waits at most this many frames for the best view."""

log = logging.getLogger(__name__)


class MultiSessionRatSLAM:
    """RatSLAM that merges the session's partial map with stored maps when they meet.

    Args:
        config: the configuration (pose-cell and template sizes must equal the stored
            maps').
        stored: the stored maps (``load_state`` results), kappa >= 0 of them.
        shift_pose_cells: False skips step (iii) of the merge (the paper's Fig. 12
            ablation: the partial map's pose-cell associations are not shifted).
        names: a name per stored map for reports (default ``"map0"``, ``"map1"``, ...).
        session: the session's name (:attr:`session_name`), recorded in :attr:`merges`.
        keep_snapshots: keep the experience poses before and after each merge in
            :attr:`snapshots` (for figures).
        merge_options: extra arguments of :func:`~torchratslam.maps.merge.merge_maps`
            (``exp_pc_shift``, ``match_exp``; default: the authors' code).
        merge_threshold: match error below which a new template matches a stored map's
            template (default None: ``vt_match_threshold``, the paper's single
            threshold). A deviation when set.
        merge_persist: merge only when this many consecutive new templates match the
            same stored map (default 1: the first match merges, the paper). A
            deviation when > 1; the merge uses the last match.
        merge_absorb: at a merge delayed by ``merge_threshold`` or ``merge_persist``,
            also identify the partial templates that had already matched the same
            stored map under ``vt_match_threshold`` (the paper's threshold; the
            consecutive new templates just before the merge) with their matches, as the
            merge does with ``z``: their experiences are dropped and their links
            re-pointed at the stored matches' first experiences
            (:func:`~torchratslam.maps.merge.fuse_templates`). Without it a delayed
            merge keeps one copy of each such place. Default False; a deviation (the
            paper merges at the first match, so there is nothing to absorb). With
            ``merge_anchor="view"`` the matched template is absorbed too, and the
            re-pointed links are measured anew from the merged map's poses (the
            odometry between the experiences they join).
        merge_anchor: where a merge joins the maps, see :data:`MERGE_ANCHORS`
            (default ``"template"``, the paper); ``"view"`` waits while the view keeps
            matching the stored template better (at most :data:`MAX_ANCHOR_FRAMES`).
        **ratslam_kwargs: passed to :class:`~torchratslam.pipeline.RatSLAM`
            (``local_view``, ``pose_cells``, ``experience_map``, ``odometry``, ``dtype``,
            ``device``).

    Attributes:
        slam: the running :class:`RatSLAM`; ``config``, ``local_view``, ``pose_cells``,
            ``experience_map``, ``odometry`` and ``session`` (the
            :class:`~torchratslam.messages.SessionState` record) are the slam's, and so is
            every other attribute not defined here (``frame_index``, ``timings``,
            ``trajectory()``, ...).
        session_name: the session's name.
        merges: one dict per merge: ``frame``, ``map`` (index in ``stored``),
            ``map_name``, ``session``, ``scenario`` ("i": first view, "ii": a partial
            map), ``error``, ``loaded_template``, ``loaded_exp``, ``loaded_exp_t`` and
            ``partial_exp_t`` (creation times of the two matched experiences; a first
            view: its frame's time), ``pc_shift``,
            ``transform`` (dth, tx, ty), ``templates_added``, ``experiences_added``,
            ``partial_experiences`` (the partial map's experiences at the merge, the
            dropped ``e_z`` included),
            ``absorbed`` (``merge_absorb``: the (template, stored template) pairs
            identified besides ``z``, in the merged map's ids before the fusion),
            ``time_s``.
        snapshots: per merge: ``loaded`` and ``partial`` experience poses (N, 3) before
            the merge, ``merged`` after it (before relaxation), ``relaxed`` after the
            relaxation, ``n_loaded``, ``partial_state`` and ``merged_state`` (MapStates).
        pending: indices of the stored maps not merged yet.
    """

    def __init__(
        self,
        config: RatSLAMConfig,
        stored: list[MapState] | tuple[MapState, ...] = (),
        *,
        shift_pose_cells: bool = True,
        names: list[str] | None = None,
        session: str = "session",
        keep_snapshots: bool = True,
        merge_options: dict[str, Any] | None = None,
        merge_threshold: float | None = None,
        merge_persist: int = 1,
        merge_absorb: bool = False,
        merge_anchor: str = "template",
        **ratslam_kwargs: Any,
    ) -> None:
        if merge_anchor not in MERGE_ANCHORS:
            raise ConfigError(f"merge_anchor must be one of {MERGE_ANCHORS}, got {merge_anchor!r}")
        self.merge_anchor = merge_anchor
        # merge_anchor="view": the match being followed (see _follow)
        self._anchor: dict[str, Any] | None = None
        self._image: Any = None
        if merge_threshold is not None and not merge_threshold > 0:
            raise ConfigError(f"merge_threshold must be > 0 (or None), got {merge_threshold!r}")
        if int(merge_persist) < 1:
            raise ConfigError(f"merge_persist must be >= 1, got {merge_persist!r}")
        self.merge_threshold = None if merge_threshold is None else float(merge_threshold)
        self.merge_persist = int(merge_persist)
        self._streak = (-1, 0)  # (stored map, consecutive new templates matching it)
        # merge_anchor="view": the frames passed since the streak's first match (_place)
        self._trail: list[dict[str, Any]] = []
        self.merge_absorb = bool(merge_absorb)
        # (partial template, stored map, stored template): the consecutive new templates
        # that matched a stored map under vt_match_threshold without merging yet
        self._seen: list[tuple[int, int, int]] = []
        self.merge_options = dict(merge_options or {})
        self.slam = RatSLAM(config, **ratslam_kwargs)
        self.stored = [
            conform(s, config, what=f"stored map {i} ({s.name or 'in memory'})")
            for i, s in enumerate(stored)
        ]
        self.names = (
            list(names)
            if names is not None
            else [s.name or f"map{i}" for i, s in enumerate(self.stored)]
        )
        self.shift_pose_cells = bool(shift_pose_cells)
        self.session_name = session
        self.keep_snapshots = keep_snapshots
        self.merges: list[dict[str, Any]] = []
        self.snapshots: list[dict[str, Any]] = []
        self.pending: list[int] = list(range(len(self.stored)))
        self._banks = [self._bank_of(s) for s in self.stored]

    # ------------------------------------------------------------------ delegation
    def __getattr__(self, name: str) -> Any:
        if name == "slam":  # not built yet (during unpickling / failed __init__)
            raise AttributeError(name)
        return getattr(self.slam, name)

    # ------------------------------------------------------------------ the slam's members
    @property
    def config(self) -> RatSLAMConfig:
        """The running slam's configuration."""
        return self.slam.config

    @property
    def local_view(self) -> LocalViewModule:
        """The running slam's local view."""
        return self.slam.local_view

    @property
    def pose_cells(self) -> PoseCellModule:
        """The running slam's pose cells."""
        return self.slam.pose_cells

    @property
    def experience_map(self) -> ExperienceMapModule:
        """The running slam's experience map."""
        return self.slam.experience_map

    @property
    def odometry(self) -> OdometrySource:
        """The running slam's odometry source."""
        return self.slam.odometry

    @property
    def session(self) -> SessionState:
        """The running slam's session record (assigning one restores it)."""
        return self.slam.session

    @session.setter
    def session(self, value: SessionState) -> None:
        self.slam.session = value

    def remap_experiences(self, old_to_new: np.ndarray) -> None:
        """Re-point the per-frame history at new experience ids (see ``RatSLAM``)."""
        self.slam.remap_experiences(old_to_new)

    def _bank_of(self, state: MapState) -> Any:
        """A local view (same class, params, dtype) holding ``state``'s templates."""
        lv: Any = self.slam.local_view  # a template local view (params, dtype, device)
        bank = type(lv)(lv.params, dtype=lv.dtype, device=lv.device)
        if state.n_templates:
            bank.add_templates(torch.as_tensor(np.asarray(state.templates)))
        return bank

    # ------------------------------------------------------------------ stepping
    def step(self, image: Any, odometry: tuple[float, float, float] | None = None) -> StepResult:
        """Process one image with its odometry (see ``RatSLAM.step``), merging if due; a
        refused step (bad odometry) leaves everything as it was."""
        result = self.slam.step(image, odometry)
        self.keep_image(image)
        return self._after_step(result)

    def step_frame(self, frame: Any) -> StepResult:
        """Process one :class:`~torchratslam.messages.Frame`, merging if due."""
        result = self.slam.step_frame(frame)
        self.keep_image(frame.image)
        return self._after_step(result)

    def keep_image(self, image: Any) -> None:
        """Remember the image being processed (``merge_anchor="view"`` compares it)."""
        self._image = image

    def run(
        self,
        frames: Iterable[Any] | Any,
        *,
        max_frames: int | None = None,
        progress: bool | str | None = None,
        callback: Callable[[StepResult], None] | None = None,
        **kwargs: Any,
    ) -> RunResult:
        """Process a sequence of frames (see ``RatSLAM.run``); merges happen between
        frames, so the run is always sequential."""
        kwargs.pop("pipelined", None)

        def after(r: StepResult) -> None:
            r = self._after_step(r)
            if callback is not None:
                callback(r)

        if self.merge_anchor == "view":
            source: Any = frames
            frames = _tap(source.frames() if hasattr(source, "frames") else source, self)
        return self.slam.run(
            frames,
            max_frames=max_frames,
            progress=progress,
            pipelined=False,
            callback=after,
            **kwargs,
        )

    # ------------------------------------------------------------------ merging
    def match_stored(self, template: Any) -> tuple[int, int, int, float]:
        """Best match of a template among the pending stored maps.

        Returns:
            ``(map index, template id, offset, error)``; ``(-1, -1, 0, inf)`` if none
            of them has a template with an experience.

        Shape:
            template: ``(Y, X)``.
        """
        best = (-1, -1, 0, float("inf"))
        for k in self.pending:
            tid, offset, err = self._banks[k].match(template)
            if tid < 0 or err >= best[3]:
                continue
            if pick_experience(self.stored[k], int(tid)) < 0:
                continue  # a template without an experience cannot anchor a merge
            best = (k, int(tid), int(offset), float(err))
        return best

    def _after_step(self, result: StepResult) -> StepResult:
        if self._anchor is not None:
            return self._follow(result)
        if self._trail and self._streak[1] > 0:  # a match waits for its confirmation
            self._trail.append(_place(self.slam, self._image, result.frame, math.inf, 0))
            del self._trail[:-MAX_ANCHOR_FRAMES]
        if not self.pending or not result.view.is_new:
            return result
        template = self.slam.local_view.templates[int(result.view.template_id)]
        k, tid, offset, err = self.match_stored(template)
        paper = self.slam.config.local_view.vt_match_threshold
        threshold = paper if self.merge_threshold is None else self.merge_threshold
        if k < 0 or err > paper:
            self._seen = []
        if k < 0 or err > threshold:
            self._streak = (-1, 0)
            self._trail = []
            if k >= 0 and err <= paper:
                self._seen.append((int(result.view.template_id), k, tid))
            return result
        streak = self._streak[1] + 1 if self._streak[0] == k else 1
        self._streak = (k, streak)
        if streak == 1 or self.merge_anchor != "view":
            self._trail = []
        if streak < self.merge_persist:
            self._seen.append((int(result.view.template_id), k, tid))
            if self.merge_anchor == "view" and not self._trail:
                self._trail = [_place(self.slam, self._image, result.frame, math.inf, 0)]
            return result
        self._streak = (-1, 0)
        absorb = [(p, t) for p, kk, t in self._seen if kk == k] if self.merge_absorb else []
        self._seen = []
        if self.merge_anchor == "view":
            best = _place(self.slam, self._image, result.frame, err, offset)
            trail, self._trail = self._trail[:-1], []  # the last one is this frame
            self._anchor = {
                "k": k,
                "u": tid,
                "absorb": [*absorb, (int(result.view.template_id), tid)]
                if self.merge_absorb
                else [],
                "frames": 0,
                "n_exp": self.slam.counts()[1],
                "best": _best_passed(self._banks[k], tid, trail, best),
            }
            return result
        self.merge_with(k, tid, offset=offset, error=err, frame=result.frame, absorb=absorb)
        return self._merged(result)

    def _merged(self, result: StepResult) -> StepResult:
        n_t, n_e, _ = self.slam.counts()
        return dataclasses.replace(
            result,
            experience_id=int(self.slam.experience_map.current_id),
            templates=n_t,
            experiences=n_e,
        )

    def _follow(self, result: StepResult) -> StepResult:
        """``merge_anchor="view"``: compare this frame's view with the matched stored
        template; merge at the best frame once the error rises."""
        a = self._anchor
        assert a is not None
        k, u = a["k"], a["u"]
        view = _view_of(self.slam, self._image)
        errs = self._banks[k].errors(view, [u])[0]
        j = int(torch.argmin(errs))
        err, offset = float(errs[j]), int(self._banks[k].offsets[j])
        a["frames"] += 1
        made_exp = self.slam.counts()[1] != a["n_exp"]
        if err < a["best"]["error"] and not made_exp:
            a["best"] = _place(self.slam, self._image, result.frame, err, offset)
            if a["frames"] < MAX_ANCHOR_FRAMES:
                return result
        self._anchor = None
        best = a["best"]
        if made_exp:  # the partial map moved on: join the maps here
            best = _place(self.slam, self._image, result.frame, err, offset)
        kw = {key: best[key] for key in ("offset", "error", "frame")}
        self.merge_with(k, u, absorb=a["absorb"], place=best, **kw)
        return self._merged(result)

    def merge_with(
        self,
        k: int,
        loaded_template: int,
        *,
        offset: int = 0,
        error: float = 0.0,
        frame: int | None = None,
        absorb: list[tuple[int, int]] | None = None,
        place: dict[str, Any] | None = None,
    ) -> dict[str, Any]:
        """Merge stored map ``k`` (matched at ``loaded_template``) into the running map
        now, relax, and record the merge.

        ``absorb``: ``(partial template, stored template)`` pairs also identified
        (``merge_absorb``; :func:`~torchratslam.maps.merge.fuse_templates`).
        ``place``: the view, frame, time, accumulators and packet at which the maps are
        joined (``merge_anchor="view"``; :func:`~torchratslam.maps.merge.append_place`),
        None: at the partial map's last template.

        Returns:
            The merge record appended to :attr:`merges`.
        """
        t0 = time.perf_counter()
        partial = state_from_slam(self.slam)
        scenario = "i" if partial.n_templates <= 1 else "ii"
        if place is not None:
            partial = _with_place(partial, place)
        loaded = self.stored[k]
        res = merge_maps(
            loaded,
            partial,
            loaded_template,
            relative_rad=float(self._banks[k].relative_rad(offset)),
            shift_pose_cells=self.shift_pose_cells,
            **self.merge_options,
        )
        state, exp_ids, absorbed = _absorbed(res, absorb or [], remeasure=place is not None)
        apply_state(state, self.slam, exp_ids=exp_ids)
        self.slam.experience_map.iterate()
        self.pending.remove(k)
        if self.keep_snapshots:
            relaxed = np.asarray(self.slam.experience_map.poses, np.float64)
            self.snapshots.append(_snapshot(loaded, partial, state, relaxed))
        rec = _merge_record(res.info, loaded, partial, state, absorbed)
        if not np.isfinite(rec["partial_exp_t"]):  # a first view: the robot is where it is
            rec["partial_exp_t"] = float(self.slam.session.last_t)
        rec.update(
            frame=int(self.slam.frame_index - 1 if frame is None else frame),
            map=int(k),
            map_name=self.names[k],
            session=self.session_name,
            scenario=scenario,
            error=float(error),
            time_s=time.perf_counter() - t0,
        )
        self.merges.append(rec)
        log.info(
            "frame %d: merged stored map %r (template %d matched, error %.4g) into the "
            "running map; %d experiences now",
            rec["frame"],
            rec["map_name"],
            rec["loaded_template"],
            rec["error"],
            self.slam.counts()[1],
        )
        return rec

    # ------------------------------------------------------------------ state
    def get_map(self) -> MapState:
        """The running map as a :class:`MapState`."""
        return state_from_slam(self.slam)

    def unmerged(self) -> list[MapState]:
        """The stored maps that were not merged (still separate)."""
        return [self.stored[k] for k in self.pending]


def _absorbed(
    res: Any, absorb: list[tuple[int, int]], *, remeasure: bool
) -> tuple[MapState, np.ndarray, list[tuple[int, int]]]:
    """The merged state with the ``absorb`` pairs (partial template, stored template)
    fused (:func:`~torchratslam.maps.merge.fuse_templates`; ``remeasure``: their links
    measured anew first), its experience ids and the pairs fused."""
    state, exp_ids = res.state, res.info["exp_ids"]
    if not absorb:
        return state, exp_ids, []
    tmap = res.info["template_ids"]
    pairs = [(int(tmap[p]), int(t)) for p, t in absorb if 0 <= p < tmap.size]
    if remeasure:
        state = _remeasured(state, pairs)
    state, fmap, absorbed = fuse_templates(state, pairs)
    return state, fmap[np.asarray(exp_ids, np.int64)], absorbed


def _snapshot(
    loaded: MapState, partial: MapState, state: MapState, relaxed: np.ndarray
) -> dict[str, Any]:
    """A merge's snapshot (:attr:`MultiSessionRatSLAM.snapshots`)."""
    return {
        "loaded": loaded.exp_pose.copy(),
        "partial": partial.exp_pose.copy(),
        "merged": state.exp_pose.copy(),
        "relaxed": relaxed.copy(),
        "n_loaded": np.array(loaded.n_experiences),
        "merged_state": state,
        "partial_state": partial,
    }


def _best_passed(
    bank: Any, u: int, trail: list[dict[str, Any]], best: dict[str, Any]
) -> dict[str, Any]:
    """The place matching stored template ``u`` (of ``bank``, a stored map's local view)
    best among ``best`` (the confirming frame) and the frames passed since the first
    match of the streak (``merge_anchor="view"`` with ``merge_persist`` > 1).

    The first of the ``merge_persist`` matching templates can lie before ``u``'s place
    and the confirming one after it: the view that matches ``u`` best is then among the
    frames between them, which the robot has already passed.
    """
    for place in trail:
        errs = bank.errors(torch.as_tensor(place["view"]), [u])[0]
        j = int(torch.argmin(errs))
        if float(errs[j]) < best["error"]:
            best = {**place, "error": float(errs[j]), "offset": int(bank.offsets[j])}
    return best


def _remeasured(state: MapState, pairs: list[tuple[int, int]]) -> MapState:
    """The merged map with every link that :func:`~torchratslam.maps.merge.fuse_templates`
    will re-point from a ``drop`` template's experience at its ``keep``'s first
    experience measured anew between the experiences it will join, from their poses in
    the merged map (``merge_anchor="view"``).

    The merge puts the partial map where the view matched best, so the pose of a partial
    experience relative to the stored one it is identified with is the odometry between
    them; a re-pointed link keeps that geometry instead of the dropped experience's
    (up to a template spacing away).
    """
    n_t = state.n_templates
    keeps = {int(k) for _, k in pairs}
    to = np.arange(state.n_experiences, dtype=np.int64)
    for d, k in pairs:
        if d == k or d in keeps or not (0 <= d < n_t and 0 <= k < n_t):
            continue  # as fuse_templates skips it
        e_k = first_experience(state, int(k))
        if e_k >= 0:
            to[state.exp_template == d] = e_k
    lf, lt = to[state.link_from], to[state.link_to]
    moved = ((lf != state.link_from) | (lt != state.link_to)) & (lf != lt)
    if not moved.any():
        return state
    p = state.exp_pose
    dx, dy = p[lt, 0] - p[lf, 0], p[lt, 1] - p[lf, 1]
    heading = wrap_angle(np.arctan2(dy, dx) - p[lf, 2], include_pi=True)
    facing = wrap_angle(p[lt, 2] - p[lf, 2], include_pi=True)
    return dataclasses.replace(
        state,
        link_d=np.where(moved, np.hypot(dx, dy), state.link_d),
        link_heading=np.where(moved, heading, state.link_heading),
        link_facing=np.where(moved, facing, state.link_facing),
    )


def _merge_record(
    info: dict[str, Any],
    loaded: MapState,
    partial: MapState,
    state: MapState,
    absorbed: list[tuple[int, int]],
) -> dict[str, Any]:
    """What a merge did (the fields of :attr:`MultiSessionRatSLAM.merges` that come from
    the maps)."""
    e_u, e_z = int(info["loaded_exp"]), int(info["partial_exp"])
    return {
        "loaded_template": int(info["loaded_template"]),
        "loaded_exp": e_u,
        "loaded_exp_t": float(loaded.exp_t[e_u]),
        "partial_exp_t": float(partial.exp_t[e_z]) if e_z >= 0 else float("nan"),
        "pc_shift": info["pc_shift"],
        "pc_shift_applied": info["pc_shift_applied"],
        "transform": [float(v) for v in info["transform"]],
        "templates_added": state.n_templates - loaded.n_templates,
        "experiences_added": state.n_experiences - loaded.n_experiences,
        "partial_experiences": int(partial.n_experiences),
        "absorbed": [list(p) for p in absorbed],
    }


def _tap(frames: Iterable[Any], ms: MultiSessionRatSLAM) -> Iterable[Any]:
    """The frames, each image kept on ``ms`` as it passes (``merge_anchor="view"``)."""
    for f in frames:
        ms.keep_image(getattr(f, "image", None))
        yield f


def _view_of(slam: RatSLAM, image: Any) -> torch.Tensor:
    """``image`` as the local view's template."""
    lv: Any = slam.local_view  # a template local view: it has ``preprocess``
    return lv.preprocess(image)


def _place(slam: RatSLAM, image: Any, frame: int, err: float, offset: int) -> dict[str, Any]:
    """This frame as the place to join the maps at (``merge_anchor="view"``): the view,
    its match with the stored template, and the accumulators and packet now."""
    state = state_from_slam(slam)
    return {
        "error": float(err),
        "offset": int(offset),
        "frame": int(frame),
        "t": float(slam.session.last_t),
        "view": _view_of(slam, image).detach().cpu().numpy(),
        "accum": np.asarray(state.extra[EM_ACCUM], np.float64).copy(),
        "pc": np.asarray(state.extra[PC_BEST], np.float64).copy(),
        "exp": int(state.current_exp),
    }


def _with_place(partial: MapState, place: dict[str, Any]) -> MapState:
    """The partial map with the place of :func:`_place` appended.

    A place passed before the current experience was made (the streak's first match
    lies before the stored template's place, the confirming one after it) is added
    where the robot was: linked from the experience current then, at its pose plus the
    odometry accumulated then; the robot stays at its current experience with its
    accumulators.
    """
    cur = int(partial.current_exp)
    at = int(place.get("exp", cur))
    kw = {"at_accum": place["accum"], "at_pc": place["pc"], "frame": place["frame"]}
    if at == cur or not 0 <= at < partial.n_experiences:
        return append_place(partial, place["view"], t=place["t"], **kw)
    then = dataclasses.replace(partial, current_exp=at)
    out = append_place(then, place["view"], t=place["t"], **kw)
    extra = {**out.extra, EM_ACCUM: np.array(partial.extra[EM_ACCUM], np.float64, copy=True)}
    return dataclasses.replace(
        out,
        extra=extra,
        scalars=dict(partial.scalars),
        current_vt=partial.current_vt,
        prev_vt=partial.prev_vt,
        current_exp=cur,
        prev_exp=partial.prev_exp,
    ).validate(source="a place passed")
