"""``graph/`` (installed as ``ratslam_graph``) is the torch-free bottom layer.

It may import itself (``ratslam_graph...``) but never torch nor any other part
of torchratslam.
"""

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _forbidden_imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return {
        n
        for n in names
        if n.split(".")[0] == "torch"
        or (n.split(".")[0] == "torchratslam" and not n.startswith("ratslam_graph"))
    }


def test_graph_sources_never_import_torch_or_the_rest_of_torchratslam():
    files = sorted((ROOT / "graph").rglob("*.py"))
    assert files, "graph package has no sources"
    offenders = {str(f.relative_to(ROOT)): sorted(_forbidden_imports(f)) for f in files}
    offenders = {k: v for k, v in offenders.items() if v}
    assert not offenders, f"graph must stay torch-free: {offenders}"


def test_importing_every_graph_module_loads_no_torch():
    modules = [
        ".".join(("torchratslam", *f.relative_to(ROOT).with_suffix("").parts)).removesuffix(
            ".__init__"
        )
        for f in sorted((ROOT / "graph").rglob("*.py"))
    ]
    code = (
        "import importlib, sys\n"
        f"for m in {modules!r}: importlib.import_module(m)\n"
        "print('torch' in sys.modules)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "False", f"importing graph pulled in torch: {out.stdout}"


def test_the_checker_detects_a_forbidden_import(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("import os\nfrom torchratslam.config import load_config\n")
    assert _forbidden_imports(bad) == {"torchratslam.config"}
    ok = tmp_path / "ok.py"
    ok.write_text("from ratslam_graph.errors import InputError\n")
    assert _forbidden_imports(ok) == set()
