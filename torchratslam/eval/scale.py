"""How a run's per-frame cost grows with its map: the scale report.

A long run is cut into ``parts`` equal spans of frames (tenths by default). For each
span the report gives the mean milliseconds per frame of every module, the map's size
at the span's end (templates, experiences, links), and the ratio of the last span's
cost per frame to the first's: 1 means a flat cost, 10 a cost that grew tenfold as the
map grew. The same function reads OpenRatSLAM's per-frame trace (``frames.csv`` of the
reference driver), so both systems are reported alike.

Example:
    >>> rec = ScaleRecorder()                                  # doctest: +SKIP
    >>> result = slam.run(frames, callback=rec.on_step)        # doctest: +SKIP
    >>> report = rec.report(slam.timings)                      # doctest: +SKIP
    >>> print(format_scale_table(report))                      # doctest: +SKIP
"""

from __future__ import annotations

import csv
import itertools
import logging
import resource
import sys
from array import array
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from torchratslam.errors import InputError

__all__ = [
    "ScaleRecorder",
    "format_scale_table",
    "peak_memory_mb",
    "read_openratslam_trace",
    "scale_report",
]

log = logging.getLogger(__name__)


def peak_memory_mb() -> float:
    """Peak resident memory of this process so far, in MiB.

    On Linux ``VmHWM`` from ``/proc/self/status``: the high-water mark of this program's
    own memory (``getrusage``'s ``ru_maxrss`` survives ``exec``, so a process started
    by a larger one would report its parent's peak). Elsewhere ``ru_maxrss``.
    """
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0  # kB
    except OSError:
        pass
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1024.0 * 1024.0) if sys.platform == "darwin" else peak / 1024.0


def scale_report(
    per_frame_ms: Mapping[str, np.ndarray],
    counts: Mapping[str, np.ndarray],
    *,
    parts: int = 10,
    peak_mb: float | None = None,
) -> dict[str, Any]:
    """Cut a run into ``parts`` spans and summarise each span's cost and map size.

    Args:
        per_frame_ms: milliseconds per frame for each module (``"total"`` is added as
            their frame-by-frame sum when absent).
        counts: map size after each frame, e.g. ``templates``, ``experiences``,
            ``links`` (each ``(F,)``).
        parts: number of spans (10: tenths).
        peak_mb: peak memory to record (MiB), if measured.

    Shape:
        every array ``(F,)``, F >= ``parts`` frames.

    Returns:
        ``{"frames", "parts": [{"first", "last", "ms": {module: mean}, <count>: value at the
        span's end}], "last_over_first": {module: ratio}, "peak_memory_mb"}``.

    Raises:
        InputError: arrays of different lengths or fewer frames than parts.
    """
    ms = {k: np.asarray(v, np.float64) for k, v in per_frame_ms.items()}
    cn = {k: np.asarray(v) for k, v in counts.items()}
    lengths = {len(v) for v in (*ms.values(), *cn.values())}
    if len(lengths) != 1:
        raise InputError(f"scale report: per-frame arrays differ in length ({sorted(lengths)})")
    n = lengths.pop()
    if parts < 1 or n < parts:
        raise InputError(f"scale report: {n} frames cannot be cut into {parts} parts")
    if "total" not in ms:
        ms["total"] = np.sum(list(ms.values()), axis=0)
    edges = np.linspace(0, n, parts + 1).round().astype(np.int64)
    rows = []
    for a, b in itertools.pairwise(edges):
        row: dict[str, Any] = {"first": int(a), "last": int(b) - 1}
        row["ms"] = {k: float(v[a:b].mean()) for k, v in ms.items()}
        row.update({k: int(v[b - 1]) for k, v in cn.items()})
        rows.append(row)
    first, last = rows[0]["ms"], rows[-1]["ms"]
    ratio = {k: (last[k] / first[k] if first[k] > 0 else float("nan")) for k in first}
    return {
        "frames": int(n),
        "parts": rows,
        "last_over_first": ratio,
        "peak_memory_mb": None if peak_mb is None else float(peak_mb),
    }


