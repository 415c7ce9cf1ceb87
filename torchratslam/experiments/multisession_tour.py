"""Multisession versus single-session mapping of a simulated tour (the multisession
paper's experiments, Section 5): the runner behind ``torchratslam multisession`` and the
demo.

* :func:`run_sessions` maps sessions one after another, each starting with the maps the
  previous ones left, merging when they meet (:class:`MultiSessionRatSLAM`);
* :func:`run_tour` runs the single-session references and the multisession mapping of a
  tour and compares them (the ``report`` of ``report.json``);
* :func:`report_markdown` renders the report as tables;
* :func:`run_experiment` does all of it for a tour name and writes ``OUT``.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from torchratslam.config import RatSLAMConfig, load_config
from torchratslam.eval.icp import PAPER_ICP_MSE_M2
from ratslam_graph.atomic import atomic_write_text
from ratslam_graph.errors import InputError
from torchratslam.maps.state import MapState
from torchratslam.multisession.session import MultiSessionRatSLAM
from torchratslam.pipeline import RatSLAM
from torchratslam.protocols import FrameSource

__all__ = [
    "PAPER_ICP_RMSE",
    "RECOMMENDED_MERGE_OPTIONS",
    "RECOMMENDED_SESSION_OPTIONS",
    "TOUR_CONFIG",
    "parse_tour_spec",
    "partial_experiences",
    "place_counts",
    "report_markdown",
    "run_experiment",
    "run_sessions",
    "run_tour",
    "seed_row",
    "seed_table",
    "seed_table_markdown",
]

PAPER_ICP_RMSE = PAPER_ICP_MSE_M2  # old name: the paper prints "RMSE", but its figures are
# LibICP residuals, mean squared distances in m^2 (torchratslam.eval.icp)
"""ICP RMSE between the multisession and single-session maps in the paper (Figs. 10, 14,
16; units as printed there)."""

TOUR_CONFIG = {"virtual_tour": "virtual_tour", "lab_tour": "lab_tour", "irat_like": "irat"}
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
    ground truth at its creation time, after rigid SE(2) alignment."""
    from torchratslam.eval.metrics import ate_rmse, interpolate_groundtruth

    out: dict[str, Any] = dict(state.summary())
    out["ate_rmse_m"] = None
    if gt is not None and state.n_experiences >= 2:
        truth = interpolate_groundtruth(gt, state.exp_t)
        out["ate_rmse_m"] = float(ate_rmse(state.exp_pose[:, :2], truth[:, :2]))
    return out


def _posegraph(state: MapState, config: RatSLAMConfig) -> Any:
    from ratslam_graph.experience_map import ExperienceMap
    from torchratslam.maps.state import experience_map_state

    em = ExperienceMap(config.experience_map)
    em.set_state(experience_map_state(state))
    return em.posegraph("creation")


def _graph_error(state: MapState, config: RatSLAMConfig) -> float:
    from ratslam_graph.backends import GraphErrorEvaluator

    pg = _posegraph(state, config)
    return float(GraphErrorEvaluator(pg)(pg.poses)) if pg.num_edges else 0.0


def _relative(n: int, ref: int) -> float | None:
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
    from torchratslam.maps.state import load_map, save_map

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


def _clock(tour: Any) -> _Clock:
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


def _single_run(
    config: RatSLAMConfig, frames: Any, n: int | None, progress: bool, **ratslam_kwargs: Any
) -> tuple[MapState, float]:
    """One single-session map over ``frames`` and its wall time (s)."""
    from torchratslam.maps.state import state_from_slam

    t0 = time.perf_counter()
    slam = RatSLAM(config, **ratslam_kwargs)
    slam.run(frames, max_frames=n, progress=progress)
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
    # the paper's figure: LibICP, single-session map fixed (template), multisession moved
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
            "from the identity with the single-session map fixed and the multisession "
            "map moved; icp_rmse* are the project's RMSEs in m (not comparable with the "
            "paper)"
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
        report[f"experiences_difference_relative{suffix}"] = _relative(
            n_m, report[key]["experiences"]
        )
    return report, {"icp": ic, "libicp": lib}


