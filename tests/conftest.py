"""Settings and fixtures shared by every test module.

* ``small_config``: the small, fast configuration (``tests/data/small.yaml``), as a path;
* ``small_run``: a finished ``torchratslam run`` of that configuration on 40 frames of the
  simulated loop, copied fresh for each test (the run itself is made once per session);
* ``loop_frames``: two laps of the simulated loop (400 frames), made once per session.
"""

import shutil
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import pytest
import torch

matplotlib.use("Agg")

DATA = Path(__file__).resolve().parent / "data"
SMALL_CONFIG = DATA / "small.yaml"
SMALL_SIM = "sim:loop?laps=1&frames=40"
"""The data of the small run: one lap of the simulated loop in 40 frames."""


@pytest.fixture(autouse=True, scope="session")
def _one_torch_thread():
    """One intra-op thread: on a busy 2-core machine torch's default pool makes small
    pose-cell steps 100x slower, and results must not depend on the thread count."""
    torch.set_num_threads(1)
    yield


@pytest.fixture
def small_config(tmp_path) -> Path:
    """A copy of the small configuration in the test's own folder."""
    path = tmp_path / "small.yaml"
    shutil.copy(SMALL_CONFIG, path)
    return path


@dataclass(frozen=True)
class SmallRun:
    """A finished run: its OUT folder, its configuration and the data it read."""

    out: Path
    config: Path
    data: str = SMALL_SIM


@pytest.fixture(scope="session")
def _small_run_once(tmp_path_factory) -> SmallRun:
    from torchratslam.cli import main

    root = tmp_path_factory.mktemp("small_run")
    cfg = root / "small.yaml"
    shutil.copy(SMALL_CONFIG, cfg)
    out = root / "out"
    argv = ["run", "--config", str(cfg), "--data", SMALL_SIM, "--out", str(out), "--no-progress"]
    assert main(argv) == 0
    return SmallRun(out=out, config=cfg)


@pytest.fixture
def small_run(_small_run_once, tmp_path) -> SmallRun:
    """The small run, copied into the test's folder (a test may change it freely)."""
    root = tmp_path / "small_run"
    shutil.copytree(_small_run_once.out.parent, root)
    return SmallRun(out=root / "out", config=root / "small.yaml")


@pytest.fixture(scope="session")
def loop_params() -> dict:
    """The config keys the pipeline tests run the loop with (a map that closes it)."""
    return dict(
        template_x_size=64,
        template_y_size=16,
        vt_panoramic=1,
        vt_shift_match=4,
        vt_step_match=1,
        vt_match_threshold=0.06,
        pc_dim_xy=21,
        pc_cell_x_size=0.25,
        pc_vt_inject_energy=0.1,
        exp_delta_pc_threshold=2,
    )


@pytest.fixture(scope="session")
def loop_frames() -> list:
    """Two laps of the simulated loop, 400 frames."""
    from torchratslam.sim import get_tour

    return list(get_tour("loop", laps=2, frames=400).full().frames())
