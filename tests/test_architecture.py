"""The layering, checked once: the import contracts of ``[tool.importlinter]``.

``make lint`` runs lint-imports on the tree as it is (``graph/`` and the checkout on
``PYTHONPATH``); these tests check that the contracts cover every part of both
distributions, that the tree keeps them, and that a forbidden import breaks them.
"""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    from pip._vendor import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent
CONFIG = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
CONTRACTS = {c["id"]: c for c in CONFIG["contracts"]}
LINT_IMPORTS = Path(sys.executable).parent / "lint-imports"
APPS = {"torchratslam.cli", "torchratslam.experiments", "torchratslam.__main__"}


def _parts() -> set[str]:
    """Every top-level part of the package: torchratslam.<name>."""
    pkg = ROOT / "torchratslam"
    names = {p.stem for p in pkg.glob("*.py")} - {"__init__"}
    names |= {p.parent.name for p in pkg.glob("*/__init__.py")}
    return {f"torchratslam.{n}" for n in names}


def _lint_imports(root: Path) -> subprocess.CompletedProcess:
    env = {"PATH": "/usr/bin:/bin", "PYTHONPATH": f"{root / 'graph'}:{root}"}
    return subprocess.run(
        [str(LINT_IMPORTS), "--config", str(ROOT / "pyproject.toml"), "--no-cache"],
        cwd=root,
        env=env,
        capture_output=True,
        text=True,
    )


def _copy_tree(dest: Path) -> Path:
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info")
    shutil.copytree(ROOT / "torchratslam", dest / "torchratslam", ignore=ignore)
    shutil.copytree(
        ROOT / "graph" / "ratslam_graph", dest / "graph" / "ratslam_graph", ignore=ignore
    )
    return dest


def test_the_contracts_name_every_part_of_the_package():
    parts = _parts()
    assert {"torchratslam.maps", "torchratslam.pipeline", "torchratslam.pose_cells"} <= parts
    assert set(CONFIG["root_packages"]) == {"torchratslam", "ratslam_graph"}
    assert set(CONTRACTS["graph"]["source_modules"]) == {"ratslam_graph"}
    assert set(CONTRACTS["graph"]["forbidden_modules"]) == {"torch", "torchratslam"}
    library = CONTRACTS["library"]
    assert set(library["source_modules"]) == parts - APPS
    assert set(library["forbidden_modules"]) == APPS - {"torchratslam.__main__"}
    assert CONTRACTS["experiments"]["forbidden_modules"] == ["torchratslam.cli"]
    shared = set(CONTRACTS["shared"]["source_modules"])
    assert set(CONTRACTS["shared"]["forbidden_modules"]) == parts - shared - {
        "torchratslam.__main__"
    }
    stages = CONTRACTS["stages"]["layers"]
    assert stages.index("torchratslam.readers") < stages.index("torchratslam.local_view")
    assert stages.index("torchratslam.pose_cells") < stages.index("ratslam_graph.experience_map")
    assert stages[-1] == "ratslam_graph.backends"


def test_the_tree_keeps_every_contract():
    out = _lint_imports(ROOT)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-2000:]
    assert f"{len(CONTRACTS)} kept, 0 broken" in out.stdout


@pytest.mark.parametrize(
    ("folder", "source", "broken"),
    [
        ("graph/ratslam_graph", "import torch\n", "graph"),
        ("graph/ratslam_graph", "from torchratslam.config import load_config\n", "graph"),
        ("torchratslam/pose_cells", "from torchratslam import local_view\n", "stages"),
        ("graph/ratslam_graph/backends", "from ratslam_graph import experience_map\n", "stages"),
        ("torchratslam/readers", "from torchratslam import pipeline\n", "stages"),
        ("torchratslam/maps", "from torchratslam.cli import run\n", "library"),
        ("torchratslam/sim", "from torchratslam.experiments import demo\n", "library"),
        ("torchratslam/experiments", "from torchratslam.cli import run\n", "experiments"),
        ("torchratslam", "from torchratslam import pipeline\n", "shared"),
    ],
)
def test_a_forbidden_import_breaks_its_contract(tmp_path, folder, source, broken):
    root = _copy_tree(tmp_path)
    if broken == "shared":  # a shared bottom module importing a stage
        target = root / folder / "registry.py"
        target.write_text(target.read_text() + "\n" + source)
    else:
        (root / folder / "_forbidden.py").write_text(source)
    out = _lint_imports(root)
    assert out.returncode != 0
    assert f"{CONTRACTS[broken]['name']} BROKEN" in " ".join(out.stdout.split())
