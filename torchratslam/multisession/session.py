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
    >>> from torchratslam.maps.state import load_state  # doctest: +SKIP
    >>> slam = MultiSessionRatSLAM(config, [load_state("out/session1")])  # doctest: +SKIP
    >>> slam.run(open_sim("sim:virtual_tour/session2"))  # doctest: +SKIP
    >>> slam.merges  # doctest: +SKIP
    [{'frame': 19, 'map': 0, 'session': 'session', ...}]
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
import torch

from torchratslam.config import RatSLAMConfig
from torchratslam.maps.merge import merge_maps, pick_experience
from torchratslam.maps.state import (
    MapState,
    apply_state,
    conform,
    state_from_slam,
)
from torchratslam.pipeline import RatSLAM, RunResult, StepResult

__all__ = ["MultiSessionRatSLAM"]


class MultiSessionRatSLAM:
    """RatSLAM that merges the session's partial map with stored maps when they meet.

    Args:
        config: the configuration (pose-cell and template sizes must equal the stored
            maps').
        stored: the stored maps (``load_state`` results), kappa >= 0 of them.
        shift_pose_cells: False skips step (iii) of the merge (the paper's Fig. 12
            ablation: the partial map's pose-cell associations are not shifted).
        names: a name per stored map for reports (default ``"map0"``, ``"map1"``, ...).
        session: the session's name, recorded in :attr:`merges`.
        keep_snapshots: keep the experience poses before and after each merge in
            :attr:`snapshots` (for figures).
        **ratslam_kwargs: passed to :class:`~torchratslam.pipeline.RatSLAM`
            (``local_view``, ``pose_cells``, ``experience_map``, ``odometry``, ``dtype``,
            ``device``).

    Attributes:
        slam: the running :class:`RatSLAM`; every attribute not defined here
            (``config``, ``local_view``, ``pose_cells``, ``experience_map``,
            ``frame_index``, ``timings``, ``trajectory()``, ...) is the slam's.
        merges: one dict per merge: ``frame``, ``map`` (index in ``stored``),
            ``map_name``, ``session``, ``scenario`` ("i": first view, "ii": a partial
            map), ``error``, ``loaded_template``, ``loaded_exp``, ``pc_shift``,
            ``transform`` (dth, tx, ty), ``templates_added``, ``experiences_added``,
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
        **ratslam_kwargs: Any,
    ) -> None:
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
        self.session = session
        self.keep_snapshots = keep_snapshots
        self.merges: list[dict[str, Any]] = []
        self.snapshots: list[dict[str, np.ndarray]] = []
        self.pending: list[int] = list(range(len(self.stored)))
        self._banks = [self._bank_of(s) for s in self.stored]

    # ------------------------------------------------------------------ delegation
    def __getattr__(self, name: str) -> Any:
        if name == "slam":  # not built yet (during unpickling / failed __init__)
            raise AttributeError(name)
        return getattr(self.slam, name)

    def _bank_of(self, state: MapState) -> Any:
        """A local view (same class, params, dtype) holding ``state``'s templates."""
        lv = self.slam.local_view
        bank = type(lv)(lv.params, dtype=lv.dtype, device=lv.device)
        if state.n_templates:
            bank.add_templates(torch.as_tensor(np.asarray(state.templates)))
        return bank

    # ------------------------------------------------------------------ stepping
    def step(self, image: Any, odometry: tuple[float, float, float] | None = None) -> StepResult:
        """Process one image with its odometry (see ``RatSLAM.step``), merging if due."""
        return self._after_step(self.slam.step(image, odometry))

    def step_frame(self, frame: Any) -> StepResult:
        """Process one :class:`~torchratslam.messages.Frame`, merging if due."""
        return self._after_step(self.slam.step_frame(frame))

    def run(
        self,
        frames: Iterable[Any] | Any,
        *,
        max_frames: int | None = None,
        progress: bool = True,
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
        if not self.pending or not result.view.is_new:
            return result
        template = self.slam.local_view.templates[int(result.view.template_id)]
        k, tid, offset, err = self.match_stored(template)
        if k < 0 or err > self.slam.config.local_view.vt_match_threshold:
            return result
        self.merge_with(k, tid, offset=offset, error=err, frame=result.frame)
        n_t, n_e, _ = self.slam.counts()
        return dataclasses.replace(
            result,
            experience_id=int(self.slam.experience_map.current_id),
            templates=n_t,
            experiences=n_e,
        )

    def merge_with(
        self,
        k: int,
        loaded_template: int,
        *,
        offset: int = 0,
        error: float = 0.0,
        frame: int | None = None,
    ) -> dict[str, Any]:
        """Merge stored map ``k`` (matched at ``loaded_template``) into the running map
        now, relax, and record the merge.

        Returns:
            The merge record appended to :attr:`merges`.
        """
        t0 = time.perf_counter()
        partial = state_from_slam(self.slam)
        loaded = self.stored[k]
        rel = float(self._banks[k].relative_rad(offset))
        res = merge_maps(
            loaded,
            partial,
            loaded_template,
            relative_rad=rel,
            shift_pose_cells=self.shift_pose_cells,
        )
        apply_state(res.state, self.slam, exp_ids=res.info["exp_ids"])
        self.slam.experience_map.iterate()
        self.pending.remove(k)
        if self.keep_snapshots:
            self.snapshots.append(
                {
                    "loaded": loaded.exp_pose.copy(),
                    "partial": partial.exp_pose.copy(),
                    "merged": res.state.exp_pose.copy(),
                    "relaxed": np.asarray(self.slam.experience_map.poses, np.float64).copy(),
                    "n_loaded": np.array(loaded.n_experiences),
                    "merged_state": res.state,
                    "partial_state": partial,
                }
            )
        rec = {
            "frame": int(self.slam.frame_index - 1 if frame is None else frame),
            "map": int(k),
            "map_name": self.names[k],
            "session": self.session,
            "scenario": "i" if partial.n_templates <= 1 else "ii",
            "error": float(error),
            "loaded_template": int(loaded_template),
            "loaded_exp": int(res.info["loaded_exp"]),
            "pc_shift": res.info["pc_shift"],
            "pc_shift_applied": res.info["pc_shift_applied"],
            "transform": [float(v) for v in res.info["transform"]],
            "templates_added": res.info["templates_added"],
            "experiences_added": res.info["experiences_added"],
            "time_s": time.perf_counter() - t0,
        }
        self.merges.append(rec)
        return rec

    # ------------------------------------------------------------------ state
    def get_map(self) -> MapState:
        """The running map as a :class:`MapState`."""
        return state_from_slam(self.slam)

    def unmerged(self) -> list[MapState]:
        """The stored maps that were not merged (still separate)."""
        return [self.stored[k] for k in self.pending]


# ====================================================================== tour runner
PAPER_ICP_RMSE = {"virtual_tour": 0.00773327, "lab_tour": 0.00883269, "irat_like": 0.0126932}
"""ICP RMSE between the multisession and single-session maps in the paper (Figs. 10, 14,
16; units as printed there)."""


class _Sized:
    """Frames with a known count (so the run's progress bar shows a total)."""

    def __init__(self, frames: Iterable[Any], n: int) -> None:
        self._frames, self._n = frames, n

    def __iter__(self) -> Any:
        return iter(self._frames)

    def __len__(self) -> int:
        return self._n


def _shifted(frames: Iterable[Any], dt: float) -> Iterable[Any]:
    for f in frames:
        yield dataclasses.replace(f, t=float(f.t) + dt)


def _map_metrics(state: MapState, gt: np.ndarray | None) -> dict[str, Any]:
    """Counts and the experience ATE: every experience's final position against the
    ground truth at its creation time, after rigid SE(2) alignment."""
    from torchratslam.eval.metrics import ate_rmse, interpolate_groundtruth

    out: dict[str, Any] = dict(state.summary())
    out["ate_rmse_m"] = None
    if gt is not None and state.n_experiences >= 2:
        truth = interpolate_groundtruth(gt, state.exp_t)
        out["ate_rmse_m"] = float(ate_rmse(state.exp_pose[:, :2], truth[:, :2]))
    return out


def _graph_error(state: MapState, config: RatSLAMConfig) -> float:
    from torchratslam.graph.backends import GraphErrorEvaluator

    pg = _posegraph(state, config)
    return float(GraphErrorEvaluator(pg)(pg.poses)) if pg.num_edges else 0.0


def _posegraph(state: MapState, config: RatSLAMConfig) -> Any:
    from torchratslam.graph.experience_map import ExperienceMap
    from torchratslam.maps.state import experience_map_state

    em = ExperienceMap(config.experience_map)
    em.set_state(experience_map_state(state))
    return em.posegraph("creation")


def run_sessions(
    config: RatSLAMConfig,
    sessions: list[Any],
    *,
    offsets: list[float] | None = None,
    shift_pose_cells: bool = True,
    save_dir: Any = None,
    progress: bool = False,
    max_frames: int | None = None,
    observer: Any = None,
    **ratslam_kwargs: Any,
) -> dict[str, Any]:
    """Map ``sessions`` one after another, each starting with the maps the previous
    ones left (saved and loaded when ``save_dir`` is given), merging when they meet.

    Args:
        config: the configuration.
        sessions: simulator/reader sessions (``name``, ``frames()``).
        offsets: seconds added to each session's timestamps (to put every session on
            one clock for ground-truth look-ups); default 0.
        shift_pose_cells: False for the Fig. 12 ablation.
        save_dir: where each session's map is saved (``<dir>/<session>/state``).
        progress: progress bars.
        max_frames: frames per session at most (for quick checks).
        observer: a :class:`torchratslam.viz.rerun_viewer.RerunObserver` (or anything
            with ``attach(slam, name)``, ``frames(data)`` and a call per step) that
            watches every session.

    Returns:
        ``maps`` (the maps left, the last one the final), ``names``, ``merges`` (all
        sessions), ``snapshots`` (per merge), ``session_maps`` (the map at the end of
        each session), ``sessions`` (per-session counts), ``relax_s`` (experience-map
        time, s), ``wall_s``.
    """
    from pathlib import Path

    from torchratslam.maps.state import load_map, save_map

    stored: list[MapState] = []
    names: list[str] = []
    merges: list[dict[str, Any]] = []
    snapshots: list[dict[str, Any]] = []
    session_maps: list[MapState] = []
    per_session: list[dict[str, Any]] = []
    relax_s = 0.0
    t0 = time.perf_counter()
    for i, s in enumerate(sessions):
        name = getattr(s, "name", f"session{i + 1}")
        ms = MultiSessionRatSLAM(
            config,
            stored,
            names=names,
            session=name,
            shift_pose_cells=shift_pose_cells,
            **ratslam_kwargs,
        )
        frames = s.frames() if hasattr(s, "frames") else s
        if offsets is not None:
            frames = _shifted(frames, offsets[i])
        if hasattr(s, "__len__"):  # the progress bar shows the session's total
            frames = _Sized(frames, len(s))
        if progress:
            from tqdm import tqdm

            tqdm.write(f"session {i + 1}/{len(sessions)}: {name}")
        if observer is not None:
            observer.attach(ms, name)
            frames = observer.frames(frames)
        res = ms.run(frames, max_frames=max_frames, progress=progress, callback=observer)
        relax_s += float(res.timings.get("experience_map", {}).get("total_s", 0.0))
        state = ms.get_map()
        if save_dir is not None:
            d = Path(save_dir) / name / "state"
            save_map(state, d)
            state = load_map(d)
        merges += ms.merges
        snapshots += ms.snapshots
        session_maps.append(state)
        per_session.append(
            {"name": name, "frames": res.frames, **state.summary(), "merges": len(ms.merges)}
        )
        names = [names[k] for k in ms.pending] + [name]
        stored = [*ms.unmerged(), state]
    return {
        "maps": stored,
        "names": names,
        "merges": merges,
        "snapshots": snapshots,
        "session_maps": session_maps,
        "sessions": per_session,
        "relax_s": relax_s,
        "wall_s": time.perf_counter() - t0,
    }


def run_tour(
    config: RatSLAMConfig,
    tour: Any,
    *,
    ablation: bool = False,
    backends: tuple[str, ...] | list[str] = (),
    save_dir: Any = None,
    progress: bool = False,
    max_frames: int | None = None,
    observer: Any = None,
    **ratslam_kwargs: Any,
) -> dict[str, Any]:
    """Multisession versus single-session mapping of a simulated tour.

    Runs the single-session map over ``tour.continuous()`` (every session driven in
    one continuous run, joined by drives along the tour's roads: the paper's single
    mapping session), the multisession mapping of ``tour.sessions`` (each session
    saved and loaded by the next), and, for reference, single-session maps over
    ``tour.full()`` (the sessions concatenated with a kidnap between them) and over the
    last session alone; then compares them.

    Args:
        config: the configuration.
        tour: a :class:`torchratslam.sim.Tour` (``sessions``, ``continuous()``,
            ``full()``, ``name``).
        ablation: also run the multisession mapping without the pose-cell shift.
        backends: also rerun the multisession mapping with each of these relaxation
            backends (``exp_backend``), and relax each merged graph with each of them.
        save_dir: where session maps are saved (``<dir>/multi/<session>/state``).
        progress: progress bars.
        max_frames: frames per session at most (quick checks; the continuous and
            concatenated runs get this many per session, the bridges included).
        observer: watches the multisession mapping's sessions (see :func:`run_sessions`).

    Returns:
        ``report`` (JSON-able: the keys of ``OUT/report.json``) and ``data`` (the maps,
        snapshots and ground truth for figures).
    """
    from pathlib import Path

    from torchratslam.eval.metrics import icp
    from torchratslam.maps.state import state_from_slam

    full = tour.full()
    cont = tour.continuous() if hasattr(tour, "continuous") else full
    parts = {p["name"]: p for p in getattr(cont, "info", {}).get("parts", [])}
    if all(s.name in parts for s in tour.sessions):
        # every session on the continuous run's clock: one ground truth for all maps
        starts = [parts[s.name]["start"] for s in tour.sessions]
    else:  # a single-session tour (or no roads between sessions): the concatenation
        cont = full
        starts = list(np.cumsum([0] + [len(s) for s in tour.sessions])[:-1])
    gt = cont.groundtruth()
    offsets = [float(cont.times[a] - s.times[0]) for a, s in zip(starts, tour.sessions)]
    limit = None if max_frames is None else max_frames * len(tour.sessions)

    def sub(name: str) -> Path | None:
        return None if save_dir is None else Path(save_dir) / name

    def single_run(frames: Any, n: int | None) -> tuple[MapState, float]:
        t0 = time.perf_counter()
        slam = RatSLAM(config, **ratslam_kwargs)
        slam.run(frames, max_frames=n, progress=progress)
        return state_from_slam(slam), time.perf_counter() - t0

    # the paper's single mapping session: one continuous run through every session
    single_state, single_wall = single_run(cont.frames(), limit)
    # the sessions concatenated, kidnapped between them (its own clock and ground truth)
    concat_state, concat_wall = single_run(full.frames(), limit)
    # the last session alone, continuous (for the virtual tour it contains session 1's path)
    last_state, _ = single_run(_shifted(tour.sessions[-1].frames(), offsets[-1]), max_frames)

    multi = run_sessions(
        config,
        tour.sessions,
        offsets=offsets,
        save_dir=sub("multi"),
        progress=progress,
        max_frames=max_frames,
        observer=observer,
        **ratslam_kwargs,
    )
    final = multi["maps"][-1]
    m_xy = final.exp_pose[:, :2]

    def icp_to(other: MapState) -> Any:
        o_xy = other.exp_pose[:, :2]
        return icp(m_xy, o_xy) if len(o_xy) and len(m_xy) else None

    ic, ic_concat, ic_last = icp_to(single_state), icp_to(concat_state), icp_to(last_state)
    extent = float(np.linalg.norm(np.ptp(gt[:, 1:3], axis=0)))

    def block(run: dict[str, Any]) -> dict[str, Any]:
        fin = run["maps"][-1]
        out = _map_metrics(fin, gt)
        out.update(
            maps=len(run["maps"]),
            connected=len(run["maps"]) == 1,
            merges=[
                {"session": m["session"], "frame": m["frame"], "map": m["map_name"]}
                for m in run["merges"]
            ],
            sessions=run["sessions"],
            graph_error=_graph_error(fin, config),
            relax_s=run["relax_s"],
            wall_s=run["wall_s"],
        )
        return out

    def rel(n: int, ref: int) -> float | None:
        return (n - ref) / ref if ref else None

    report: dict[str, Any] = {
        "tour": getattr(tour, "name", "tour"),
        "frames": int(sum(len(s) for s in tour.sessions)),
        "frames_continuous": len(cont),
        "sessions": [s.name for s in tour.sessions],
        "single_kind": "continuous" if cont is not full else "concatenated",
        "single": {
            **_map_metrics(single_state, gt),
            "graph_error": _graph_error(single_state, config),
            "wall_s": single_wall,
        },
        "single_concatenated": {
            **_map_metrics(concat_state, full.groundtruth()),
            "graph_error": _graph_error(concat_state, config),
            "wall_s": concat_wall,
        },
        "single_last_session": _map_metrics(last_state, gt),
        "multi": block(multi),
        "icp_rmse": None if ic is None else float(ic.rmse),
        "icp_rmse_relative": None if ic is None else float(ic.rmse / max(extent, 1e-12)),
        "icp_rmse_concatenated": None if ic_concat is None else float(ic_concat.rmse),
        "icp_rmse_last_session": None if ic_last is None else float(ic_last.rmse),
        "tour_extent_m": extent,
        "paper_icp_rmse": PAPER_ICP_RMSE.get(getattr(tour, "name", ""), None),
        "merges": [
            {
                "session": m["session"],
                "frame": m["frame"],
                "map": m["map_name"],
                "error": m["error"],
                "scenario": m["scenario"],
                "experiences_added": m["experiences_added"],
            }
            for m in multi["merges"]
        ],
    }
    n_m = report["multi"]["experiences"]
    report["experiences_difference_relative"] = rel(n_m, report["single"]["experiences"])
    report["experiences_difference_relative_concatenated"] = rel(
        n_m, report["single_concatenated"]["experiences"]
    )
    report["experiences_difference_relative_last_session"] = rel(
        n_m, report["single_last_session"]["experiences"]
    )
    data: dict[str, Any] = {
        "single": single_state,
        "single_concatenated": concat_state,
        "single_last_session": last_state,
        "multi": multi,
        "groundtruth": gt,
        "offsets": offsets,
        "icp": ic,
        "session_starts": [float(cont.times[a]) for a in starts],
        "world": getattr(tour, "world", None),
    }
    if ablation:
        abl = run_sessions(
            config,
            tour.sessions,
            offsets=offsets,
            shift_pose_cells=False,
            progress=progress,
            max_frames=max_frames,
            **ratslam_kwargs,
        )
        report["ablation_no_pc_shift"] = block(abl)
        data["ablation"] = abl
    if backends:
        from torchratslam.eval.metrics import interpolate_groundtruth
        from torchratslam.graph.compare import compare_backends

        table: dict[str, Any] = {}
        for name in backends:
            if name == config.experience_map.exp_backend:
                run = multi
            else:
                cfg = config.replace(exp_backend=name)
                run = run_sessions(
                    cfg,
                    tour.sessions,
                    offsets=offsets,
                    progress=progress,
                    max_frames=max_frames,
                    **ratslam_kwargs,
                )
            b = block(run)
            table[name] = {
                "error": b["graph_error"],
                "ate_rmse_m": b["ate_rmse_m"],
                "time_s": run["relax_s"],
                "experiences": b["experiences"],
                "connected": b["connected"],
            }
        report["backends"] = table
        after = []
        for m, snap in zip(multi["merges"], multi["snapshots"]):
            st = snap["merged_state"]
            pg = _posegraph(st, config)
            if pg.num_edges == 0:
                continue
            truth = interpolate_groundtruth(gt, st.exp_t)
            rows = compare_backends(
                pg,
                list(backends),
                truth,
                passes=config.experience_map.exp_loops,
                correction=config.experience_map.exp_correction,
            )
            after.append(
                {
                    "session": m["session"],
                    "frame": m["frame"],
                    "results": {
                        r["name"]: {
                            k: r[k] for k in ("error", "initial_error", "ate_rmse_m", "time_s")
                        }
                        for r in rows
                    },
                }
            )
        report["backends_after_merge"] = after
        pg = _posegraph(final, config)
        if pg.num_edges:
            truth = interpolate_groundtruth(gt, final.exp_t)
            rows = compare_backends(
                pg,
                list(backends),
                truth,
                passes=config.experience_map.exp_loops,
                correction=config.experience_map.exp_correction,
            )
            report["backends_final_map"] = {
                r["name"]: {k: r[k] for k in ("error", "initial_error", "ate_rmse_m", "time_s")}
                for r in rows
            }
    return {"report": report, "data": data}
