"""The Python API refuses bad arguments in one line naming the argument, and a refused
``step`` leaves the state untouched."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from torchratslam import RatSLAM
from torchratslam.config import load_config
from torchratslam.errors import ConfigError, InputError

SMALL = Path(__file__).resolve().parents[2] / "data" / "small.yaml"


def _frames(n, seed):
    rng = np.random.default_rng(seed)
    imgs = rng.integers(0, 256, size=(n, 16, 64), dtype=np.uint8)
    odo = [(0.5 + 0.1 * rng.random(), 0.2 * rng.standard_normal(), 0.1) for _ in range(n)]
    return imgs, odo


def test_a_preset_name_or_path_is_a_config():
    assert RatSLAM("virtual_tour").config == load_config("virtual_tour")
    assert RatSLAM(SMALL).config == load_config(SMALL)
    with pytest.raises(ConfigError, match=r"RatSLAM\(config=...\): expected a RatSLAMConfig"):
        RatSLAM(3)  # type: ignore[arg-type]


@pytest.mark.skipif(torch.cuda.is_available(), reason="needs a torch without CUDA")
def test_cuda_without_cuda_is_one_line_naming_the_argument():
    with pytest.raises(InputError, match=r"RatSLAM\(device='cuda'\): this torch has no CUDA"):
        RatSLAM(load_config(SMALL), device="cuda")
    with pytest.raises(InputError, match=r"RatSLAM\(device='gpu7'\): not a torch device"):
        RatSLAM(load_config(SMALL), device="gpu7")


@pytest.mark.parametrize(
    "bad, match",
    [
        ((1, 2), "expected three numbers"),
        ((1, 2, 3, 4), "got 4"),
        (("a", 0, 0.1), "expected three numbers"),
        (5, "expected three numbers"),
        ((1e300, 0.0, 0.1), "vtrans = 1e\\+300 is not finite or exceeds"),
        ((float("nan"), 0.0, 0.1), "vtrans = nan"),
        ((0.5, float("inf"), 0.1), "vrot = inf"),
        ((0.5, 0.0, -0.1), "dt = -0.1"),
    ],
)
def test_a_refused_step_leaves_the_state_untouched(bad, match):
    """step a valid frame, a refused one, then valid frames: bit for bit the run that
    never saw the refused one."""
    cfg = load_config(SMALL)
    imgs, odo = _frames(12, seed=3)
    ref = RatSLAM(cfg)
    ref_out = [ref.step(imgs[i], odo[i]) for i in range(12)]
    slam = RatSLAM(cfg)
    outs = [slam.step(imgs[0], odo[0])]
    with pytest.raises(InputError, match=match):
        slam.step(imgs[1], bad)
    outs += [slam.step(imgs[i], odo[i]) for i in range(1, 12)]
    assert [o.experience_id for o in outs] == [o.experience_id for o in ref_out]
    assert slam.frame_index == ref.frame_index == 12
    assert torch.equal(slam.activity, ref.activity)  # pose cells, bit for bit
    assert torch.equal(slam.templates, ref.templates)
    assert slam.counts() == ref.counts()
    assert np.array_equal(slam.experience_map.poses, ref.experience_map.poses)
    assert np.array_equal(slam.trajectory(), ref.trajectory(), equal_nan=True)
    assert np.array_equal(slam.odometry_log(), ref.odometry_log())