def format_scale_table(report: Mapping[str, Any], *, title: str = "") -> str:
    """A Markdown table of a :func:`scale_report`: one row per span."""
    rows = report["parts"]
    modules = list(rows[0]["ms"])
    count_keys = [k for k in rows[0] if k not in ("first", "last", "ms")]
    head = ["frames", *[f"{m} ms" for m in modules], *count_keys]
    lines = [f"**{title}**", ""] if title else []
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [f"{r['first']}-{r['last']}"]
        cells += [f"{r['ms'][m]:.3f}" for m in modules]
        cells += [str(r[k]) for k in count_keys]
        lines.append("| " + " | ".join(cells) + " |")
    ratio = report["last_over_first"]
    lines.append("")
    lines.append(
        "last tenth / first tenth, per frame: "
        + ", ".join(f"{m} {ratio[m]:.2f}x" for m in modules)
        + (
            f"; peak memory {report['peak_memory_mb']:.0f} MiB"
            if report.get("peak_memory_mb") is not None
            else ""
        )
    )
    return "\n".join(lines)


@dataclass
class ScaleRecorder:
    """Collects the map size after every frame of a run (pass :meth:`on_step` as the
    run's ``callback``), 8 bytes a count; :meth:`report` joins them with the run's
    module timings.

    Attributes:
        links_of: a function returning the current number of links (optional; the
            step results carry templates and experiences but not links).
    """

    links_of: Any = None
    templates: array[int] = field(default_factory=lambda: array("q"))
    experiences: array[int] = field(default_factory=lambda: array("q"))
    links: array[int] = field(default_factory=lambda: array("q"))

    def on_step(self, step: Any) -> None:
        """Record one :class:`~torchratslam.pipeline.StepResult`."""
        self.templates.append(int(step.templates))
        self.experiences.append(int(step.experiences))
        if self.links_of is not None:
            self.links.append(int(self.links_of()))

    def report(self, timings: Any, *, parts: int = 10) -> dict[str, Any]:
        """The :func:`scale_report` of the recorded frames and ``timings`` (a
        :class:`~torchratslam.timing.TimeLogger`)."""
        n = len(self.templates)
        ms = {m: timings.per_frame_ms(m)[-n:] for m in timings.modules}
        ms = {m: v for m, v in ms.items() if len(v) == n}
        counts = {"templates": np.array(self.templates), "experiences": np.array(self.experiences)}
        if self.links:
            counts["links"] = np.array(self.links)
        return scale_report(ms, counts, parts=parts, peak_mb=peak_memory_mb())


def read_openratslam_trace(path: str | Path, *, parts: int = 10) -> dict[str, Any]:
    """The :func:`scale_report` of an OpenRatSLAM driver trace (``frames.csv``).

    The driver writes, per frame, ``lv_ms, pc_ms, em_ms, total_ms`` and the template
    and experience ids; the map's size after frame k is one more than the largest id
    seen so far (links are not in the trace).

    Raises:
        InputError: the file is missing or lacks those columns.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no OpenRatSLAM trace (frames.csv) there")
    with p.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    need = ("lv_ms", "pc_ms", "em_ms", "total_ms", "vt_id", "current_exp_id")
    if not rows or any(k not in rows[0] for k in need):
        raise InputError(f"{p}: expected the columns {', '.join(need)}")
    col = {k: np.array([float(r[k]) for r in rows]) for k in need}
    ms = {
        "local_view": col["lv_ms"],
        "pose_cells": col["pc_ms"],
        "experience_map": col["em_ms"],
        "total": col["total_ms"],
    }
    counts = {
        "templates": np.maximum.accumulate(col["vt_id"]).astype(np.int64) + 1,
        "experiences": np.maximum.accumulate(col["current_exp_id"]).astype(np.int64) + 1,
    }
    return scale_report(ms, counts, parts=parts)