def _relax_rows(
    state: MapState, gt: np.ndarray, config: RatSLAMConfig, backends: list[str]
) -> dict[str, Any] | None:
    """Each backend relaxing ``state``'s graph once (None when it has no links)."""
    from torchratslam.eval.metrics import interpolate_groundtruth
    from ratslam_graph.compare import compare_backends

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
    clock = _clock(tour)
    limit = None if max_frames is None else max_frames * len(tour.sessions)
    kw = dict(progress=progress, max_frames=max_frames, **ratslam_kwargs)
    if merge_options:
        kw["merge_options"] = dict(merge_options)
    kw.update(session_options or {})
    last_frames = _shifted(tour.sessions[-1].frames(), clock.offsets[-1])
    singles = {  # the paper's single session; the concatenation; the last session alone
        "single": _single_run(config, clock.cont.frames(), limit, progress, **ratslam_kwargs),
        "single_concatenated": _single_run(
            config, clock.full.frames(), limit, progress, **ratslam_kwargs
        ),
        "single_last_session": _single_run(
            config, last_frames, max_frames, progress, **ratslam_kwargs
        ),
    }
    save = None if save_dir is None else Path(save_dir) / "multi"
    multi = run_sessions(
        config, tour.sessions, offsets=clock.offsets, save_dir=save, observer=observer, **kw
    )
    report, icps = _comparison(tour, clock, config, singles, multi)
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


# ------------------------------------------------------------------ the report
def _fmt(v: Any, spec: str = ".4g") -> str:
    return "-" if v is None else format(v, spec)


def _runs_table(report: dict[str, Any]) -> list[str]:
    last = report["sessions"][-1]
    rows = [
        ("single session, continuous (the paper's single mapping session)", report["single"]),
        (
            "single session, sessions concatenated (kidnapped between them)",
            report["single_concatenated"],
        ),
        (f"single session, {last} alone", report["single_last_session"]),
        ("multisession", report["multi"]),
    ]
    if report.get("single_kind") == "concatenated":  # a tour without roads between sessions
        rows = [(name, r) for name, r in rows if r is not report["single_concatenated"]]
    if "ablation_no_pc_shift" in report:
        rows.append(("multisession, no pose-cell shift", report["ablation_no_pc_shift"]))
    lines = [
        f"### {report['tour']}: {len(report['sessions'])} sessions, {report['frames']} frames "
        f"({report['frames_continuous']} in the continuous run)",
        "",
        "| run | templates | experiences | links | ATE (m) | maps at end |",
        "|---|---|---|---|---|---|",
    ]
    for name, r in rows:
        lines.append(
            f"| {name} | {r['templates']} | {r['experiences']} | {r['links']} | "
            f"{_fmt(r['ate_rmse_m'])} | {r.get('maps', 1)} |"
        )
    return lines


def _summary_lines(report: dict[str, Any]) -> list[str]:
    last = report["sessions"][-1]
    return [
        "",
        f"- ICP, the paper's figure (LibICP residual: mean squared nearest-neighbour "
        f"distance, single-session map fixed, multisession moved): "
        f"{_fmt(report.get('icp_libicp_mse_m2'))} m^2; the paper reports "
        f"{_fmt(report.get('paper_icp_mse_m2'))} m^2",
        f"- ICP RMSE (the project's figure, not the paper's) multisession vs single-session "
        f"(continuous) map: "
        f"{_fmt(report['icp_rmse'])} m ({_fmt(report['icp_rmse_relative'])} of the tour's "
        f"{report['tour_extent_m']:.1f} m extent); vs the concatenated run: "
        f"{_fmt(report['icp_rmse_concatenated'])} m; vs {last} alone: "
        f"{_fmt(report['icp_rmse_last_session'])} m",
        "- experiences, multi vs single (continuous): "
        + _fmt(report["experiences_difference_relative"], "+.1%")
        + ", vs concatenated: "
        + _fmt(report["experiences_difference_relative_concatenated"], "+.1%")
        + f", vs {last} alone: "
        + _fmt(report["experiences_difference_relative_last_session"], "+.1%"),
        "- merges: "
        + (
            ", ".join(
                f"{m['session']} frame {m['frame']} with {m['map']}" for m in report["merges"]
            )
            or "none"
        ),
    ]


