"""Figures of the multisession experiment, like the paper's Fig. 9 (a-e), Fig. 10's ICP
overlay and Fig. 12's ablation, from :func:`torchratslam.experiments.multisession_tour.run_tour`'s
result. Pure drawing: matplotlib's Agg backend, one PNG per panel.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["SESSION_COLOURS", "write_figures"]

SESSION_COLOURS = ("tab:blue", "gold", "tab:green", "tab:purple", "tab:orange", "tab:cyan")


def _session_of(state: Any, bounds: np.ndarray) -> np.ndarray:
    """Session index of every experience from its creation time."""
    return np.clip(np.searchsorted(bounds, state.exp_t, side="right") - 1, 0, len(bounds) - 1)


def _links(st: Any) -> np.ndarray:
    return np.stack([st.link_from, st.link_to], 1)


def _draw(ax: Any, poses: np.ndarray, links: np.ndarray, colour: str, label: str) -> None:
    from matplotlib.collections import LineCollection

    p = np.asarray(poses).reshape(-1, 3)
    e = np.asarray(links, np.int64).reshape(-1, 2)
    if e.size:
        ok = (e >= 0).all(1) & (e < len(p)).all(1)
        segments = p[e[ok]][:, :, :2]
        ax.add_collection(LineCollection(segments, colors=colour, linewidths=0.7))  # type: ignore[arg-type]
    ax.scatter(p[:, 0], p[:, 1], s=5, color=colour, label=f"{label} ({len(p)})", zorder=3)


def _single(ax: Any, data: dict[str, Any], report: dict[str, Any]) -> None:
    _draw(ax, data["single"].exp_pose, _links(data["single"]), "tab:purple", "single session")
    ax.set_title("a) single-session map (continuous run)")


def _first_session(ax: Any, data: dict[str, Any], report: dict[str, Any]) -> None:
    first = data["multi"]["session_maps"][0]
    _draw(ax, first.exp_pose, _links(first), SESSION_COLOURS[0], report["sessions"][0])
    ax.set_title("b) map at the end of the first session")


def _before_merge(ax: Any, data: dict[str, Any], report: dict[str, Any]) -> None:
    snap, m0 = data["multi"]["snapshots"][0], data["multi"]["merges"][0]
    _draw(ax, snap["loaded"], np.zeros((0, 2)), SESSION_COLOURS[0], "loaded map")
    _draw(ax, snap["partial"], np.zeros((0, 2)), SESSION_COLOURS[1], "partial map")
    ax.set_title(f"c) {m0['session']}, frame {m0['frame']}: the merge condition is met")


def _after_merge(ax: Any, data: dict[str, Any], report: dict[str, Any]) -> None:
    snap, m0 = data["multi"]["snapshots"][0], data["multi"]["merges"][0]
    st = snap["merged_state"]
    n_l = int(snap["n_loaded"])
    lk = _links(st)
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


def _final(ax: Any, data: dict[str, Any], report: dict[str, Any]) -> None:
    from matplotlib.collections import LineCollection

    final = data["multi"]["maps"][-1]
    ses = _session_of(final, np.asarray(data["session_starts"], np.float64))
    lk = _links(final)
    across = lk[ses[lk[:, 0]] != ses[lk[:, 1]]]  # links joining the sessions' maps
    if len(across):
        seg = final.exp_pose[across][:, :, :2]
        ax.add_collection(LineCollection(seg, colors="0.5", linewidths=0.7, linestyles=":"))
    for k in range(len(report["sessions"])):
        sel = np.flatnonzero(ses == k)
        if sel.size:
            remap = np.full(final.n_experiences, -1)
            remap[sel] = np.arange(sel.size)
            lk = remap[_links(final)]
            _draw(
                ax,
                final.exp_pose[sel],
                lk[(lk >= 0).all(1)],
                SESSION_COLOURS[k % len(SESSION_COLOURS)],
                f"from {report['sessions'][k]}",
            )
    ax.set_title("e) final multisession map, by session of origin")


def _icp_overlay(ax: Any, data: dict[str, Any], report: dict[str, Any]) -> None:
    """Fig. 10: the single-session map moved by LibICP onto the multisession map (the
    fixed model), as the paper computes it."""
    from torchratslam.viz.plots import draw_icp_overlay

    draw_icp_overlay(
        ax,
        data["multi"]["maps"][-1].exp_pose,
        data["libicp"].aligned,
        fixed_label="multisession",
        moved_label="single session (ICP-aligned)",
        mse_m2=data["libicp"].residual_m2,
    )


def _ablation(ax: Any, data: dict[str, Any], report: dict[str, Any]) -> None:
    """Fig. 12: the map made without the pose-cell shift over the multisession map, its
    duplicates (a second experience of a template that already had one) marked."""
    abl, final = data["ablation"]["maps"][-1], data["multi"]["maps"][-1]
    _draw(ax, final.exp_pose, _links(final), "0.7", "multisession, with the shift")
    _draw(ax, abl.exp_pose, _links(abl), "tab:red", "no pose-cell shift")
    tpl = np.asarray(abl.exp_template, np.int64)
    first = np.unique(tpl, return_index=True)[1]
    dup = np.setdiff1d(np.arange(len(tpl)), first)
    if dup.size:
        ax.scatter(
            abl.exp_pose[dup, 0],
            abl.exp_pose[dup, 1],
            s=60,
            marker="x",
            color="black",
            label=f"duplicates: a template's second experience ({dup.size})",
            zorder=4,
        )
    ax.set_title(f"ablation: {abl.n_experiences} experiences vs {final.n_experiences}")


Panel = Callable[[Any, dict[str, Any], dict[str, Any]], None]


def _panels(data: dict[str, Any]) -> list[tuple[str, Panel]]:
    """The figures that this result has data for, in order."""
    merged = bool(data["multi"]["snapshots"])
    panels: list[tuple[str, Panel, bool]] = [
        ("fig9a_single.png", _single, True),
        ("fig9b_session1.png", _first_session, True),
        ("fig9c_before_merge.png", _before_merge, merged),
        ("fig9d_after_merge.png", _after_merge, merged),
        ("fig9e_final.png", _final, True),
        ("fig10_icp.png", _icp_overlay, data.get("libicp") is not None),
        ("fig12_ablation.png", _ablation, "ablation" in data),
    ]
    return [(name, draw) for name, draw, wanted in panels if wanted]


def write_figures(result: dict[str, Any], out: Path) -> list[Path]:
    """Figures like the paper's Fig. 9 (and Fig. 10's ICP overlay, Fig. 12's ablation)
    under ``out``; returns their paths."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from torchratslam.viz.plots import save_figure

    data, report = result["data"], result["report"]
    paths = []
    for name, draw in _panels(data):
        fig, ax = plt.subplots(figsize=(5, 5))
        draw(ax, data, report)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.autoscale_view()
        ax.legend(fontsize=7, loc="best")
        fig.tight_layout()
        p = Path(out) / name
        save_figure(fig, p, dpi=100, tight=False)
        paths.append(p)
    return paths
