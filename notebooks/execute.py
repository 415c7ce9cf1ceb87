"""Execute notebooks in place and strip their volatile metadata, so they are committed
with their outputs and read on a repository page without running them.

Run: ``python notebooks/execute.py [NOTEBOOK ...]`` (default: every ``NN_*.ipynb``), or
``make notebooks``. Kept: outputs and execution counts. Dropped: execution timestamps,
the kernel's version details and widget state.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import nbformat
from nbclient import NotebookClient

HERE = Path(__file__).resolve().parent


def strip(nb: nbformat.NotebookNode) -> nbformat.NotebookNode:
    """Remove what changes from one execution to the next but the outputs."""
    nb.metadata = nbformat.NotebookNode(
        kernelspec=nb.metadata.get(
            "kernelspec", {"display_name": "Python 3", "language": "python", "name": "python3"}
        ),
        language_info={"name": "python"},
    )
    for cell in nb.cells:
        cell.metadata.pop("execution", None)
        cell.metadata.pop("widgets", None)
    return nb


def execute(path: Path) -> None:
    nb = nbformat.read(path, as_version=4)
    with tempfile.TemporaryDirectory() as out:
        os.environ["TORCHRATSLAM_NOTEBOOK_OUT"] = out
        os.environ["MPLBACKEND"] = "module://matplotlib_inline.backend_inline"
        NotebookClient(
            nb,
            timeout=600,
            kernel_name="python3",
            record_timing=False,
            resources={"metadata": {"path": str(path.parent)}},
        ).execute()
    nbformat.write(strip(nb), path)
    print(f"executed {path.name}")


if __name__ == "__main__":
    paths = [Path(p) for p in sys.argv[1:]] or sorted(HERE.glob("[0-9][0-9]_*.ipynb"))
    for p in paths:
        execute(p)
