"""The package installs and imports like a library.

* import names are folder paths below a source root (the checkout, ``graph/``): no
  package is remapped; the torch-free half is a distribution of its own (``graph/``,
  import name ``ratslam_graph``) without torch, and ships inside the main distribution
  too, so a plain ``pip install .`` gives both packages;
* a user's own ``graph.py`` / ``configs.py`` in the working directory shadows nothing;
* the wheels hold every package and the shipped presets (``configs/``, data, as
  ``torchratslam/presets/``), and the README's quick start runs from the wheels' contents
  alone, outside the checkout.
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
# Each distribution's source folder: what you import is where the file is.
SOURCES = {"torchratslam": ROOT, "ratslam_graph": ROOT / "graph"}


def _package_folders() -> list[Path]:
    return sorted(
        p.parent
        for name, src in SOURCES.items()
        for p in (src / name).rglob("__init__.py")
        if "__pycache__" not in p.parts
    )


def _import_name(folder: Path) -> str:
    """The import name of a package folder: its path below the distribution's folder."""
    for name, src in SOURCES.items():
        if folder.is_relative_to(src / name):
            return ".".join(folder.relative_to(src).parts)
    raise AssertionError(f"{folder} is outside every distribution {SOURCES}")


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


def test_no_package_is_remapped():
    for pyproject in (ROOT / "pyproject.toml", ROOT / "graph" / "pyproject.toml"):
        setuptools = tomllib.loads(pyproject.read_text())["tool"]["setuptools"]
        assert "package-dir" not in setuptools, pyproject
    assert not (ROOT / "configs" / "__init__.py").exists(), "configs/ holds data, not code"
    assert _import_name(ROOT / "graph" / "ratslam_graph" / "backends") == "ratslam_graph.backends"
    assert "ratslam_graph.backends.alpha" in _modules()


def test_the_graph_distribution_does_not_depend_on_torch():
    graph = tomllib.loads((ROOT / "graph" / "pyproject.toml").read_text())["project"]
    assert not any(d.startswith("torch") for d in graph["dependencies"])
    # the main distribution ships ratslam_graph itself, so it needs what graph/ needs

    def name(d: str) -> str:
        return d.split(">")[0].split("=")[0].split("<")[0].strip()

    main = {name(d) for d in PYPROJECT["project"]["dependencies"]}
    assert {name(d) for d in graph["dependencies"]} <= main
    assert not any(n.startswith("ratslam") for n in main), "no dependency a plain pip cannot find"


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
    for name in ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md"):
        shutil.copy(ROOT / name, src / name)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "build")
    for folder in ("torchratslam", "graph", "configs"):
        shutil.copytree(ROOT / folder, src / folder, ignore=ignore)
    out = tmp_path_factory.mktemp("wheel")
    cmd = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation"]
    for dist in (src, src / "graph"):
        res = subprocess.run(
            [*cmd, "--no-index", "-q", "-w", str(out), str(dist)], capture_output=True, text=True
        )
        assert res.returncode == 0, res.stderr[-3000:]
    (whl,) = out.glob("torchratslam-*.whl")
    (graph,) = out.glob("ratslam_graph-*.whl")
    return whl, graph


def test_the_wheels_hold_every_package_and_the_presets(wheel):
    names = set(zipfile.ZipFile(wheel[0]).namelist())  # the main wheel alone: both packages
    graph_names = set(zipfile.ZipFile(wheel[1]).namelist())
    assert "ratslam_graph/__init__.py" in graph_names
    assert not any(n.startswith("torchratslam/") for n in graph_names)
    assert {n for n in graph_names if n.startswith("ratslam_graph/")} <= names
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
    zipfile.ZipFile(wheel[0]).extractall(site)  # the main wheel alone, as `pip install .`
    work = tmp_path / "work"
    work.mkdir()
    code = """
import torch
import torchratslam, ratslam_graph
from torchratslam.config import CONFIG_DIR
from torchratslam import RatSLAM, load_config
from torchratslam.readers.datasets import open_data

torch.set_num_threads(1)
slam = RatSLAM(load_config("virtual_tour"))
result = slam.run(open_data("sim:virtual_tour/session2"), max_frames=40, progress=False)
assert result.templates > 0 and result.experiences > 0, result
print(torchratslam.__file__)
print(ratslam_graph.__file__)
print(CONFIG_DIR / "virtual_tour.yaml")
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
