"""Configs written as OpenRatSLAM ``.txt`` files read back unchanged."""

from __future__ import annotations

import configparser

import pytest

from torchratslam.config import CONFIG_DIR, load_config, to_openratslam_txt


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
