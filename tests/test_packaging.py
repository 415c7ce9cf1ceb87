"""The package installs and imports like a library.

* import names: a user's own ``graph.py`` / ``configs.py`` in the working directory
  does not shadow anything (the torch-free half is ``torchratslam.graph``, the presets
  ``torchratslam.presets``);
* the wheel holds every package and the shipped presets, and the README's quick start
  runs from the wheel's contents alone, outside the checkout;
* every folder with an ``__init__.py`` is listed in pyproject's ``packages``.
"""

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    from pip._vendor import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
SETUPTOOLS = PYPROJECT["tool"]["setuptools"]
# Source folder -> import name, as the build maps them.
PACKAGE_DIRS = {src: name for name, src in SETUPTOOLS["package-dir"].items()}


def _import_name(folder: Path) -> str:
    """The import name of a package folder of the checkout (through package-dir)."""
    rel = folder.relative_to(ROOT).parts
    for cut in range(len(rel), 0, -1):
        head = "/".join(rel[:cut])
        if head in PACKAGE_DIRS:
            return ".".join((PACKAGE_DIRS[head], *rel[cut:]))
    raise AssertionError(f"{folder} is outside every package-dir root {PACKAGE_DIRS}")


def _package_folders() -> list[Path]:
    return sorted(
        p.parent
        for src in PACKAGE_DIRS
        for p in (ROOT / src).rglob("__init__.py")
        if "__pycache__" not in p.parts
    )


def _modules() -> list[str]:
    """Every importable module of the checkout, by import name."""
    names = []
    for folder in _package_folders():
        pkg = _import_name(folder)
        names.append(pkg)
        names += [
            f"{pkg}.{f.stem}"
            for f in sorted(folder.glob("*.py"))
            if f.stem not in ("__init__", "__main__")
        ]
    return sorted(set(names))


def test_every_package_folder_is_listed_in_pyproject():
    listed = set(SETUPTOOLS["packages"])
    found = {_import_name(f) for f in _package_folders()}
    assert found - listed == set(), f"add these to [tool.setuptools] packages: {found - listed}"
    assert listed - found == set(), f"listed packages without a folder: {listed - found}"
    assert {"torchratslam.graph", "torchratslam.presets", "torchratslam.cli"} <= found


def test_the_checker_maps_folders_through_package_dir():
    assert _import_name(ROOT / "graph" / "backends") == "torchratslam.graph.backends"
    assert _import_name(ROOT / "configs") == "torchratslam.presets"
    assert _import_name(ROOT / "torchratslam" / "maps") == "torchratslam.maps"
    assert "torchratslam.graph.backends.alpha" in _modules()


def test_a_users_graph_py_and_configs_py_shadow_nothing(tmp_path):
    for name in ("graph", "configs", "presets"):
        (tmp_path / f"{name}.py").write_text(f"raise ImportError('the user {name}.py')\n")
    modules = _modules()
    code = (
        "import importlib, sys\n"
        f"for m in {modules!r}:\n"
        "    importlib.import_module(m)\n"
        "assert 'graph' not in sys.modules and 'configs' not in sys.modules\n"
        "from torchratslam import load_config\n"
        "print(load_config('virtual_tour').local_view.template_x_size)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["128"]
    assert len(modules) > 40


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """Build the wheel offline from a copy of the sources (no build/ in the checkout)."""
    src = tmp_path_factory.mktemp("src")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, src / name)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for folder in PACKAGE_DIRS:
        shutil.copytree(ROOT / folder, src / folder, ignore=ignore)
    out = tmp_path_factory.mktemp("wheel")
    cmd = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation"]
    res = subprocess.run(
        [*cmd, "--no-index", "-q", "-w", str(out), str(src)], capture_output=True, text=True
    )
    assert res.returncode == 0, res.stderr[-3000:]
    (whl,) = out.glob("torchratslam-*.whl")
    return whl


def test_the_wheel_holds_every_package_and_the_presets(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    for folder in _package_folders():
        init = _import_name(folder).replace(".", "/") + "/__init__.py"
        assert init in names, f"{init} missing from the wheel"
    presets = sorted((ROOT / "configs").glob("*.yaml"))
    assert len(presets) >= 7
    for p in presets:
        assert f"torchratslam/presets/{p.name}" in names
    assert "torchratslam/py.typed" in names
    assert not any(n.startswith(("graph/", "configs/", "tests/")) for n in names)


def test_the_quick_start_runs_from_the_wheel_outside_the_checkout(wheel, tmp_path):
    site = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(site)
    work = tmp_path / "work"
    work.mkdir()
    code = """
import torch
import torchratslam, torchratslam.graph, torchratslam.presets
from torchratslam import RatSLAM, load_config
from torchratslam.readers.datasets import open_data

torch.set_num_threads(1)
slam = RatSLAM(load_config("virtual_tour"))
result = slam.run(open_data("sim:virtual_tour/session2"), max_frames=40, progress=False)
assert result.templates > 0 and result.experiences > 0, result
print(torchratslam.__file__)
print(torchratslam.graph.__file__)
print(torchratslam.presets.__file__)
"""
    env = {"PATH": "/usr/bin:/bin", "PYTHONPATH": str(site), "HOME": str(tmp_path)}
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=work, env=env, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr[-3000:]
    files = [Path(line) for line in out.stdout.split()]
    assert len(files) == 3
    for f in files:
        assert f.is_relative_to(site), f"{f} does not come from the extracted wheel"
