"""Multisession versus single-session mapping of a simulated tour (the multisession
paper's experiments, Section 5): the runner behind ``torchratslam multisession`` and the
demo.

* :func:`run_sessions` maps sessions one after another, each starting with the maps the
  previous ones left, merging when they meet (:class:`MultiSessionRatSLAM`);
* :func:`run_tour` runs the single-session references and the multisession mapping of a
  tour and compares them (the ``report`` of ``report.json``);
* :func:`run_experiment` does all of it for a tour name and writes ``OUT``, with the
  options of :class:`MultisessionOptions`.

The report's tables are :mod:`torchratslam.experiments.multisession_report`; the check
across seeds is :mod:`torchratslam.experiments.multisession_seeds`.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ratslam_graph.atomic import atomic_write_text
from ratslam_graph.out_checks import check_out_dir
from torchratslam.config import RatSLAMConfig, load_config
from torchratslam.errors import InputError, option
from torchratslam.eval.icp import PAPER_ICP_MSE_M2
from torchratslam.experiments.multisession_report import report_markdown
from torchratslam.maps.state import MapState
from torchratslam.multisession.session import MultiSessionRatSLAM
from torchratslam.pipeline import RatSLAM
from torchratslam.protocols import FrameSource

__all__ = [
    "PAPER_ICP_RMSE",
    "TOUR_CONFIG",
    "MultisessionOptions",
    "parse_tour_spec",
    "relative",
    "run_experiment",
    "run_sessions",
    "run_tour",
    "single_run",
    "tour_clock",
    "tour_setup",
]

PAPER_ICP_RMSE = PAPER_ICP_MSE_M2  # the paper prints "RMSE", but its figures are
# LibICP residuals, mean squared distances in m^2 (torchratslam.eval.icp)
"""ICP RMSE between the multisession and single-session maps in the paper (Figs. 10, 14,
16; units as printed there)."""

TOUR_CONFIG = {
    "virtual_tour": "virtual_tour",
    "lab_tour": "lab_tour",
    "irat_like": "irat",
    "new_college": "new_college",
}
"""The shipped config of each tour, used unmodified when no config is given."""

_METRIC_KEYS = ("error", "initial_error", "ate_rmse_m", "time_s")


# ------------------------------------------------------------------ small helpers
def _shifted(frames: Iterable[Any], dt: float) -> Iterable[Any]:
    for f in frames:
        yield dataclasses.replace(f, t=float(f.t) + dt)


class _Sized:
    """Frames with a known count (so the run's progress bar shows a total)."""

    def __init__(self, frames: Iterable[Any], n: int) -> None:
        self._frames, self._n = frames, n

    def __iter__(self) -> Any:
        return iter(self._frames)

    def __len__(self) -> int:
        return self._n


def _map_metrics(state: MapState, gt: np.ndarray | None) -> dict[str, Any]:
    """Counts and the experience ATE: every experience's final position against the
    ground truth at its creation time, after rigid SE(2) alignment, over the experiences
    the ground truth covers (``ate_poses``; under 3 the ATE is None)."""
    from torchratslam.eval.metrics import ATE_ALIGNMENT, ate_at_times

    out: dict[str, Any] = dict(state.summary())
    out["ate_rmse_m"] = None
    if gt is not None:
        out["ate_rmse_m"], out["ate_poses"] = ate_at_times(state.exp_pose, state.exp_t, gt)
        out["ate_alignment"] = ATE_ALIGNMENT
    return out


def _posegraph(state: MapState, config: RatSLAMConfig) -> Any:
    from ratslam_graph.experience_map import ExperienceMap
    from torchratslam.maps.stages import experience_map_state

    em = ExperienceMap(config.experience_map)
    em.set_state(experience_map_state(state))
    return em.posegraph("creation")


def _graph_error(state: MapState, config: RatSLAMConfig) -> float:
    from ratslam_graph.backends import GraphErrorEvaluator

    pg = _posegraph(state, config)
    return float(GraphErrorEvaluator(pg)(pg.poses)) if pg.num_edges else 0.0


def relative(n: int, ref: int) -> float | None:
    """``n / ref - 1`` (None when ``ref`` is 0)."""
    return (n - ref) / ref if ref else None


# ------------------------------------------------------------------ session by session
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
        sessions: simulator/reader sessions (``name``, ``frames()``) or frame iterables.
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
    from torchratslam.maps.native import load_map, save_map

    stored: list[MapState] = []
    names: list[str] = []
    out: dict[str, Any] = {"merges": [], "snapshots": [], "session_maps": [], "sessions": []}
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
        frames = s.frames() if isinstance(s, FrameSource) else s
        if offsets is not None:
            frames = _shifted(frames, offsets[i])
        if hasattr(s, "__len__"):  # the progress bar shows the session's total
            frames = _Sized(frames, len(s))
        label = f"session {i + 1}/{len(sessions)} {name}" if progress else False
        if observer is not None:
            observer.attach(ms, name)
            frames = observer.frames(frames)
        res = ms.run(frames, max_frames=max_frames, progress=label, callback=observer)
        relax_s += float(res.timings.get("experience_map", {}).get("total_s", 0.0))
        state = ms.get_map()
        if save_dir is not None:
            d = Path(save_dir) / name / "state"
            save_map(state, d)
            state = load_map(d)
        out["merges"] += ms.merges
        out["snapshots"] += ms.snapshots
        out["session_maps"].append(state)
        out["sessions"].append(
            {"name": name, "frames": res.frames, **state.summary(), "merges": len(ms.merges)}
        )
        names = [names[k] for k in ms.pending] + [name]
        stored = [*ms.unmerged(), state]
    return {
        "maps": stored,
        "names": names,
        **out,
        "relax_s": relax_s,
        "wall_s": time.perf_counter() - t0,
    }


# ------------------------------------------------------------------ the tour comparison
@dataclass
class _Clock:
    """The tour's sessions on one clock.

    Attributes:
        cont: the single-session reference run (continuous, or the concatenation).
        full: the sessions concatenated with kidnaps between them.
        starts: the frame of ``cont`` at which each session starts.
        gt: ``cont``'s ground truth ``(T, 4)``.
        offsets: seconds to add to each session's own timestamps.
    """

    cont: Any
    full: Any
    starts: list[int]
    gt: np.ndarray
    offsets: list[float]


def tour_clock(tour: Any) -> _Clock:
    """Put every session on the continuous run's clock (one ground truth for all maps);
    a single-session tour, or one without roads between sessions, uses the
    concatenation."""
    full = tour.full()
    cont = tour.continuous() if callable(getattr(tour, "continuous", None)) else full
    parts = {p["name"]: p for p in getattr(cont, "info", {}).get("parts", [])}
    if all(s.name in parts for s in tour.sessions):
        starts = [parts[s.name]["start"] for s in tour.sessions]
    else:
        cont = full
        starts = list(np.cumsum([0] + [len(s) for s in tour.sessions])[:-1])
    offsets = [float(cont.times[a] - s.times[0]) for a, s in zip(starts, tour.sessions)]
    return _Clock(cont, full, starts, cont.groundtruth(), offsets)


def single_run(
    config: RatSLAMConfig,
    frames: Any,
    n: int | None,
    progress: bool | str,
    *,
    odometry_stats: dict[str, Any] | None = None,
    **ratslam_kwargs: Any,
) -> tuple[MapState, float]:
    """One single-session map over ``frames`` and its wall time (s); ``progress``: a
    bar, labelled when a label is given. ``odometry_stats``, when given, receives the
    visual odometry's :meth:`~torchratslam.readers.visual_odometry.VisualOdometry.limits`
    and the mean translation per frame, estimated and true (nothing for other sources)."""
    from torchratslam.maps.running import state_from_slam

    t0 = time.perf_counter()
    slam = RatSLAM(config, **ratslam_kwargs)
    slam.run(frames, max_frames=n, progress=progress)
    limits = getattr(slam.odometry, "limits", None)
    if odometry_stats is not None and callable(limits):
        odometry_stats.update(limits())
        odo = slam.odometry_log()[1:]
        truth = slam.groundtruth_poses()
        odometry_stats["mean_translation_m"] = float(np.mean(odo[:, 0] * odo[:, 2]))
        if truth is not None and len(truth) > 1:
            step = np.hypot(*np.diff(np.asarray(truth)[:, :2], axis=0).T)
            odometry_stats["true_mean_translation_m"] = float(np.nanmean(step))
    return state_from_slam(slam), time.perf_counter() - t0


def _multi_block(run: dict[str, Any], gt: np.ndarray, config: RatSLAMConfig) -> dict[str, Any]:
    """The report's entry of one multisession run (its final map, merges, timing)."""
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


def _icp(moving: MapState, fixed: MapState) -> Any:
    """ICP of one map's experience positions onto another's (None if either is empty)."""
    from torchratslam.eval.metrics import icp

    m_xy, o_xy = moving.exp_pose[:, :2], fixed.exp_pose[:, :2]
    return icp(m_xy, o_xy) if len(o_xy) and len(m_xy) else None


def _comparison(
    tour: Any,
    clock: _Clock,
    config: RatSLAMConfig,
    singles: dict[str, tuple[MapState, float]],
    multi: dict[str, Any],
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The report comparing the single-session maps with the multisession one, and the
    ICP results against the continuous map (``icp``: the project's; ``libicp``: the
    paper's convention)."""
    final = multi["maps"][-1]
    (single, single_wall), (concat, concat_wall), (last, _) = (
        singles[k] for k in ("single", "single_concatenated", "single_last_session")
    )
    ic, ic_concat, ic_last = _icp(final, single), _icp(final, concat), _icp(final, last)
    from torchratslam.eval.icp import libicp_point_to_point

    s_xy, m_xy = single.exp_pose[:, :2], final.exp_pose[:, :2]
    # the paper's figure: LibICP, the single-session map (template) moved onto the
    # multisession map (model)
    lib = libicp_point_to_point(s_xy, m_xy) if len(s_xy) and len(m_xy) else None
    gt = clock.gt
    extent = float(np.linalg.norm(np.ptp(gt[:, 1:3], axis=0)))
    report: dict[str, Any] = {
        "tour": getattr(tour, "name", "tour"),
        "frames": int(sum(len(s) for s in tour.sessions)),
        "frames_continuous": len(clock.cont),
        "sessions": [s.name for s in tour.sessions],
        "single_kind": "continuous" if clock.cont is not clock.full else "concatenated",
        "single": {
            **_map_metrics(single, gt),
            "graph_error": _graph_error(single, config),
            "wall_s": single_wall,
        },
        "single_concatenated": {
            **_map_metrics(concat, clock.full.groundtruth()),
            "graph_error": _graph_error(concat, config),
            "wall_s": concat_wall,
        },
        "single_last_session": _map_metrics(last, gt),
        "multi": _multi_block(multi, gt, config),
        "icp_rmse": None if ic is None else float(ic.rmse),
        "icp_rmse_relative": None if ic is None else float(ic.rmse / max(extent, 1e-12)),
        "icp_rmse_concatenated": None if ic_concat is None else float(ic_concat.rmse),
        "icp_rmse_last_session": None if ic_last is None else float(ic_last.rmse),
        "tour_extent_m": extent,
        "icp_libicp_mse_m2": None if lib is None else lib.residual_m2,
        "paper_icp_mse_m2": PAPER_ICP_MSE_M2.get(getattr(tour, "name", ""), None),
        "icp_note": (
            "icp_libicp_mse_m2 compares with paper_icp_mse_m2: both are LibICP residuals, "
            "the mean squared nearest-neighbour distance in m^2 after point-to-point ICP "
            "from the identity with the single-session map (LibICP's template) moved onto "
            "the multisession map (its model); icp_rmse* are the project's RMSEs in m "
            "(not comparable with the paper)"
        ),
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
    for suffix, key in (
        ("", "single"),
        ("_concatenated", "single_concatenated"),
        ("_last_session", "single_last_session"),
    ):
        report[f"experiences_difference_relative{suffix}"] = relative(
            n_m, report[key]["experiences"]
        )
    return report, {"icp": ic, "libicp": lib}


def _relax_rows(
    state: MapState, gt: np.ndarray, config: RatSLAMConfig, backends: list[str]
) -> dict[str, Any] | None:
    """Each backend relaxing ``state``'s graph once (None when it has no links)."""
    from ratslam_graph.compare import compare_backends
    from torchratslam.eval.metrics import interpolate_groundtruth

    pg = _posegraph(state, config)
    if pg.num_edges == 0:
        return None
    truth = interpolate_groundtruth(gt, state.exp_t)
    rows = compare_backends(
        pg,
        list(backends),
        truth,
        passes=config.experience_map.exp_loops,
        correction=config.experience_map.exp_correction,
    )
    return {r["name"]: {k: r[k] for k in _METRIC_KEYS} for r in rows}


def _backend_reports(
    multi: dict[str, Any],
    config: RatSLAMConfig,
    gt: np.ndarray,
    backends: tuple[str, ...] | list[str],
    rerun: Any,
) -> dict[str, Any]:
    """The backend comparison: whole multisession runs with each backend
    (``backends``), each merged graph and the final map relaxed by each
    (``backends_after_merge``, ``backends_final_map``)."""
    table: dict[str, Any] = {}
    for name in backends:
        run = multi if name == config.experience_map.exp_backend else rerun(name)
        b = _multi_block(run, gt, config)
        table[name] = {
            "error": b["graph_error"],
            "ate_rmse_m": b["ate_rmse_m"],
            "time_s": run["relax_s"],
            "experiences": b["experiences"],
            "connected": b["connected"],
        }
    after = []
    for m, snap in zip(multi["merges"], multi["snapshots"]):
        rows = _relax_rows(snap["merged_state"], gt, config, list(backends))
        if rows is not None:
            after.append({"session": m["session"], "frame": m["frame"], "results": rows})
    out: dict[str, Any] = {"backends": table, "backends_after_merge": after}
    final = _relax_rows(multi["maps"][-1], gt, config, list(backends))
    if final is not None:
        out["backends_final_map"] = final
    return out


def run_tour(
    config: RatSLAMConfig,
    tour: Any,
    *,
    ablation: bool = False,
    backends: tuple[str, ...] | list[str] = (),
    save_dir: Any = None,
    progress: bool = False,
    max_frames: int | None = None,
    merge_options: dict[str, Any] | None = None,
    observer: Any = None,
    session_options: dict[str, Any] | None = None,
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
        merge_options: ``merge_maps`` options for every multisession run
            (``exp_pc_shift``, ``match_exp``; default: the authors' code).
        observer: watches the multisession mapping's sessions (see :func:`run_sessions`).
        session_options: :class:`MultiSessionRatSLAM` options for every multisession
            run (``merge_threshold``, ``merge_persist``, ``merge_absorb``; default: the
            paper's).

    Returns:
        ``report`` (JSON-able: the keys of ``OUT/report.json``) and ``data`` (the maps,
        snapshots and ground truth for figures).
    """
    clock = tour_clock(tour)
    limit = None if max_frames is None else max_frames * len(tour.sessions)
    kw = dict(progress=progress, max_frames=max_frames, **ratslam_kwargs)
    if merge_options:
        kw["merge_options"] = dict(merge_options)
    kw.update(session_options or {})
    last_frames = _shifted(tour.sessions[-1].frames(), clock.offsets[-1])

    def bar(label: str) -> bool | str:
        return label if progress else False

    odometry_stats: dict[str, Any] = {}
    singles = {  # the paper's single session; the concatenation; the last session alone
        "single": single_run(
            config,
            clock.cont.frames(),
            limit,
            bar("single session"),
            odometry_stats=odometry_stats,
            **ratslam_kwargs,
        ),
        "single_concatenated": single_run(
            config, clock.full.frames(), limit, bar("sessions concatenated"), **ratslam_kwargs
        ),
        "single_last_session": single_run(
            config, last_frames, max_frames, bar("last session alone"), **ratslam_kwargs
        ),
    }
    save = None if save_dir is None else Path(save_dir) / "multi"
    multi = run_sessions(
        config, tour.sessions, offsets=clock.offsets, save_dir=save, observer=observer, **kw
    )
    report, icps = _comparison(tour, clock, config, singles, multi)
    if odometry_stats:  # visual odometry: how often it sat on a limit (continuous run)
        report["visual_odometry"] = odometry_stats
    if merge_options:
        report["merge_options"] = dict(merge_options)
    if session_options:
        report["session_options"] = dict(session_options)
    data: dict[str, Any] = {
        **{k: v[0] for k, v in singles.items()},
        "multi": multi,
        "groundtruth": clock.gt,
        "offsets": clock.offsets,
        **icps,
        "session_starts": [float(clock.cont.times[a]) for a in clock.starts],
        "world": getattr(tour, "world", None),
    }
    if ablation:
        abl = run_sessions(
            config, tour.sessions, offsets=clock.offsets, shift_pose_cells=False, **kw
        )
        report["ablation_no_pc_shift"] = _multi_block(abl, clock.gt, config)
        data["ablation"] = abl
    if backends:

        def rerun(name: str) -> dict[str, Any]:
            cfg = config.replace(exp_backend=name)
            return run_sessions(cfg, tour.sessions, offsets=clock.offsets, **kw)

        report.update(_backend_reports(multi, config, clock.gt, backends, rerun))
    return {"report": report, "data": data}


# ------------------------------------------------------------------ the experiment
def parse_tour_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """The tour and its options of a ``sim:NAME[?key=value&...]`` spec (the simulator's
    own options, e.g. ``sim:virtual_tour?session2_start=0.82&fog=20``).

    Raises:
        InputError: not a simulator spec, an unknown tour, a spec naming one session
            (``sim:NAME/SESSION``), or a ``seed`` option (seeds are arguments).
    """
    from torchratslam.sim.dataset import parse_sim_spec

    name, session, options = parse_sim_spec(spec if spec.startswith("sim:") else f"sim:{spec}")
    if session is not None:
        raise InputError(f"--tour takes a whole tour (sim:NAME), not one session: {spec!r}")
    if "seed" in options:
        raise InputError(f"{spec!r}: give the seed with --seed or --seeds, not in the spec")
    return name, options


def tour_setup(
    tour_spec: str, config: Any, overrides: dict[str, Any] | None
) -> tuple[str, dict[str, Any], RatSLAMConfig]:
    """The tour name and options of ``tour_spec`` and the config: ``config`` (a
    ``RatSLAMConfig`` or a path/name) or the tour's shipped one, ``overrides`` applied."""
    name, tour_options = parse_tour_spec(tour_spec)
    if config is None:
        config = load_config(TOUR_CONFIG.get(name))
    elif isinstance(config, (str, Path)):
        config = load_config(config)
    if overrides:
        config = config.replace(**overrides)
    return name, tour_options, config


def _write_json(path: Path, obj: Any) -> None:
    """Atomic JSON write (the one atomic writer, :mod:`ratslam_graph.atomic`)."""
    text = json.dumps(obj, indent=1, default=lambda v: v.item() if hasattr(v, "item") else str(v))
    atomic_write_text(path, text)


@dataclass(frozen=True)
class MultisessionOptions:
    """Options of :func:`run_experiment`.

    Attributes:
        ablation: also run without the pose-cell shift (Fig. 12).
        backends: relaxation backends to compare on the final map.
        seed: the simulator's seed.
        max_frames: frames per session at most (quick checks).
        figures: write the figures.
        progress: progress bars.
        overrides: flat config keys replaced last.
        merge_options: ``merge_maps`` options (default: the authors' code).
        rerun: watch the multisession mapping live in a rerun viewer
            (:class:`torchratslam.viz.rerun_viewer.RerunObserver`; extra ``viewer``).
        rerun_save: record the multisession mapping for rerun into this ``.rrd`` file.
        merge_threshold: :class:`MultiSessionRatSLAM` ``merge_threshold`` (None: the paper's).
        merge_persist: :class:`MultiSessionRatSLAM` ``merge_persist`` (1: the paper's).
        merge_absorb: :class:`MultiSessionRatSLAM` ``merge_absorb`` (False: the paper's).
        merge_anchor: :class:`MultiSessionRatSLAM` ``merge_anchor`` ("template": the
            paper's; "view": join the maps where the view matches best).
    """

    ablation: bool = False
    backends: tuple[str, ...] = ()
    seed: int = 0
    max_frames: int | None = None
    figures: bool = True
    progress: bool = False
    overrides: Mapping[str, Any] | None = None
    merge_options: Mapping[str, Any] | None = None
    rerun: bool = False
    rerun_save: str | Path | None = None
    merge_threshold: float | None = None
    merge_persist: int = 1
    merge_absorb: bool = False
    merge_anchor: str = "template"


RUNNING = "running.json"
"""The command line's lock in OUT while a multisession run works."""
FINISHED = ("report.json", "seeds.json")
"""What a finished multisession run leaves in OUT: one experiment's report, a seed table."""


def check_out(out: str | Path, overwrite: bool) -> None:
    """Refuse an OUT holding anything but a multisession run, or a finished one without
    ``overwrite``.

    Raises:
        InputError: naming OUT and what it holds.
    """
    check_out_dir(out, what="multisession run", marks=(RUNNING, *FINISHED))
    done = [n for n in FINISHED if (Path(out) / n).is_file()]
    if done and not overwrite:
        raise InputError(
            f"{out} holds a finished multisession run ({done[0]}); choose another "
            f"{option('--out', 'out')}, or replace it with "
            f"{option('--overwrite', 'overwrite=True')}"
        )


def run_experiment(
    config: Any,
    tour_spec: str,
    out: str | Path,
    options: MultisessionOptions | None = None,
    *,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Run the experiment on a tour and write OUT (what the CLI and the demo call):
    ``report.json``, ``report.md``, the figures and the session maps.

    Args:
        config: a ``RatSLAMConfig``, a config path/name, or None for the tour's shipped
            config (:data:`TOUR_CONFIG`), unmodified.
        tour_spec: ``sim:NAME``, optionally with the simulator's options
            (``sim:NAME?key=value&...``, :func:`parse_tour_spec`).
        out: the output folder.
        options: the run's options (default: :class:`MultisessionOptions`).
        overwrite: replace a finished multisession run in ``out`` (a folder holding
            anything else is always refused).

    Returns:
        :func:`run_tour`'s result (``report`` and ``data``).

    Raises:
        InputError: ``out`` holds something else, or a finished run without ``overwrite``.
    """
    check_out(out, overwrite)
    from torchratslam.sim import get_tour
    from torchratslam.viz.multisession import write_figures

    o = options if options is not None else MultisessionOptions()
    overrides = dict(o.overrides) if o.overrides is not None else None
    merge_options = dict(o.merge_options) if o.merge_options is not None else None
    name, tour_options, config = tour_setup(tour_spec, config, overrides)
    tour = get_tour(name, seed=o.seed, **tour_options)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    observer = None
    if o.rerun or o.rerun_save:
        from torchratslam.viz.rerun_viewer import RerunObserver

        observer = RerunObserver(None, spawn=o.rerun, save=o.rerun_save)
    try:
        result = run_tour(
            config,
            tour,
            ablation=o.ablation,
            backends=tuple(o.backends),
            save_dir=out,
            progress=o.progress,
            max_frames=o.max_frames,
            merge_options=merge_options,
            observer=observer,
            session_options={
                k: v
                for k, v in (
                    ("merge_threshold", o.merge_threshold),
                    ("merge_persist", o.merge_persist),
                    ("merge_absorb", o.merge_absorb),
                    ("merge_anchor", o.merge_anchor),
                )
                if v
                != {
                    "merge_threshold": None,
                    "merge_persist": 1,
                    "merge_absorb": False,
                    "merge_anchor": "template",
                }[k]
            },
        )
    finally:
        if observer is not None:
            observer.close()
    report = result["report"]
    report["seed"] = o.seed
    if tour_options:
        report["tour_options"] = tour_options
    report["config"] = config.to_flat()
    _write_json(out / "report.json", report)
    atomic_write_text(out / "report.md", report_markdown(report))
    if o.figures:
        report["figures"] = [p.name for p in write_figures(result, out)]
        _write_json(out / "report.json", report)
    return result
