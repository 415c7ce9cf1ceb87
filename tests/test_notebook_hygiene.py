"""The notebooks read on a repository page without running them: numbered 01, 02, ...
with no gap, committed with their outputs and without volatile metadata, importing
nothing from outside the package (no sys.path tricks, no benchmarks/ or tests/)."""

import re
from pathlib import Path

import nbformat
import pytest

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def test_numbered_in_order_without_gaps():
    numbers = []
    for p in NOTEBOOKS:
        m = re.fullmatch(r"(\d\d)_[a-z0-9_]+", p.stem)
        assert m, f"{p.name}: name it NN_words.ipynb"
        numbers.append(int(m.group(1)))
    assert numbers == list(range(1, len(numbers) + 1)), numbers


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_committed_with_outputs_and_no_volatile_metadata(path):
    nb = nbformat.read(path, as_version=4)
    assert set(nb.metadata) <= {"kernelspec", "language_info"}, (
        f"{path.name}: volatile notebook metadata; run python notebooks/execute.py {path.name}"
    )
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code and all(c.execution_count is not None for c in code), (
        f"{path.name}: not executed; run python notebooks/execute.py {path.name}"
    )
    counts = [c.execution_count for c in code]
    assert counts == list(range(1, len(code) + 1)), f"{path.name}: run top to bottom once"
    for c in code:
        assert "execution" not in c.metadata, f"{path.name}: execution timestamps"
        assert not any(o.get("output_type") == "error" for o in c.outputs), path.name
    assert any(c.outputs for c in code)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_imports_only_the_package_and_its_dependencies(path):
    nb = nbformat.read(path, as_version=4)
    src = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
    assert "sys.path" not in src, f"{path.name}: changes sys.path"
    for m in re.finditer(r"^\s*(?:from|import)\s+([\w.]+)", src, re.M):
        top = m.group(1).split(".")[0]
        assert top not in ("benchmarks", "tests", "notebooks", "graph"), (path.name, m.group(0))
