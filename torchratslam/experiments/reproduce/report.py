"""What one reproduced experiment reports: the paper's numbers beside ours.

``report.json`` holds ``"experiment"``, ``"paper"``, ``"title"``, ``"rows"`` (each
``{"name", "paper", "ours", "unit"}``; ``"paper"`` is null where the paper gives no
number), ``"figures"`` (file names beside the report), ``"differences"`` (what differs
from the paper's set-up and why), ``"quick"``, ``"seed"`` and ``"details"`` (the
experiment's own data). ``report.md`` shows the same as a table a person reads.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from ratslam_graph.atomic import atomic_write_text
from torchratslam.errors import InputError

__all__ = [
    "CHECKPOINTS",
    "PAPERS",
    "Experiment",
    "ExperimentContext",
    "Report",
    "Row",
    "format_cell",
    "write_report",
]

CHECKPOINTS = "checkpoints"
"""The folder of OUT where a long experiment saves its finished parts (resumable)."""

PAPERS: Mapping[str, str] = {
    "multisession": "Multi-session mapping with RatSLAM (the multisession paper)",
    "edge": "Goal-directed navigation on RatSLAM's experience map (the experience-map paper)",
    "xratslam": "xRatSLAM: an extensible RatSLAM framework",
    "mbaram": "MBARAM",
}
"""The papers by the first part of an experiment id."""


@dataclass(frozen=True)
class Row:
    """One number: the paper's beside ours.

    Attributes:
        name: what is measured ("experiences after the merge").
        paper: the paper's value, or None where the paper gives none.
        ours: our value (a number, a bool or a short text).
        unit: its unit ("", "m", "%", "ms", ...).
    """

    name: str
    paper: float | int | str | None
    ours: float | int | str | bool | None
    unit: str = ""


@dataclass(frozen=True)
class ExperimentContext:
    """How an experiment is run.

    Attributes:
        out: the folder for the report and the figures (exists; empty, or holding
            the checkpoints of a stopped run of the same experiment).
        quick: a small version (for the tests); else the paper's size.
        seed: the random seed of simulated worlds and noise.
        resume: an experiment that checkpoints its long parts (``OUT/checkpoints``)
            reuses those a stopped run of the same settings finished; False
            (``--overwrite``) redoes them.
    """

    out: Path
    quick: bool = False
    seed: int = 0
    resume: bool = True


@dataclass(frozen=True)
class Report:
    """The result of one experiment (see the module's docstring for the JSON)."""

    experiment: str
    paper: str
    title: str
    rows: tuple[Row, ...]
    figures: tuple[str, ...] = ()
    differences: tuple[str, ...] = ()
    details: Mapping[str, Any] = field(default_factory=dict)
    quick: bool = False
    seed: int = 0

    def to_json(self) -> dict[str, Any]:
        """The report as ``report.json`` holds it."""
        return {
            "experiment": self.experiment,
            "paper": self.paper,
            "title": self.title,
            "rows": [asdict(r) for r in self.rows],
            "figures": list(self.figures),
            "differences": list(self.differences),
            "quick": self.quick,
            "seed": self.seed,
            "details": _plain(self.details),
        }


@dataclass(frozen=True)
class Experiment:
    """One experiment of a paper.

    Attributes:
        id: ``"<paper>/<name>"``, e.g. ``"multisession/virtual-tour"``.
        title: one line for ``reproduce --list``.
        run: runs it; returns the report (figures already written into ``ctx.out``).
    """

    id: str
    title: str
    run: Callable[[ExperimentContext], Report]

    def __post_init__(self) -> None:
        paper = self.id.split("/", 1)[0]
        if paper not in PAPERS or "/" not in self.id:
            raise InputError(
                f"experiment id {self.id!r} must be <paper>/<name>, paper in {list(PAPERS)}"
            )

    @property
    def paper(self) -> str:
        """The paper's key (the id's first part)."""
        return self.id.split("/", 1)[0]


def _plain(value: Any) -> Any:
    """``value`` as JSON can hold it (NaN and infinities as null, arrays as lists)."""
    if hasattr(value, "tolist"):
        value = value.tolist()
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, Sequence) and not isinstance(value, str):
        return [_plain(v) for v in value]
    return value


def format_cell(value: Any, unit: str) -> str:
    """A table cell: a number to four significant digits with its unit, yes/no, or a dash."""
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        text = f"{value:.4g}" if abs(value) < 1e4 else f"{value:.0f}"
    else:
        text = str(value)
    return f"{text} {unit}".strip() if unit and unit != "%" else text + (unit or "")


def report_markdown(report: Report) -> str:
    """``report.md``: the title, the rows as a table, what differs, the figures."""
    lines = [
        f"# {report.experiment}: {report.title}",
        "",
        f"Paper: {PAPERS.get(report.paper, report.paper)}."
        + (" Quick version (smaller than the paper's)." if report.quick else "")
        + f" Seed {report.seed}.",
        "",
        "| | paper | ours |",
        "|---|---|---|",
    ]
    lines += [
        f"| {r.name} | {format_cell(r.paper, r.unit)} | {format_cell(r.ours, r.unit)} |"
        for r in report.rows
    ]
    if report.differences:
        lines += ["", "What differs and why:", ""]
        lines += [f"- {d}" for d in report.differences]
    if report.figures:
        lines += [""]
        lines += [f"![{Path(f).stem}]({f})" for f in report.figures]
    return "\n".join(lines) + "\n"


def write_report(report: Report, out: Path) -> tuple[Path, Path]:
    """Write ``report.json`` and ``report.md`` into ``out`` (atomically each).

    Raises:
        InputError: a figure the report names is not in ``out``.
    """
    missing = [f for f in report.figures if not (out / f).is_file()]
    if missing:
        raise InputError(f"{report.experiment}: figures not written: {', '.join(missing)}")
    js, md = out / "report.json", out / "report.md"
    atomic_write_text(js, json.dumps(report.to_json(), indent=2) + "\n")
    atomic_write_text(md, report_markdown(report))
    return js, md
