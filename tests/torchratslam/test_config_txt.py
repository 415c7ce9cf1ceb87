"""Configs written as OpenRatSLAM ``.txt`` files read back unchanged."""

from __future__ import annotations

import configparser

import pytest

from torchratslam.config import CONFIG_DIR, load_config, to_openratslam_txt
from torchratslam.errors import ConfigError


@pytest.mark.parametrize("preset", sorted(p.stem for p in CONFIG_DIR.glob("*.yaml")))
def test_every_preset_round_trips_through_the_openratslam_txt_format(tmp_path, preset):
    config = load_config(preset)
    path = tmp_path / "config.txt"
    path.write_text(to_openratslam_txt(config, comment=preset))
    assert load_config(path) == config
    ini = configparser.ConfigParser(interpolation=None)
    ini.read_string(path.read_text())
    assert set(ini.sections()) == {"general", "ratslam", "visual_odometry"}
    for section in ini.sections():
        for key, value in ini.items(section):
            # OpenRatSLAM parses some keys as ints: no "2.0" where "2" is meant
            assert not (value.endswith(".0") and value[:-2].lstrip("-").isdigit()), (key, value)


def test_simulate_writes_the_tours_config_beside_the_data(tmp_path):
    from torchratslam.cli import main

    assert (
        main(["simulate", "suburb", "--out", str(tmp_path / "d"), "--max-frames", "5", "--quiet"])
        == 0
    )
    assert load_config(tmp_path / "d" / "config.txt") == load_config("suburb")


def test_a_key_given_twice_is_refused_not_silently_the_last(tmp_path):
    """OpenRatSLAM's ini reader refuses a key twice in one section; so does load_config
    (it used to take the last value silently), naming the key, section and line."""
    p = tmp_path / "c.txt"
    p.write_text(
        "[ratslam]\nvt_match_threshold = 0.03\npc_dim_xy = 21\nvt_match_threshold = 0.09\n"
    )
    with pytest.raises(
        ConfigError, match=r"'vt_match_threshold' appears twice in \[ratslam\] \(line 4\)"
    ):
        load_config(p)
    p.write_text("[ratslam]\npc_dim_xy = 21\n[ratslam]\npc_dim_xy = 25\n")
    with pytest.raises(ConfigError, match=r"section \[ratslam\] appears twice \(line 3\)"):
        load_config(p)
    p.write_text("[ratslam]\nvt_match_threshold = 0.03\n[general]\nvt_match_threshold = 0.09\n")
    with pytest.raises(ConfigError):  # one flat key in two sections is one key twice too
        load_config(p)


def test_a_config_with_no_parameters_is_refused(tmp_path):
    p = tmp_path / "c.txt"
    p.write_text("[draw]\nenable = 1\n")
    with pytest.raises(ConfigError, match="holds no parameters"):
        load_config(p)