def _backend_lines(report: dict[str, Any]) -> list[str]:
    if "backends" not in report:
        return []
    lines = [
        "",
        "| backend (whole multisession run) | graph error | ATE (m) | "
        "relaxation time (s) | experiences |",
        "|---|---|---|---|---|",
    ]
    for name, b in report["backends"].items():
        lines.append(
            f"| {name} | {_fmt(b['error'])} | {_fmt(b['ate_rmse_m'])} | "
            f"{_fmt(b['time_s'], '.3f')} | {b['experiences']} |"
        )
    if "backends_final_map" in report:
        lines += [
            "",
            "relaxing the final multisession map's graph once more:",
            "",
            "| backend | initial error | error after | ATE (m) | time (s) |",
            "|---|---|---|---|---|",
        ]
        for name, r in report["backends_final_map"].items():
            lines.append(
                f"| {name} | {_fmt(r['initial_error'])} | {_fmt(r['error'])} | "
                f"{_fmt(r['ate_rmse_m'])} | {_fmt(r['time_s'], '.3f')} |"
            )
    return lines


def report_markdown(report: dict[str, Any]) -> str:
    """The report as Markdown tables (what the demo prints and the README shows)."""
    lines = _runs_table(report) + _summary_lines(report) + _backend_lines(report)
    return "\n".join(lines) + "\n"


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


