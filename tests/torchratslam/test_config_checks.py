"""The defaults run, and keys that cannot go together fail when the config is loaded."""

import numpy as np
import pytest
import torch

from torchratslam import ConfigError, RatSLAM, load_config
from torchratslam.config import LocalViewParams, RatSLAMConfig
from torchratslam.local_view.matcher import TemplateMatcher
from torchratslam.readers.datasets import open_data


def test_ratslam_without_arguments_runs():
    slam = RatSLAM()
    assert slam.config == load_config() == RatSLAMConfig()
    lv = slam.config.local_view
    # OpenRatSLAM's own defaults, except the template size they cannot match with
    assert (lv.vt_shift_match, lv.vt_step_match, lv.vt_panoramic) == (25, 5, False)
    assert (lv.template_x_size, lv.template_y_size) == (60, 10)
    rng = np.random.default_rng(0)
    for _ in range(3):
        r = slam.step((rng.random((48, 120)) * 255).astype(np.uint8), (0.1, 0.0, 0.1))
    assert len(slam.templates) >= 1 and r.experience_id >= 0


def test_ratslam_without_arguments_maps_a_simulated_tour():
    torch.set_num_threads(1)
    slam = RatSLAM()
    result = slam.run(open_data("sim:virtual_tour/session1"), max_frames=60, progress=False)
    assert result.templates >= 2 and result.experiences >= 2


def test_the_default_template_is_wide_enough_for_the_default_shift():
    p = LocalViewParams()
    matcher = TemplateMatcher(
        p.template_y_size, p.template_x_size, panoramic=False, shift=25, step=5
    )
    assert matcher.width == p.template_x_size - 2 * p.vt_shift_match > 0


@pytest.mark.parametrize(
    ("keys", "named"),
    [
        ({"template_x_size": 1}, ("template_x_size = 1", "vt_shift_match = 50")),
        ({"template_x_size": 10, "vt_shift_match": 5}, ("template_x_size = 10", "= 10")),
        ({"image_crop_x_min": 30, "image_crop_x_max": 30}, ("image_crop_x_max", "_x_min")),
        ({"image_crop_y_min": 5, "image_crop_y_max": 2}, ("image_crop_y_max", "_y_min")),
        ({"vtrans_image_x_min": 9, "vtrans_image_x_max": 3}, ("vtrans_image_x_max", "x_min")),
        ({"vrot_image_y_min": 9, "vrot_image_y_max": 9}, ("vrot_image_y_max", "y_min")),
    ],
)
def test_cross_field_checks_fail_at_load_time_naming_both_keys(tmp_path, keys, named):
    with pytest.raises(ConfigError) as err:
        load_config(**keys)
    message = str(err.value)
    assert "\n" not in message
    for part in named:
        assert part in message
    # the same from a file, named in the message, and through replace()
    f = tmp_path / "bad.yaml"
    f.write_text("".join(f"{k}: {v}\n" for k, v in keys.items()))
    with pytest.raises(ConfigError, match=r"bad\.yaml: .*must exceed"):
        load_config(f)
    with pytest.raises(ConfigError, match="must exceed"):
        RatSLAMConfig().replace(**keys)


@pytest.mark.parametrize(
    "keys",
    [
        {"template_x_size": 51},  # 51 > 2 * 25: one compared column
        {"template_x_size": 1, "vt_panoramic": 1},  # panoramic: every offset is valid
        {"template_x_size": 4, "vt_shift_match": 0},
        {"image_crop_x_min": 30, "image_crop_x_max": -1},  # -1: the image edge
        {"vrot_image_y_min": 3, "vrot_image_y_max": 4},
    ],
)
def test_compatible_keys_load(keys):
    cfg = load_config(**keys)
    assert {k: cfg.to_flat()[k] for k in keys} == {
        k: (bool(v) if k == "vt_panoramic" else v) for k, v in keys.items()
    }


def test_every_shipped_preset_passes_the_cross_field_checks():
    from torchratslam.config import CONFIG_DIR

    names = sorted(p.stem for p in CONFIG_DIR.glob("*.yaml"))
    assert len(names) >= 7
    for name in names:
        load_config(name).check()
