"""Run one experiment, or all of them, into a folder.

``run_one`` writes ``OUT/report.json``, ``OUT/report.md`` and the figures; ``run_all``
runs every experiment into ``OUT/<paper>/<name>/`` and writes ``OUT/index.md`` and
``OUT/index.json`` (each experiment's rows, or the one-line error it stopped with).
A folder that already holds a report is never overwritten unless asked; one that holds
the checkpoints of a stopped run (``OUT/checkpoints``) is resumed, its finished parts
kept (``--overwrite`` redoes them).
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path

from ratslam_graph.atomic import atomic_write_text
from torchratslam.errors import InputError, RatSLAMError
from torchratslam.experiments.reproduce.catalogue import all_experiments, get_experiment
from torchratslam.experiments.reproduce.report import (
    CHECKPOINTS,
    Experiment,
    ExperimentContext,
    Report,
    write_report,
)

__all__ = ["Outcome", "run_all", "run_one"]

log = logging.getLogger(__name__)


def _prepare(out: Path, *, overwrite: bool) -> None:
    from ratslam_graph.out_checks import check_out_dir

    # new, empty, a report of its own or the checkpoints of a stopped run (resumed):
    # a folder holding anything else is refused
    check_out_dir(out, what="report", marks=("report.json", "index.json", CHECKPOINTS))
    if (out / "report.json").exists() and not overwrite:
        raise InputError(f"{out} already holds a report; choose another --out or pass --overwrite")
    if out.exists() and not out.is_dir():
        raise InputError(f"{out} is a file, not a folder")
    out.mkdir(parents=True, exist_ok=True)


def run_one(
    name: str | Experiment,
    out: Path,
    *,
    quick: bool = False,
    seed: int = 0,
    overwrite: bool = False,
) -> Report:
    """Run one experiment into ``out``.

    Raises:
        InputError: unknown experiment, or ``out`` holds a report and not ``overwrite``.
    """
    exp = get_experiment(name) if isinstance(name, str) else name
    out = Path(out)
    _prepare(out, overwrite=overwrite)
    log.info("%s: %s%s", exp.id, exp.title, " (quick)" if quick else "")
    report = exp.run(ExperimentContext(out=out, quick=quick, seed=seed, resume=not overwrite))
    write_report(report, out)
    return report


@dataclass(frozen=True)
class Outcome:
    """One experiment of ``run_all``: its report, or the error it stopped with."""

    experiment: str
    folder: str
    seconds: float
    report: Report | None = None
    error: str | None = None


def _index_markdown(outcomes: list[Outcome], quick: bool) -> str:
    lines = [
        "# Reproducing the papers",
        "",
        f"{len(outcomes)} experiments" + (" (quick versions)" if quick else "") + ".",
        "",
        "| experiment | title | result |",
        "|---|---|---|",
    ]
    for o in outcomes:
        if o.report is None:
            result = f"failed: {o.error}"
            title = ""
        else:
            result = f"[report]({o.folder}/report.md), {o.seconds:.0f} s"
            title = o.report.title
        lines.append(f"| {o.experiment} | {title} | {result} |")
    return "\n".join(lines) + "\n"


def run_all(
    out: Path, *, quick: bool = False, seed: int = 0, overwrite: bool = False
) -> list[Outcome]:
    """Run every experiment into ``out/<id>/``; write ``out/index.md`` and ``index.json``.

    An experiment that fails with a :class:`RatSLAMError` is recorded and the others go
    on; the caller decides the exit code from the outcomes.

    Raises:
        InputError: ``out`` holds a finished ``run_all`` (its index) and not ``overwrite``.
    """
    out = Path(out)
    if (out / "index.json").exists() and not overwrite:
        raise InputError(
            f"{out} already holds the papers' reports (index.json); choose another --out or "
            "pass --overwrite"
        )
    outcomes: list[Outcome] = []
    for exp in all_experiments().values():
        t0 = time.perf_counter()
        try:
            report = run_one(exp, out / exp.id, quick=quick, seed=seed, overwrite=overwrite)
            outcomes.append(Outcome(exp.id, exp.id, time.perf_counter() - t0, report=report))
        except RatSLAMError as exc:
            log.error("%s failed: %s", exp.id, exc)
            outcomes.append(Outcome(exp.id, exp.id, time.perf_counter() - t0, error=str(exc)))
    index = [
        {
            "experiment": o.experiment,
            "folder": o.folder,
            "seconds": round(o.seconds, 3),
            "error": o.error,
            "rows": None if o.report is None else o.report.to_json()["rows"],
        }
        for o in outcomes
    ]
    atomic_write_text(out / "index.json", json.dumps(index, indent=2) + "\n")
    atomic_write_text(out / "index.md", _index_markdown(outcomes, quick))
    return outcomes
