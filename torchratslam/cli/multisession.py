"""``torchratslam multisession``: multisession versus single-session mapping of a
simulated tour (the multisession paper's experiments, Section 5).

Every session of the tour is mapped in turn, each saved and loaded by the next, and
merged when it meets a stored map. The reference (``single`` in report.json) is the
paper's single mapping session: one continuous run through every session, joined by
drives along the tour's roads (``Tour.continuous()``); the sessions concatenated with a
kidnap between them (``single_concatenated``) and the last session alone
(``single_last_session``) are reported too. Writes under OUT: ``report.json``
(templates, experiences, links, ATE, ICP RMSE between the maps, the merges, optional
ablation and backend comparison), ``report.md`` (the same as tables), figures like the
paper's Fig. 9 (``fig9_*.png``: single map, first session, before merge, after merge,
final, ICP overlay) and the session maps (``multi/<session>/state``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from torchratslam.config import load_config
from torchratslam.graph.atomic import atomic_write_text

SESSION_COLOURS = ("tab:blue", "gold", "tab:green", "tab:purple", "tab:orange", "tab:cyan")


def register(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "multisession",
        help="map a simulated tour session by session, merging maps, vs single-session",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--config",
        default=None,
        help="config file or shipped name (default: the tour's own config)",
    )
    p.add_argument("--tour", required=True, help="sim:NAME (virtual_tour, lab_tour, irat_like)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument(
        "--ablation",
        action="store_true",
        help="also map without the pose-cell shift (the paper's Fig. 12)",
    )
    p.add_argument(
        "--backends",
        default="",
        help="comma-separated relaxation backends to compare, e.g. alpha,gtsam",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a config key (repeatable)",
    )
    p.add_argument("--seed", type=int, default=0, help="simulator seed (default 0)")
    p.add_argument(
        "--max-frames",
        type=int,
        default=None,
        help="at most this many frames per session (quick checks)",
    )
    p.add_argument("--no-figures", action="store_true", help="write report.json only")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=main)
    return p


TOUR_CONFIG = {"virtual_tour": "virtual_tour", "lab_tour": "lab_tour", "irat_like": "irat"}
"""The shipped config of each tour, used unmodified when no --config is given."""


def _tour_name(spec: str) -> str:
    from torchratslam.graph.errors import InputError

    name = spec.removeprefix("sim:")
    if "/" in name:
        raise InputError(f"--tour takes a whole tour (sim:NAME), not one session: {spec!r}")
    return name


def _write_json(path: Path, obj: Any) -> None:
    """Atomic JSON write (temporary file + rename)."""
    text = json.dumps(obj, indent=1, default=lambda v: v.item() if hasattr(v, "item") else str(v))
    atomic_write_text(path, text)


def _fmt(v: Any, spec: str = ".4g") -> str:
    return "-" if v is None else format(v, spec)


def report_markdown(report: dict[str, Any]) -> str:
    """The report as Markdown tables (what the demo prints and the README shows)."""
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
    lines += [
        "",
        f"- ICP RMSE multisession vs single-session (continuous) map: "
        f"{_fmt(report['icp_rmse'])} m ({_fmt(report['icp_rmse_relative'])} of the tour's "
        f"{report['tour_extent_m']:.1f} m extent); the paper reports "
        f"{_fmt(report['paper_icp_rmse'])}; vs the concatenated run: "
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
    if "backends" in report:
        lines += [
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
    return "\n".join(lines) + "\n"


def _session_of(state: Any, bounds: np.ndarray) -> np.ndarray:
    """Session index of every experience from its creation time."""
    return np.clip(np.searchsorted(bounds, state.exp_t, side="right") - 1, 0, len(bounds) - 1)


def _draw(ax: Any, poses: np.ndarray, links: np.ndarray, colour: str, label: str) -> None:
    from matplotlib.collections import LineCollection

    p = np.asarray(poses).reshape(-1, 3)
    e = np.asarray(links, np.int64).reshape(-1, 2)
    if e.size:
        ok = (e >= 0).all(1) & (e < len(p)).all(1)
        ax.add_collection(LineCollection(p[e[ok]][:, :, :2], colors=colour, linewidths=0.7))
    ax.scatter(p[:, 0], p[:, 1], s=5, color=colour, label=f"{label} ({len(p)})", zorder=3)


def write_figures(result: dict[str, Any], out: Path) -> list[Path]:
    """Figures like the paper's Fig. 9 (and Fig. 10's ICP overlay) under ``out``."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from torchratslam.viz.plots import save_figure

    data, report = result["data"], result["report"]
    multi = data["multi"]
    bounds = np.asarray(data["session_starts"], np.float64)
    paths = []

    def links(st: Any) -> np.ndarray:
        return np.stack([st.link_from, st.link_to], 1)

    def save(fig: Any, name: str) -> None:
        ax = fig.axes[0]
        ax.set_aspect("equal", adjustable="datalim")
        ax.autoscale_view()
        ax.legend(fontsize=7, loc="best")
        fig.tight_layout()
        p = out / name
        save_figure(fig, p, dpi=100, tight=False)
        paths.append(p)

    fig, ax = plt.subplots(figsize=(5, 5))
    _draw(ax, data["single"].exp_pose, links(data["single"]), "tab:purple", "single session")
    ax.set_title("a) single-session map (continuous run)")
    save(fig, "fig9a_single.png")

    first = multi["session_maps"][0]
    fig, ax = plt.subplots(figsize=(5, 5))
    _draw(ax, first.exp_pose, links(first), SESSION_COLOURS[0], report["sessions"][0])
    ax.set_title("b) map at the end of the first session")
    save(fig, "fig9b_session1.png")

    if multi["snapshots"]:
        snap = multi["snapshots"][0]
        st = snap["merged_state"]
        n_l = int(snap["n_loaded"])
        m0 = multi["merges"][0]
        fig, ax = plt.subplots(figsize=(5, 5))
        _draw(ax, snap["loaded"], np.zeros((0, 2)), SESSION_COLOURS[0], "loaded map")
        _draw(ax, snap["partial"], np.zeros((0, 2)), SESSION_COLOURS[1], "partial map")
        ax.set_title(f"c) {m0['session']}, frame {m0['frame']}: the merge condition is met")
        save(fig, "fig9c_before_merge.png")
        fig, ax = plt.subplots(figsize=(5, 5))
        lk = links(st)
        _draw(ax, st.exp_pose[:n_l], lk[(lk < n_l).all(1)], SESSION_COLOURS[0], "loaded")
        part = np.r_[snap["merged"][m0["loaded_exp"]][None], st.exp_pose[n_l:]]
        _draw(ax, part, np.zeros((0, 2)), SESSION_COLOURS[1], "partial, transformed")
        ax.scatter(
            *st.exp_pose[m0["loaded_exp"], :2],
            s=120,
            facecolors="none",
            edgecolors="red",
            label="merge point",
            zorder=4,
        )
        ax.set_title("d) after the merge")
        save(fig, "fig9d_after_merge.png")

    final = multi["maps"][-1]
    ses = _session_of(final, bounds)
    fig, ax = plt.subplots(figsize=(5, 5))
    from matplotlib.collections import LineCollection

    lk = links(final)
    across = lk[ses[lk[:, 0]] != ses[lk[:, 1]]]  # links joining the sessions' maps
    if len(across):
        seg = final.exp_pose[across][:, :, :2]
        ax.add_collection(LineCollection(seg, colors="0.5", linewidths=0.7, linestyles=":"))
    for k in range(len(report["sessions"])):
        sel = np.flatnonzero(ses == k)
        if sel.size:
            remap = np.full(final.n_experiences, -1)
            remap[sel] = np.arange(sel.size)
            lk = remap[links(final)]
            _draw(
                ax,
                final.exp_pose[sel],
                lk[(lk >= 0).all(1)],
                SESSION_COLOURS[k % len(SESSION_COLOURS)],
                f"from {report['sessions'][k]}",
            )
    ax.set_title("e) final multisession map, by session of origin")
    save(fig, "fig9e_final.png")

    if data.get("icp") is not None:
        fig, ax = plt.subplots(figsize=(5, 5))
        s = data["single"].exp_pose
        ax.scatter(s[:, 0], s[:, 1], s=5, color="tab:purple", label="single session")
        a = data["icp"].aligned
        ax.scatter(a[:, 0], a[:, 1], s=5, color="tab:orange", label="multisession (ICP-aligned)")
        ax.set_title(f"ICP: RMSE {report['icp_rmse']:.4g} m")
        save(fig, "fig10_icp.png")

    if "ablation" in data:
        abl = data["ablation"]["maps"][-1]
        fig, ax = plt.subplots(figsize=(5, 5))
        _draw(ax, abl.exp_pose, links(abl), "tab:red", "no pose-cell shift")
        ax.set_title(f"ablation: {abl.n_experiences} experiences vs {final.n_experiences}")
        save(fig, "fig12_ablation.png")
    return paths


