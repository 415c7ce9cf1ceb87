"""Config loading: shipped YAMLs, OpenRatSLAM .txt files, and clear errors."""

from pathlib import Path

import pytest

from torchratslam.config import CONFIG_DIR, RatSLAMConfig, load_config
from torchratslam.errors import ConfigError, InputError

SHIPPED = sorted(CONFIG_DIR.glob("*.yaml"))


def test_all_published_parameter_sets_are_shipped():
    names = {p.stem for p in SHIPPED}
    assert names >= {
        "virtual_tour",
        "lab_tour",
        "irat",
        "new_college",
        "irat_openratslam",
        "stlucia",
        "new_college_openratslam",
    }


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_every_shipped_config_loads(path):
    cfg = load_config(path)
    assert isinstance(cfg, RatSLAMConfig)
    assert cfg.pose_cells.pc_dim_xy > 0 and cfg.local_view.template_x_size > 0


def test_published_values_reach_the_right_modules():
    vt = load_config("virtual_tour")  # by name
    assert (vt.pose_cells.pc_dim_xy, vt.pose_cells.pc_dim_th) == (80, 35)
    assert (vt.local_view.template_x_size, vt.local_view.template_y_size) == (128, 32)
    assert vt.local_view.vt_panoramic is False and vt.local_view.vt_step_match == 2
    assert vt.experience_map.exp_loops == 250 and vt.experience_map.exp_initial_em_deg == 140.0
    assert vt.visual_odometry.camera_fov_deg == 360.0
    nc = load_config(CONFIG_DIR / "new_college_openratslam.yaml")
    assert nc.local_view.vt_panoramic is True and nc.local_view.vt_patch_normalise == 2
    # absent keys take OpenRatSLAM's defaults
    assert nc.pose_cells.pc_w_e_dim == 7 and nc.pose_cells.pc_global_inhib == pytest.approx(2e-5)
    assert nc.experience_map.exp_correction == 0.5


def test_defaults_without_a_file_are_openratslams():
    cfg = load_config()
    assert cfg.pose_cells.pc_dim_xy == 21 and cfg.pose_cells.pc_dim_th == 36
    assert (cfg.local_view.vt_shift_match, cfg.local_view.vt_step_match) == (25, 5)
    assert cfg.experience_map.exp_loops == 10 and cfg.visual_odometry.vtrans_scaling == 100.0


OPENRATSLAM_TXT = """\
[general]
topic_root=irat_red

[ratslam]
; a comment
image_crop_y_max=150
template_x_size=60
template_y_size=20
vt_shift_match=4
vt_step_match=1
vt_match_threshold=0.03
pc_dim_xy=11   ; inline comment
pc_cell_x_size=0.015
exp_initial_em_deg=140
vt_window_width=416

[visual_odometry]
camera_fov_deg=53

[draw]
enable=1
exp_map_size=500

[some_other_tool]
whatever=1
"""


def test_openratslam_txt_config_loads(tmp_path: Path):
    p = tmp_path / "config_irat.txt"
    p.write_text(OPENRATSLAM_TXT)
    cfg = load_config(p)
    assert cfg.general.topic_root == "irat_red"
    assert cfg.local_view.image_crop_y_max == 150 and cfg.local_view.template_x_size == 60
    assert cfg.pose_cells.pc_dim_xy == 11 and cfg.pose_cells.pc_cell_x_size == pytest.approx(0.015)
    assert cfg.visual_odometry.camera_fov_deg == 53.0
    assert cfg.experience_map.exp_initial_em_deg == 140.0


def test_txt_equals_yaml_for_the_same_values(tmp_path: Path):
    p = tmp_path / "c.txt"
    p.write_text(
        "[ratslam]\n" + "\n".join(f"{k}={v}" for k, v in load_config("irat").to_flat().items())
    )
    assert load_config(p) == load_config("irat")


def test_unknown_key_names_key_and_nearest(tmp_path: Path):
    p = tmp_path / "bad.yaml"
    p.write_text("pc_dim_xyz: 21\n")
    with pytest.raises(ConfigError, match=r"'pc_dim_xyz'.*did you mean 'pc_dim_xy'"):
        load_config(p)
    t = tmp_path / "bad.txt"
    t.write_text("[ratslam]\nvt_match_treshold=0.1\n")
    with pytest.raises(ConfigError, match=r"'vt_match_treshold'.*'vt_match_threshold'"):
        load_config(t)


