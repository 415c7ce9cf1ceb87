"""The cost-per-frame figure of the scale report: cost against map size."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from torchratslam.viz.plots import save_figure

__all__ = ["plot_scale"]


def plot_scale(
    path: str | Path, reports: Mapping[str, Mapping[str, Any]], *, title: str = ""
) -> Path:
    """Mean milliseconds per frame of each tenth of a run against the map's size then.

    One line per system (e.g. ``{"torchratslam": report, "OpenRatSLAM C++": report}``,
    each a :func:`~torchratslam.eval.scale.scale_report`); the left panel plots the total
    cost against the number of templates, the right one each module's cost of every
    system against the frame index, so a growing module shows at a glance.

    Returns:
        The written path.
    """
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 6))
    styles = ["-", "--", ":", "-."]
    for i, (name, rep) in enumerate(reports.items()):
        parts = rep["parts"]
        size = [p["templates"] for p in parts]
        total = [p["ms"]["total"] for p in parts]
        ratio = rep["last_over_first"]["total"]
        ax.plot(size, total, "o" + styles[i % 4], label=f"{name} (last/first tenth {ratio:.2f}x)")
        mid = [(p["first"] + p["last"]) / 2 for p in parts]
        for module in ("local_view", "pose_cells", "experience_map"):
            if module in parts[0]["ms"]:
                bx.plot(
                    mid,
                    [p["ms"][module] for p in parts],
                    styles[i % 4],
                    marker=".",
                    label=f"{name}: {module.replace('_', ' ')}",
                )
    ax.set_xlabel("templates in the map at the end of each tenth")
    ax.set_ylabel("mean cost per frame (ms)")
    ax.set_title("cost per frame against map size")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14))
    bx.set_xlabel("frame (middle of each tenth)")
    bx.set_ylabel("mean cost per frame (ms)")
    bx.set_title("per module")
    bx.set_ylim(bottom=0)
    bx.grid(alpha=0.3)
    bx.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14))
    if title:
        fig.suptitle(title)
    fig.subplots_adjust(bottom=0.42, wspace=0.25, left=0.06, right=0.98)
    out = save_figure(fig, path)
    plt.close(fig)
    return out
