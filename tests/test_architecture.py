"""The import contracts of ``[tool.importlinter]`` (run by ``make lint``) hold, cover
every part of the package, and catch a forbidden import.

lint-imports reads the package from a view of symlinks laid out as it installs
(``ratslam_graph`` -> ``graph/``, ``torchratslam/presets`` -> ``configs/``), the
same view ``make lint`` builds under ``build/lint``.
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
    """Every top-level part of the installed package: torchratslam.<name>."""
    names = {p.stem for p in (ROOT / "torchratslam").glob("*.py")} - {"__init__"}
    names |= {p.parent.name for p in (ROOT / "torchratslam").glob("*/__init__.py")}
    return {f"torchratslam.{n}" for n in names | {"graph", "presets"}}


def _view(dest: Path, *, copy: tuple[str, ...] = ()) -> Path:
    """The package as it installs, under ``dest``: symlinks, or copies for ``copy``."""
    pkg = dest / "torchratslam"
    pkg.mkdir(parents=True)
    entries = {p.name: p for p in (ROOT / "torchratslam").iterdir() if p.name != "__pycache__"}
    entries |= {"graph": ROOT / "graph", "presets": ROOT / "configs"}
    for name, src in entries.items():
        if name in copy:
            if src.is_dir():
                shutil.copytree(src, pkg / name, ignore=shutil.ignore_patterns("__pycache__"))
            else:
                shutil.copy(src, pkg / name)
        else:
            (pkg / name).symlink_to(src)
    return pkg


def _lint_imports(view: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(LINT_IMPORTS), "--config", str(ROOT / "pyproject.toml"), "--no-cache"],
        cwd=view,
        capture_output=True,
        text=True,
    )


def test_the_contracts_name_every_part_of_the_package():
    parts = _parts()
    assert {"ratslam_graph", "torchratslam.maps", "torchratslam.pipeline"} <= parts
    graph = CONTRACTS["graph"]
    assert set(graph["forbidden_modules"]) == parts - {"ratslam_graph"} | {"torch"}
    library = CONTRACTS["library"]
    assert set(library["source_modules"]) == parts - APPS
    assert set(library["forbidden_modules"]) == APPS - {"torchratslam.__main__"}
    shared = set(CONTRACTS["shared"]["source_modules"])
    assert shared == {f"torchratslam.{m}" for m in ("config", "errors", "messages", "protocols",
                                                    "registry", "timing")}  # fmt: skip
    stages = CONTRACTS["stages"]["layers"]
    assert stages.index("torchratslam.readers") < stages.index("torchratslam.local_view")
    assert stages.index("torchratslam.pose_cells") < stages.index(
        "ratslam_graph.experience_map"
    )
    assert stages[-1] == "ratslam_graph.backends"


def test_the_package_keeps_every_contract(tmp_path):
    out = _lint_imports(_view(tmp_path).parent)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-2000:]
    assert f"{len(CONTRACTS)} kept, 0 broken" in out.stdout


@pytest.mark.parametrize(
    ("package", "source", "broken"),
    [
        ("graph", "import torch\n", "graph"),
        ("graph", "from torchratslam.config import load_config\n", "graph"),
        ("pose_cells", "from torchratslam.local_view import view\n", "stages"),
        ("graph", "from torchratslam.pose_cells import network\n", "graph"),
        ("graph/backends", "from ratslam_graph import experience_map\n", "stages"),
        ("readers", "from torchratslam import pipeline\n", "stages"),
        ("maps", "from torchratslam.cli import run\n", "library"),
        ("sim", "from torchratslam.experiments import demo\n", "library"),
    ],
)
def test_a_forbidden_import_breaks_its_contract(tmp_path, package, source, broken):
    pkg = _view(tmp_path, copy=(package.split("/")[0],))
    (pkg / package / "_forbidden.py").write_text(source)
    out = _lint_imports(tmp_path)
    assert out.returncode != 0
    assert f"{CONTRACTS[broken]['name']} BROKEN" in " ".join(out.stdout.split())


def test_a_shared_module_importing_a_stage_breaks_its_contract(tmp_path):
    pkg = _view(tmp_path, copy=("registry.py",))
    with open(pkg / "registry.py", "a") as f:
        f.write("\nfrom torchratslam import pipeline\n")
    out = _lint_imports(tmp_path)
    assert out.returncode != 0
    assert f"{CONTRACTS['shared']['name']} BROKEN" in " ".join(out.stdout.split())
