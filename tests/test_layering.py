"""Experiment runners and the CLI sit on top of the library, never inside it.

The library (every module of ``torchratslam`` outside ``cli/``, ``experiments/`` and
``__main__``) never imports ``torchratslam.cli`` or ``torchratslam.experiments``; the
experiments never import the CLI; the notebooks never import ``benchmarks``.
"""

from __future__ import annotations

import ast
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PKG = ROOT / "torchratslam"


def _imports(source: str) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def _hits(files: list[Path], prefixes: tuple[str, ...], read=Path.read_text) -> dict:
    out = {}
    for f in files:
        bad = sorted(n for n in _imports(read(f)) if n.startswith(prefixes))
        if bad:
            out[str(f.relative_to(ROOT))] = bad
    return out


def test_the_library_never_imports_the_cli_or_the_experiments():
    top = ("torchratslam.cli", "torchratslam.experiments")
    library = [
        f
        for f in PKG.rglob("*.py")
        if f.relative_to(PKG).parts[0] not in ("cli", "experiments", "__main__.py")
    ]
    assert len(library) > 20
    assert not _hits(library, top)
    assert not _hits(sorted((PKG / "experiments").rglob("*.py")), ("torchratslam.cli",))


def _notebook_code(path: Path) -> str:
    cells = json.loads(path.read_text())["cells"]
    return "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "code")


def test_notebooks_never_import_the_benchmarks():
    nbs = sorted((ROOT / "notebooks").glob("*.ipynb"))
    assert nbs
    assert not _hits(nbs, ("benchmarks",), read=_notebook_code)
    assert not _hits(sorted((ROOT / "notebooks").glob("*.py")), ("benchmarks",))


def test_the_checker_sees_an_import(tmp_path):
    f = tmp_path / "m.py"
    f.write_text("from torchratslam import cli\nimport benchmarks.bench_sim\n")
    assert _imports(f.read_text()) >= {"torchratslam.cli", "benchmarks.bench_sim"}
