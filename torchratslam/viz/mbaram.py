"""Figures of the MBARAM experiment: the topological map over the world, the nodes
added per lap beside the paper's, and the localisation rate per lap."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["plot_results"]


def plot_results(result: Any, session: Any, out: Path, *, paper: dict[str, Any]) -> None:
    """``map.png``, ``nodes_per_lap.png`` and ``localisation.png`` (``paper``: the
    published numbers drawn beside ours, ``nodes_per_lap`` among them)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    g, xy = result.model.graph, result.node_xy
    fig, ax = plt.subplots(figsize=(7, 6))
    session.world.plot(ax)
    ax.plot(result.path[:, 0], result.path[:, 1], color="0.75", lw=0.6, label="path")
    for u, v in g.edges:
        ax.plot(xy[[u, v], 0], xy[[u, v], 1], "k-", lw=0.8)
    ax.plot(xy[:, 0], xy[:, 1], "o", color="red", ms=5, label=f"{len(xy)} nodes")
    ax.set_aspect("equal")
    ax.set_title(f"MBARAM topological map: {len(xy)} nodes, {g.number_of_edges()} edges")
    ax.legend(loc="upper right", fontsize=8)
    fig.savefig(out / "map.png", dpi=120, bbox_inches="tight")
    plt.close(fig)

    per_lap = result.nodes_per_lap
    fig, ax = plt.subplots(figsize=(6, 4))
    laps = np.arange(1, len(per_lap) + 1)
    ax.bar(laps - 0.2, per_lap, width=0.4, label="nodes added (this run)")
    published = paper["nodes_per_lap"][: len(per_lap)]
    ax.bar(
        np.arange(1, len(published) + 1) + 0.2,
        published,
        width=0.4,
        label="paper, Fig. 13a (24, then 5-6; 47 after 5)",
    )
    ax.set_xlabel("lap")
    ax.set_ylabel("nodes added")
    ax.set_xticks(laps)
    ax.legend()
    fig.savefig(out / "nodes_per_lap.png", dpi=120, bbox_inches="tight")
    plt.close(fig)

    m = result.metrics
    w, wo = m["localisation_per_lap_with_odometry"], m["localisation_per_lap_without_odometry"]
    if w:
        fig, ax = plt.subplots(figsize=(6, 4))
        laps = np.arange(1, len(w) + 1)
        ax.plot(laps, np.array(w) * 100, "o-", label="with odometry")
        ax.plot(laps, np.array(wo) * 100, "s-", label="lasers only")
        ax.axhline(97.5, color="C0", ls=":", lw=1, label="paper 97.5% / 86% (robot)")
        ax.axhline(86.0, color="C1", ls=":", lw=1)
        ax.set_ylim(0, 105)
        ax.set_xlabel("localisation lap")
        ax.set_ylabel("success rate (%)")
        ax.set_xticks(laps)
        ax.legend()
        fig.savefig(out / "localisation.png", dpi=120, bbox_inches="tight")
        plt.close(fig)