@pytest.mark.parametrize(
    ("key", "value", "pattern"),
    [
        ("pc_dim_xy", -3, r"'pc_dim_xy' = -3"),
        ("pc_dim_th", 0, r"'pc_dim_th' = 0"),
        ("template_x_size", "wide", r"'template_x_size'.*'wide'"),
        ("pc_cell_x_size", float("nan"), r"'pc_cell_x_size'.*NaN"),
        ("vt_panoramic", 2, r"'vt_panoramic'.*2"),
        ("exp_correction", 1.5, r"'exp_correction' = 1.5"),
        ("pc_dim_xy", 2.5, r"'pc_dim_xy'.*2.5"),
    ],
)
def test_bad_values_are_named(key, value, pattern):
    with pytest.raises(ConfigError, match=pattern):
        load_config(**{key: value})


def test_missing_file_is_a_clear_error(tmp_path: Path):
    with pytest.raises(InputError, match="not found"):
        load_config(tmp_path / "nope.yaml")


def test_invalid_yaml_is_a_config_error(tmp_path: Path):
    p = tmp_path / "x.yaml"
    p.write_text("a: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(p)


def test_configs_are_frozen_and_replace_validates():
    cfg = load_config()
    with pytest.raises(AttributeError):
        cfg.pose_cells.pc_dim_xy = 5  # type: ignore[misc]
    assert cfg.replace(pc_dim_xy=31).pose_cells.pc_dim_xy == 31
    with pytest.raises(ConfigError):
        cfg.replace(pc_dim_xy=0)


def test_modules_are_chosen_by_name_in_the_config():
    cfg = load_config(local_view="features", odometry="visual", experience_map="mine")
    assert cfg.general.local_view == "features" and cfg.general.odometry == "visual"
    assert cfg.general.experience_map == "mine" and cfg.general.pose_cells == "ratslam"


# ----------------------------------------------------------------- behaviour profiles
def _switches(cfg: RatSLAMConfig) -> dict:
    from torchratslam.config import PROFILES

    flat = cfg.to_flat()
    return {k: flat[k] for k in PROFILES["openratslam"]}


def test_the_default_behaviour_is_openratslam_and_a_profile_sets_every_switch():
    import dataclasses

    from torchratslam.config import PROFILES, RECOMMENDED

    assert set(PROFILES) == {"openratslam", "torchratslam"}
    assert set(PROFILES["openratslam"]) == set(PROFILES["torchratslam"]) == set(RECOMMENDED)
    owner = RatSLAMConfig.key_owner()
    assert set(RECOMMENDED) <= set(owner)  # every switch is a real key
    # the openratslam profile is the dataclass defaults; the recommended one changes each
    for key, value in RECOMMENDED.items():
        klass = RatSLAMConfig.sections()[owner[key]]
        default = {f.name: f.default for f in dataclasses.fields(klass)}[key]
        assert PROFILES["openratslam"][key] == default != value
    default_cfg = load_config()
    assert default_cfg.general.behaviour == "openratslam"
    assert default_cfg == RatSLAMConfig()  # no profile value differs from a default
    assert _switches(default_cfg) == PROFILES["openratslam"]
    rec = load_config(behaviour="torchratslam")  # the recommended bundle
    assert _switches(rec) == RECOMMENDED
    for key, value in RECOMMENDED.items():  # each key lands in its module
        assert getattr(getattr(rec, owner[key]), key) == value
    # keys outside the profiles keep their defaults under either profile
    flat, rec_flat = default_cfg.to_flat(), rec.to_flat()
    assert {k for k in flat if flat[k] != rec_flat[k]} == set(RECOMMENDED) | {"behaviour"}
    assert rec.experience_map.exp_relax == "on_action" and rec.pose_cells.pc_multi_cell


def test_explicit_keys_override_the_profile(tmp_path: Path):
    p = tmp_path / "c.yaml"
    p.write_text("behaviour: torchratslam\nexp_link_time: since_start\npc_dim_xy: 15\n")
    cfg = load_config(p)
    assert cfg.experience_map.exp_link_time == "since_start"  # the file's own key wins
    assert cfg.experience_map.exp_first_at_origin  # the rest from the profile
    assert cfg.pose_cells.pc_dim_xy == 15
    assert not load_config(p, exp_first_at_origin=False).experience_map.exp_first_at_origin
    # replace() switches the profile but keeps keys the config set itself
    back = cfg.replace(behaviour="openratslam")
    assert back.general.behaviour == "openratslam" and back.general.skip_first_odometry
    assert not back.experience_map.exp_first_at_origin and back.pose_cells.pc_dim_xy == 15
    mine = load_config(behaviour="torchratslam", exp_link_time="since_start")
    assert mine.replace(behaviour="openratslam") == load_config(exp_link_time="since_start")
    kept = load_config(exp_link_time="per_link").replace(behaviour="torchratslam")
    assert kept == load_config(behaviour="torchratslam")
    assert load_config().replace(behaviour="torchratslam") == load_config(behaviour="torchratslam")
    # the saved flat form reloads to the same config
    assert RatSLAMConfig.from_flat(cfg.to_flat()) == cfg


def test_unknown_profile_is_rejected_with_a_suggestion(tmp_path: Path):
    with pytest.raises(ConfigError, match=r"unknown behaviour profile 'openratslm'.*'openratslam'"):
        load_config(behaviour="openratslm")
    p = tmp_path / "c.yaml"
    p.write_text("behaviour: TorchRatSLAM\n")
    with pytest.raises(ConfigError, match=r"c\.yaml.*did you mean 'torchratslam'"):
        load_config(p)
    with pytest.raises(ConfigError, match="exp_relax"):
        load_config(exp_relax="sometimes")


def test_an_openratslam_txt_config_gets_the_openratslam_behaviour(tmp_path: Path):
    from torchratslam.config import PROFILES

    p = tmp_path / "config.txt"
    p.write_text("[general]\ntopic_root=irat\n[ratslam]\nexp_loops=20\npc_dim_xy=21\n")
    cfg = load_config(p)
    assert cfg.general.behaviour == "openratslam"
    assert _switches(cfg) == PROFILES["openratslam"] and cfg.experience_map.exp_loops == 20


@pytest.mark.parametrize("value", ["[]", "{a: 1}", "7", "null"])
def test_a_behaviour_that_is_not_a_name_is_one_config_error(tmp_path: Path, value):
    p = tmp_path / "c.yaml"
    p.write_text(f"behaviour: {value}\n")
    with pytest.raises(ConfigError, match=r"c\.yaml: behaviour must be a profile name") as e:
        load_config(p)
    assert "\n" not in str(e.value)


def test_a_dict_of_flat_keys_is_a_config(tmp_path: Path):
    cfg = load_config({"pc_dim_xy": 15, "exp_loops": 3}, vt_match_threshold=0.2)
    p = tmp_path / "same.yaml"
    p.write_text("pc_dim_xy: 15\nexp_loops: 3\nvt_match_threshold: 0.2\n")
    assert cfg == load_config(p)
    assert cfg.pose_cells.pc_dim_xy == 15 and cfg.experience_map.exp_loops == 3
    with pytest.raises(ConfigError, match=r"config dict: unknown parameter 'pc_dim_yx'"):
        load_config({"pc_dim_yx": 15})
    with pytest.raises(ConfigError, match=r"config dict: key 3 \(int\) is not a parameter"):
        load_config({3: 15})
    with pytest.raises(ConfigError, match=r"a dict of flat keys or None; got list"):
        load_config([("pc_dim_xy", 15)])  # type: ignore[arg-type]


def test_a_key_given_twice_in_a_yaml_file_is_refused(tmp_path: Path):
    p = tmp_path / "twice.yaml"
    p.write_text("pc_dim_xy: 15\nexp_loops: 3\npc_dim_xy: 21\n")
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert str(e.value) == f"{p}: key 'pc_dim_xy' appears twice (lines 1 and 3); keep one"
    p.write_text("pc_dim_xy: 15\nexp_loops: 3\n")  # each key once: loads
    assert load_config(p).pose_cells.pc_dim_xy == 15


@pytest.mark.parametrize("text", ["", "\n\n", "# nothing but a comment\n"])
def test_an_empty_yaml_config_is_refused_not_run_as_the_defaults(tmp_path, text):
    p = tmp_path / "c.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=r"holds no parameters \(an empty file\)"):
        load_config(p)
    p.write_text("{}\n")  # the defaults, asked for
    assert load_config(p) == load_config(None)


def test_the_cli_refuses_an_empty_config_in_one_line(tmp_path, capsys):
    from torchratslam.cli import main

    p = tmp_path / "c.yaml"
    p.write_text("")
    out = tmp_path / "out"
    assert main(["run", "--config", str(p), "--data", "sim:loop?frames=5", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "holds no parameters" in err and "Traceback" not in err and not out.exists()
