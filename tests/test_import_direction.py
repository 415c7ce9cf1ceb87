"""``graph`` is the torch-free bottom layer: it must never import torchratslam or torch."""

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FORBIDDEN = ("torchratslam", "torch")


def _imported_roots(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    roots: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            roots.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            roots.add(node.module.split(".")[0])
    return roots


def test_graph_sources_never_import_torch_or_torchratslam():
    files = sorted((ROOT / "graph").rglob("*.py"))
    assert files, "graph package has no sources"
    offenders = {
        str(f.relative_to(ROOT)): sorted(_imported_roots(f) & set(FORBIDDEN)) for f in files
    }
    offenders = {k: v for k, v in offenders.items() if v}
    assert not offenders, f"graph must stay torch-free: {offenders}"


def test_importing_every_graph_module_loads_no_torch():
    modules = [
        ".".join(f.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        for f in sorted((ROOT / "graph").rglob("*.py"))
    ]
    code = (
        "import importlib, sys\n"
        f"for m in {modules!r}: importlib.import_module(m)\n"
        "bad = [m for m in ('torch', 'torchratslam') if m in sys.modules]\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "", f"importing graph pulled in: {out.stdout.strip()}"


def test_the_checker_detects_a_forbidden_import(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("import os\nfrom torchratslam.config import load_config\n")
    assert "torchratslam" in _imported_roots(bad)
