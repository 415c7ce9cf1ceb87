"""The multisession experiment across seeds: per seed the continuous single-session run,
the multisession run and the run without the pose-cell shift, their experience counts
and where the merges matched (ground truth)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from torchratslam.config import RatSLAMConfig
from torchratslam.experiments.multisession_report import fmt_value
from torchratslam.experiments.multisession_tour import (
    relative,
    run_sessions,
    single_run,
    tour_clock,
    tour_setup,
)
from torchratslam.maps.state import MapState

__all__ = [
    "ABLATION_MARGIN",
    "RECOMMENDED_MERGE_OPTIONS",
    "RECOMMENDED_SESSION_OPTIONS",
    "SEED_TOLERANCE",
    "WRONG_PLACE_M",
    "merge_distances",
    "partial_experiences",
    "place_counts",
    "seed_row",
    "seed_table",
    "seed_table_markdown",
]


SEED_TOLERANCE = 0.02
"""The merged map's experience count within 2% of the continuous run's."""
ABLATION_MARGIN = 0.10
"""Without the pose-cell shift at least 10% more experiences."""
WRONG_PLACE_M = 1.0
"""A merge whose two matched experiences lie further apart (ground truth) is wrong."""
RECOMMENDED_MERGE_OPTIONS: dict[str, Any] = {"pc_shift_rotate": True}
"""The ``merge_maps`` options recommended for merges that hold across seeds
(docs/multisession.md, "Across seeds"); each is a named deviation from the paper."""
RECOMMENDED_SESSION_OPTIONS: dict[str, Any] = {
    "merge_persist": 2,
    "merge_absorb": True,
    "merge_anchor": "view",
}
"""The :class:`MultiSessionRatSLAM` options recommended with
:data:`RECOMMENDED_MERGE_OPTIONS`: a match confirmed by the next new template, the maps
joined at the frame whose view matches the stored template best (the frames passed
since the streak's first match included), the earlier matching templates identified
with their stored matches (their links measured anew). On the virtual tour's seeds
0-19 and 1000-1009: within one experience of the continuous run on 26 of 30, no merge
more than 1 m off (docs/multisession.md, "Across seeds")."""


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
    clock = tour_clock(tour)
    limit = None if max_frames is None else max_frames * len(tour.sessions)
    kw: dict[str, Any] = dict(max_frames=max_frames, **session_kwargs)
    if merge_options:
        kw["merge_options"] = dict(merge_options)
    single, _ = single_run(config, clock.cont.frames(), limit, False)
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
        "diff": relative(n_m, n_s),
        "partial_experiences": int(partial),
        "ablation_ceiling": relative(n_m + partial, n_s),
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
        row.update(ablation=int(n_a), ablation_diff=relative(n_a, n_s))
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
    """The per-seed check on a simulated tour: merged against continuous experience counts.

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

    name, tour_options, config = tour_setup(tour_spec, config, overrides)
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
        line("difference", lambda r: fmt_value(r["diff"], "+.2%")),
    ]
    if "ablation_above" in table:
        lines.append(
            line(
                "ablation (no pose-cell shift)",
                lambda r: f"{r['ablation']} ({fmt_value(r['ablation_diff'], '+.1%')})",
            )
        )
    if all("ablation_ceiling" in rows[s] for s in seeds):
        lines.append(
            line(
                "partial experiences merged (ablation ceiling)",
                lambda r: (
                    f"{r['partial_experiences']} ({fmt_value(r['ablation_ceiling'], '+.1%')})"
                ),
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
            lambda r: ", ".join(fmt_value(m["distance_m"], ".2f") for m in r["merges"]) or "none",
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