def run(
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
) -> dict[str, Any]:
    """Run the experiment and write OUT (what the CLI and the demo call).

    Args:
        config: a ``RatSLAMConfig``, a config path/name, or None for the tour's shipped
            config (:data:`TOUR_CONFIG`), unmodified.
        overrides: flat config keys replaced last.

    Returns:
        ``run_tour``'s result (``report`` and ``data``).
    """
    from torchratslam.multisession.session import run_tour
    from torchratslam.sim import get_tour

    name = _tour_name(tour_spec)
    if config is None:
        config = load_config(TOUR_CONFIG.get(name))
    elif isinstance(config, (str, Path)):
        config = load_config(config)
    if overrides:
        config = config.replace(**overrides)
    tour = get_tour(name, seed=seed)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    result = run_tour(
        config,
        tour,
        ablation=ablation,
        backends=tuple(backends),
        save_dir=out,
        progress=progress,
        max_frames=max_frames,
    )
    report = result["report"]
    report["seed"] = seed
    report["config"] = config.to_flat()
    _write_json(out / "report.json", report)
    atomic_write_text(out / "report.md", report_markdown(report))
    if figures:
        report["figures"] = [p.name for p in write_figures(result, out)]
        _write_json(out / "report.json", report)
    return result


def main(args: argparse.Namespace) -> int:
    from torchratslam.graph.errors import ConfigError

    backends = tuple(b.strip() for b in args.backends.split(",") if b.strip())
    overrides = {}
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep:
            raise ConfigError(f"--set {item!r}: expected KEY=VALUE")
        overrides[key.strip()] = value.strip()
    result = run(
        args.config,
        args.tour,
        args.out,
        ablation=args.ablation,
        backends=backends,
        seed=args.seed,
        max_frames=args.max_frames,
        figures=not args.no_figures,
        progress=not args.quiet,
        overrides=overrides,
    )
    print(report_markdown(result["report"]))
    print(f"wrote {Path(args.out) / 'report.json'}")
    return 0
