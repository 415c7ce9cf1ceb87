"""Write ``docs/reproducing.md`` ("Reproducing the papers") from ``reproduce all``.

Reads the folder ``torchratslam reproduce all --out DIR`` wrote (``DIR/index.json`` and
every ``DIR/<id>/report.json``), or runs it first, and writes one page: per paper, per
experiment, the paper's numbers beside ours, what differs and why, and the figures
(copied into ``docs/img/reproduce/``).

Usage (from the repository root)::

    python -m torchratslam.experiments.reproduce.docs_page --run --quick --out out/papers
    python -m torchratslam.experiments.reproduce.docs_page --from out/papers
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path
from typing import Any

from ratslam_graph.atomic import atomic_write_text
from torchratslam.errors import InputError
from torchratslam.experiments.reproduce.report import PAPERS, format_cell

__all__ = ["PAGE_FIGURES", "copy_figure", "main", "write_page"]

REGENERATE = "python -m torchratslam.experiments.reproduce.docs_page --run --quick --out out/papers"
PAGE_FIGURES = 3
"""Figures shown per experiment: the report's first ones (each experiment lists its
main figures first); the others are named, to keep the committed images small."""


def copy_figure(src: Path, dest: Path) -> Path:
    """Copy a figure for the page: a PNG is stored with a 256-colour palette (plots have
    few colours; about a third of the bytes), anything else, or a PNG that cannot be
    read, byte for byte."""
    if src.suffix.lower() == ".png":
        try:
            from PIL import Image

            with Image.open(src) as im:
                im.convert("RGB").quantize(colors=256).save(dest, format="PNG", optimize=True)
            return dest
        except (OSError, ValueError):
            pass  # not an image PIL reads: copied as it is
    shutil.copyfile(src, dest)
    return dest


def _experiment(rep: dict[str, Any], folder: Path, img: Path, seconds: float) -> list[str]:
    """One experiment's section; copies its figures into ``img``."""
    exp = rep["experiment"]
    lines = [f"### `{exp}`: {rep['title']}", ""]
    size = "quick version" if rep.get("quick") else "full version"
    lines += [f"({size}, seed {rep.get('seed', 0)}, {seconds:.0f} s)", ""]
    lines += ["| | paper | ours |", "|---|---|---|"]
    for r in rep["rows"]:
        unit = r.get("unit", "")
        paper, ours = format_cell(r["paper"], unit), format_cell(r["ours"], unit)
        lines.append(f"| {r['name']} | {paper} | {ours} |")
    if rep.get("differences"):
        lines += ["", "What differs and why:", ""]
        lines += [f"- {d}" for d in rep["differences"]]
    figures = [f for f in rep.get("figures", []) if (folder / f).is_file()]
    for fig in figures[:PAGE_FIGURES]:
        dest = img / f"{exp.replace('/', '_')}_{Path(fig).name}"
        copy_figure(folder / fig, dest)
        lines += ["", f"![{exp}: {Path(fig).stem}](img/reproduce/{dest.name})"]
    if figures[PAGE_FIGURES:]:
        names = ", ".join(f"`{Path(f).name}`" for f in figures[PAGE_FIGURES:])
        lines += ["", f"The run also draws {names} (not copied here)."]
    return [*lines, ""]


def write_page(results: Path, page: Path, img: Path) -> Path:
    """Write ``page`` from the ``reproduce all`` folder ``results``; figures go to
    ``img`` (emptied first).

    Raises:
        InputError: ``results`` holds no ``index.json``.
    """
    index_file = results / "index.json"
    if not index_file.is_file():
        raise InputError(f"{results} holds no index.json: run 'torchratslam reproduce all' first")
    index = json.loads(index_file.read_text())
    if img.exists():
        shutil.rmtree(img)
    img.mkdir(parents=True)
    quick: list[str] = []
    done = 0
    total = 0.0
    by_paper: dict[str, list[str]] = {}
    for entry in index:
        exp = entry["experiment"]
        paper = exp.split("/", 1)[0]
        folder = results / entry["folder"]
        if entry.get("error"):
            section = [f"### `{exp}`", "", f"Failed: {entry['error']}", ""]
        else:
            rep = json.loads((folder / "report.json").read_text())
            done += 1
            if rep.get("quick"):
                quick.append(exp)
            seconds = float(entry.get("seconds", 0.0))
            total += seconds
            section = _experiment(rep, folder, img, seconds)
        by_paper.setdefault(paper, []).extend(section)
    lines = [
        "# Reproducing the papers",
        "",
        "Every experiment of the four papers, run by `torchratslam reproduce`, with the "
        "paper's numbers beside ours. Our data are the simulator's tours, not the papers' "
        "recordings, so most numbers compare in kind and units, not in value; each "
        "experiment says what differs and why.",
        "",
    ]
    if quick and len(quick) == done:
        lines += [
            "!!! note",
            "    This page shows the quick versions (smaller data, minutes in all); "
            "`torchratslam reproduce all --out DIR` without `--quick` runs the papers' "
            "sizes.",
            "",
        ]
    elif quick:
        names = ", ".join(f"`{q}`" for q in quick)
        lines += [
            "!!! note",
            f"    The full versions (the papers' sizes) except {names}: those show their "
            "quick versions (smaller data); `torchratslam reproduce ID --out DIR` without "
            "`--quick` runs their full size.",
            "",
        ]
    command = REGENERATE if quick else REGENERATE.replace(" --quick", "")
    lines += [
        f"This page is generated: `{command}` (or `--from DIR` to read a finished "
        f"`reproduce all --out DIR`); its runs took {total / 60:.0f} min.",
        "",
    ]
    for paper in [*PAPERS, *sorted(set(by_paper) - set(PAPERS))]:
        if paper in by_paper:
            lines += [f"## {PAPERS.get(paper, paper)}", "", *by_paper[paper]]
    return atomic_write_text(page, "\n".join(lines).rstrip() + "\n")


def main(argv: list[str] | None = None) -> int:
    """Command line: ``--from DIR`` reads a finished run; ``--run`` runs it first."""
    ap = argparse.ArgumentParser(prog="python -m torchratslam.experiments.reproduce.docs_page")
    ap.add_argument("--from", dest="results", type=Path, help="a 'reproduce all --out' folder")
    ap.add_argument("--run", action="store_true", help="run 'reproduce all' into --out first")
    ap.add_argument("--out", type=Path, default=Path("out/papers"), help="where --run writes")
    ap.add_argument("--quick", action="store_true", help="the quick versions (with --run)")
    ap.add_argument("--docs", type=Path, default=Path("docs"), help="the docs folder")
    a = ap.parse_args(argv)
    results = a.results
    if a.run:
        from torchratslam.experiments.reproduce.runner import run_all

        run_all(a.out, quick=a.quick, overwrite=True)
        results = a.out
    if results is None:
        ap.error("give --from DIR or --run")
    page = write_page(results, a.docs / "reproducing.md", a.docs / "img" / "reproduce")
    print(f"wrote {page}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