def _tour_setup(
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


def run_experiment(
    config: Any,
    tour_spec: str,
    out: str | Path,
    *,
    ablation: bool = False,
    backends: tuple[str, ...] = (),
    seed: int = 0,
    max_frames: int | None = None,
    figures: bool = True,
    progress: bool = False,
    overrides: dict[str, Any] | None = None,
    merge_options: dict[str, Any] | None = None,
    rerun: bool = False,
    rerun_save: str | Path | None = None,
    merge_threshold: float | None = None,
    merge_persist: int = 1,
    merge_absorb: bool = False,
) -> dict[str, Any]:
    """Run the experiment on a tour and write OUT (what the CLI and the demo call):
    ``report.json``, ``report.md``, the figures and the session maps.

    Args:
        config: a ``RatSLAMConfig``, a config path/name, or None for the tour's shipped
            config (:data:`TOUR_CONFIG`), unmodified.
        tour_spec: ``sim:NAME``, optionally with the simulator's options
            (``sim:NAME?key=value&...``, :func:`parse_tour_spec`).
        out: the output folder.
        overrides: flat config keys replaced last.
        merge_options: ``merge_maps`` options (default: the authors' code).
        rerun: watch the multisession mapping live in a rerun viewer
            (:class:`torchratslam.viz.rerun_viewer.RerunObserver`; extra ``viewer``).
        rerun_save: record the multisession mapping for rerun into this ``.rrd`` file.
        merge_threshold: :class:`MultiSessionRatSLAM` ``merge_threshold`` (None: the paper's).
        merge_persist: :class:`MultiSessionRatSLAM` ``merge_persist`` (1: the paper's).
        merge_absorb: :class:`MultiSessionRatSLAM` ``merge_absorb`` (False: the paper's).

    Returns:
        :func:`run_tour`'s result (``report`` and ``data``).
    """
    from torchratslam.sim import get_tour
    from torchratslam.viz.multisession import write_figures

    name, tour_options, config = _tour_setup(tour_spec, config, overrides)
    tour = get_tour(name, seed=seed, **tour_options)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    observer = None
    if rerun or rerun_save:
        from torchratslam.viz.rerun_viewer import RerunObserver

        observer = RerunObserver(None, spawn=rerun, save=rerun_save)
    try:
        result = run_tour(
            config,
            tour,
            ablation=ablation,
            backends=tuple(backends),
            save_dir=out,
            progress=progress,
            max_frames=max_frames,
            merge_options=merge_options,
            observer=observer,
            session_options={
                k: v
                for k, v in (
                    ("merge_threshold", merge_threshold),
                    ("merge_persist", merge_persist),
                    ("merge_absorb", merge_absorb),
                )
                if v != {"merge_threshold": None, "merge_persist": 1, "merge_absorb": False}[k]
            },
        )
    finally:
        if observer is not None:
            observer.close()
    report = result["report"]
    report["seed"] = seed
    if tour_options:
        report["tour_options"] = tour_options
    report["config"] = config.to_flat()
    _write_json(out / "report.json", report)
    atomic_write_text(out / "report.md", report_markdown(report))
    if figures:
        report["figures"] = [p.name for p in write_figures(result, out)]
        _write_json(out / "report.json", report)
    return result


# ------------------------------------------------------------------ across seeds
SEED_TOLERANCE = 0.02
"""Issue 18: the merged map's experience count within 2% of the continuous run's."""
ABLATION_MARGIN = 0.10
"""Issue 18: without the pose-cell shift at least 10% more experiences."""
WRONG_PLACE_M = 1.0
"""A merge whose two matched experiences lie further apart (ground truth) is wrong."""
RECOMMENDED_MERGE_OPTIONS: dict[str, Any] = {"pc_shift_rotate": True}
"""Issue 18: the ``merge_maps`` options recommended for merges that hold across seeds
(docs/multisession.md, "Across seeds"); each is a named deviation from the paper."""
RECOMMENDED_SESSION_OPTIONS: dict[str, Any] = {"merge_persist": 2, "merge_absorb": True}
"""Issue 18: the :class:`MultiSessionRatSLAM` options recommended with
:data:`RECOMMENDED_MERGE_OPTIONS` (a match confirmed by the next new template, the
first matching template identified with its stored match)."""


def _gt_at(gt: np.ndarray, t: float) -> np.ndarray:
    """Ground-truth ``(x, y)`` at the row nearest time ``t``. Shape: gt ``(T, 4)``."""
    return np.asarray(gt[int(np.argmin(np.abs(gt[:, 0] - t))), 1:3], np.float64)


def merge_distances(merges: list[dict[str, Any]], gt: np.ndarray) -> list[float]:
    """Ground-truth distance (m) between the two experiences matched by each merge.

    Shape:
        gt: ``(T, 4)`` rows ``[t, x, y, th]`` on the merges' clock.
    """
    out = []
    for m in merges:
        a, b = m.get("loaded_exp_t"), m.get("partial_exp_t")
        if a is None or b is None or not (np.isfinite(a) and np.isfinite(b)):
            out.append(float("nan"))
            continue
        out.append(float(np.linalg.norm(_gt_at(gt, a) - _gt_at(gt, b))))
    return out


PLACE_HEADING_DEG = 20.0
""":func:`place_counts`: two experiences are at one place when their headings (ground
truth) differ by at most this much (and their positions by half the median spacing)."""


def place_counts(
    state: MapState, gt: np.ndarray, session_frames: np.ndarray | None = None
) -> dict[str, Any]:
    """How many of a map's experiences are distinct places, in ground truth (a diagnostic
    of the per-seed table: which experiences are repeats, which lie where no session
    looks).

    An experience *repeats* an earlier one (creation time) when their ground-truth
    positions are within half the median distance between experiences consecutive in
    creation, and their headings within :data:`PLACE_HEADING_DEG`; ``places`` counts
    the rest. With ``session_frames`` (rows of ``gt`` the sessions drive), an
    experience is *unseen* when no session frame has its position and heading within
    the same bounds (a view only the continuous run's drives between sessions see).

    Shape:
        gt: ``(T, 4)`` rows ``[t, x, y, th]`` on the map's clock; session_frames: ``(F,)``.

    Returns:
        ``experiences``, ``repeats``, ``places``, ``radius_m``, and with
        ``session_frames``: ``unseen``, ``places_seen`` (places the sessions see).
    """
    from ratslam_graph.geometry import wrap_angle

    n = state.n_experiences
    out: dict[str, Any] = {"experiences": n, "repeats": 0, "places": n, "radius_m": 0.0}
    if n == 0:
        return out
    idx = np.argmin(np.abs(gt[:, 0][None, :] - state.exp_t[:, None]), axis=1)
    p, h = gt[idx, 1:3], gt[idx, 3]
    order = np.argsort(state.exp_t, kind="stable")
    steps = np.linalg.norm(np.diff(p[order], axis=0), axis=1)
    r = 0.5 * float(np.median(steps)) if steps.size else 0.0
    hmax = np.radians(PLACE_HEADING_DEG)

    def near(q: np.ndarray, hq: np.ndarray) -> np.ndarray:
        d = np.linalg.norm(p[:, None, :] - q[None, :, :], axis=2)
        dh = np.abs(wrap_angle(h[:, None] - hq[None, :]))
        return (d <= r) & (dh <= hmax)

    rank = np.empty(n, np.int64)
    rank[order] = np.arange(n)
    repeat = (near(p, h) & (rank[None, :] < rank[:, None])).any(axis=1)
    out.update(repeats=int(repeat.sum()), places=int((~repeat).sum()), radius_m=r)
    if session_frames is not None:
        f = np.asarray(session_frames, np.int64)
        seen = near(gt[f, 1:3], gt[f, 3]).any(axis=1)
        out.update(unseen=int((~seen).sum()), places_seen=int((~repeat & seen).sum()))
    return out


def partial_experiences(merges: list[dict[str, Any]]) -> int:
    """The partial maps' experiences that merges brought into the stored maps, each once.

    They are the only experiences whose pose-cell associations the shift moves, so the
    ablation without it can re-make at most these (measured: never more on the virtual
    tour's seeds 0-19). A merge brings its partial map's experiences but the matched
    ``e_z``; within a session the running map at a later merge holds the earlier
    merges' partial maps (and the stored maps merged since), so a session counts at its
    last merge.

    Args:
        merges: :attr:`MultiSessionRatSLAM.merges` records (``session``,
            ``partial_experiences``), in order.
    """
    last = {m["session"]: m for m in merges}
    return int(sum(max(int(m.get("partial_experiences", 0)) - 1, 0) for m in last.values()))


def seed_row(
    config: RatSLAMConfig,
    tour: Any,
    *,
    ablation: bool = True,
    max_frames: int | None = None,
    merge_options: dict[str, Any] | None = None,
    **session_kwargs: Any,
) -> dict[str, Any]:
    """One seed of the per-seed check: the continuous single-session run, the
    multisession run and (``ablation``) the multisession run without the pose-cell shift.

    Args:
        config: the configuration.
        tour: the simulated tour of this seed.
        ablation: also run without the pose-cell shift.
        max_frames: frames per session at most (quick checks).
        merge_options: ``merge_maps`` options.
        **session_kwargs: :class:`MultiSessionRatSLAM` options (``merge_threshold``,
            ``merge_persist``, ``merge_absorb``).

    Returns:
        ``single``, ``multi``, ``ablation`` (experience counts), ``diff`` and
        ``ablation_diff`` (relative to single), ``partial_experiences`` (the partial
        maps' experiences the merges brought in, the matched ``e_z`` excluded, each
        counted once: a session's at its last merge) and ``ablation_ceiling`` (the ablation's
        difference if it re-made every one of them: ``(multi + partial - single) /
        single``), ``single_places`` and ``multi_places``
        (:func:`place_counts`: repeats, distinct places, places the sessions see),
        ``merges`` (session, frame, ground-truth distance of the matched experiences in
        m, experiences added), ``wrong_merges``.
    """
    clock = _clock(tour)
    limit = None if max_frames is None else max_frames * len(tour.sessions)
    kw: dict[str, Any] = dict(max_frames=max_frames, **session_kwargs)
    if merge_options:
        kw["merge_options"] = dict(merge_options)
    single, _ = _single_run(config, clock.cont.frames(), limit, False)
    multi = run_sessions(config, tour.sessions, offsets=clock.offsets, **kw)
    n_s, n_m = single.n_experiences, multi["maps"][-1].n_experiences
    partial = partial_experiences(multi["merges"])
    dist = merge_distances(multi["merges"], clock.gt)
    frames = np.concatenate(
        [np.arange(a, min(a + len(t), len(clock.gt))) for a, t in zip(clock.starts, tour.sessions)]
    )
    row: dict[str, Any] = {
        "single": int(n_s),
        "multi": int(n_m),
        "single_places": place_counts(single, clock.gt, frames),
        "multi_places": place_counts(multi["maps"][-1], clock.gt, frames),
        "maps": len(multi["maps"]),
        "diff": _relative(n_m, n_s),
        "partial_experiences": int(partial),
        "ablation_ceiling": _relative(n_m + partial, n_s),
        "merges": [
            {
                "session": m["session"],
                "frame": m["frame"],
                "error": m["error"],
                "distance_m": d,
                "experiences_added": m.get("experiences_added"),
                "partial_experiences": m.get("partial_experiences"),
            }
            for m, d in zip(multi["merges"], dist)
        ],
        "wrong_merges": int(sum(1 for d in dist if not d <= WRONG_PLACE_M)),
    }
    if ablation:
        abl = run_sessions(
            config, tour.sessions, offsets=clock.offsets, shift_pose_cells=False, **kw
        )
        n_a = abl["maps"][-1].n_experiences
        row.update(ablation=int(n_a), ablation_diff=_relative(n_a, n_s))
    return row


def seed_table(
    tour_spec: str,
    seeds: Iterable[int],
    *,
    config: Any = None,
    ablation: bool = True,
    max_frames: int | None = None,
    overrides: dict[str, Any] | None = None,
    merge_options: dict[str, Any] | None = None,
    on_row: Any = None,
    **session_kwargs: Any,
) -> dict[str, Any]:
    """The per-seed check of issue 18 on a simulated tour.

    Args:
        tour_spec: ``sim:NAME``, optionally with the simulator's options
            (``sim:NAME?key=value&...``, :func:`parse_tour_spec`).
        seeds: simulator seeds.
        config: config, path/name, or None for the tour's shipped config, unmodified.
        ablation: also run without the pose-cell shift.
        max_frames: frames per session at most.
        overrides: flat config keys replaced last.
        merge_options: ``merge_maps`` options.
        on_row: called with ``(seed, row)`` after each seed (progress).
        **session_kwargs: :class:`MultiSessionRatSLAM` options.

    Returns:
        ``tour``, ``rows`` (seed -> :func:`seed_row`), and the summary: ``within``
        (seeds within :data:`SEED_TOLERANCE`), ``within_one`` (seeds whose counts differ
        by at most one experience), ``ablation_above`` (seeds whose ablation is at
        least :data:`ABLATION_MARGIN` above), ``ablation_reachable`` (seeds whose
        ``ablation_ceiling`` reaches it), ``wrong_merges``, ``seeds``.
    """
    from torchratslam.sim import get_tour

    name, tour_options, config = _tour_setup(tour_spec, config, overrides)
    rows: dict[int, dict[str, Any]] = {}
    for seed in seeds:
        row = seed_row(
            config,
            get_tour(name, seed=int(seed), **tour_options),
            ablation=ablation,
            max_frames=max_frames,
            merge_options=merge_options,
            **session_kwargs,
        )
        rows[int(seed)] = row
        if on_row is not None:
            on_row(int(seed), row)
    diffs = [r["diff"] for r in rows.values()]
    out: dict[str, Any] = {
        "tour": name,
        "seeds": list(rows),
        "rows": rows,
        "within": int(sum(1 for d in diffs if d is not None and abs(d) <= SEED_TOLERANCE)),
        "within_one": int(sum(1 for r in rows.values() if abs(r["multi"] - r["single"]) <= 1)),
        "wrong_merges": int(sum(r["wrong_merges"] for r in rows.values())),
        "options": {**session_kwargs, **(merge_options or {})},
    }
    if tour_options:
        out["tour_options"] = tour_options
    if ablation:
        out["ablation_above"] = int(
            sum(
                1
                for r in rows.values()
                if r["ablation_diff"] is not None and r["ablation_diff"] >= ABLATION_MARGIN
            )
        )
        out["ablation_reachable"] = int(
            sum(
                1
                for r in rows.values()
                if r["ablation_ceiling"] is not None and r["ablation_ceiling"] >= ABLATION_MARGIN
            )
        )
    return out


def seed_table_markdown(table: dict[str, Any]) -> str:
    """The per-seed table as Markdown (experiences: multisession / single, ablation)."""
    seeds = table["seeds"]
    rows = table["rows"]

    def line(label: str, cell: Callable[[dict[str, Any]], str]) -> str:
        return f"| {label} | " + " | ".join(cell(rows[s]) for s in seeds) + " |"

    lines = [
        f"### {table['tour']}: experiences per seed",
        "",
        "| seed | " + " | ".join(str(s) for s in seeds) + " |",
        "|---|" + "---|" * len(seeds),
        line("multi / single", lambda r: f"{r['multi']}/{r['single']}"),
        line("difference", lambda r: _fmt(r["diff"], "+.2%")),
    ]
    if "ablation_above" in table:
        lines.append(
            line(
                "ablation (no pose-cell shift)",
                lambda r: f"{r['ablation']} ({_fmt(r['ablation_diff'], '+.1%')})",
            )
        )
    if all("ablation_ceiling" in rows[s] for s in seeds):
        lines.append(
            line(
                "partial experiences merged (ablation ceiling)",
                lambda r: f"{r['partial_experiences']} ({_fmt(r['ablation_ceiling'], '+.1%')})",
            )
        )
    if all("single_places" in rows[s] for s in seeds):
        lines.append(
            line(
                "places multi / single (seen by the sessions)",
                lambda r: f"{r['multi_places']['places_seen']}/{r['single_places']['places_seen']}",
            )
        )
        lines.append(
            line(
                "single: repeats, unseen",
                lambda r: f"{r['single_places']['repeats']}, {r['single_places']['unseen']}",
            )
        )
    lines.append(
        line(
            "merge distance (m)",
            lambda r: ", ".join(_fmt(m["distance_m"], ".2f") for m in r["merges"]) or "none",
        )
    )
    n = len(seeds)
    lines += [
        "",
        f"- within {SEED_TOLERANCE:.0%} of the continuous single session: "
        f"{table['within']}/{n} seeds",
    ]
    if "within_one" in table:
        lines.append(f"- within one experience: {table['within_one']}/{n} seeds")
    if "ablation_above" in table:
        lines.append(
            f"- ablation at least {ABLATION_MARGIN:.0%} above: {table['ablation_above']}/{n} seeds"
        )
    if "ablation_reachable" in table:
        lines.append(
            f"- ablation ceiling at least {ABLATION_MARGIN:.0%} above (the partial map large "
            f"enough for it): {table['ablation_reachable']}/{n} seeds"
        )
    lines.append(
        f"- merges at a wrong place (matched experiences > {WRONG_PLACE_M:g} m apart): "
        f"{table['wrong_merges']}"
    )
    if table.get("options"):
        lines.append(f"- options: {table['options']}")
    if table.get("tour_options"):
        lines.append(f"- tour options: {table['tour_options']}")
    return "\n".join(lines) + "\n"
