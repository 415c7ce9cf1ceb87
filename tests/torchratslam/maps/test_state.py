"""Native map format: exact round trip, atomic writes, and clear errors on bad maps."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from torchratslam.config import load_config
from torchratslam.errors import InputError, MapFormatError
from torchratslam.maps import native
from torchratslam.maps.compat import check_compatible
from torchratslam.maps.native import load_map, load_state, save_map
from torchratslam.maps.state import MapState

CONFIG = load_config(
    pc_dim_xy=7, pc_dim_th=10, template_x_size=5, template_y_size=3, vt_shift_match=2
).to_flat()


def random_map(seed: int = 0, n: int = 6, m: int = 9, el: int = 11) -> MapState:
    rng = np.random.default_rng(seed)
    frm = rng.integers(0, m, el)
    to = (frm + 1 + rng.integers(0, m - 1, el)) % m
    return MapState(
        config=dict(CONFIG),
        templates=rng.random((n, 3, 5)).astype(np.float32),
        template_mean=rng.random(n),
        template_frame=np.arange(n, dtype=np.int64) * 2,
        template_pc=rng.random((n, 3)) * [7, 7, 10],
        template_decay=rng.random(n) + 1,
        exp_pose=rng.normal(size=(m, 3)),
        exp_pc=rng.random((m, 3)) * [7, 7, 10],
        exp_template=rng.integers(0, n, m),
        exp_frame=np.arange(m, dtype=np.int64),
        exp_t=np.arange(m) * 0.1,
        link_from=frm,
        link_to=to,
        link_d=rng.random(el),
        link_heading=rng.uniform(-3, 3, el),
        link_facing=rng.uniform(-3, 3, el),
        link_dt=rng.random(el),
        activity=rng.random((10, 7, 7)),
        current_vt=n - 1,
        prev_vt=n - 2,
        current_exp=m - 1,
        prev_exp=m - 3,
        frame_index=123,
        extra={"link:count": rng.integers(0, 5, el), "em:accum": rng.random(4)},
        scalars={"time": 1.25, "name": "s1", "flag": True, "n": 3},
    ).validate()


def snapshot(d: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(d.iterdir())}


def test_round_trip_is_exact(tmp_path):
    s = random_map()
    save_map(s, tmp_path / "m")
    back = load_map(tmp_path / "m")
    assert back.equals(s)
    assert back.templates.dtype == np.float32 and back.exp_template.dtype == np.int64
    assert back.extra["em:accum"].tolist() == s.extra["em:accum"].tolist()
    # a run's OUT directory (state/ inside) loads too
    save_map(s, tmp_path / "out" / "state")
    assert load_state(tmp_path / "out").equals(s)
    meta = json.loads((tmp_path / "m" / "state.json").read_text())
    assert meta["version"] == native.FORMAT_VERSION and meta["counts"]["experiences"] == 9


def test_equals_notices_every_difference():
    s = random_map()
    t = s.copy()
    assert t.equals(s)
    t.exp_pose[3, 1] += 1e-15
    assert not t.equals(s)
    u = s.copy()
    u.current_exp = 0
    assert not u.equals(s)


def test_overwrite_replaces_a_map_and_leaves_no_temporaries(tmp_path):
    save_map(random_map(0), tmp_path / "m")
    save_map(random_map(1), tmp_path / "m")
    assert load_map(tmp_path / "m").equals(random_map(1))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m"]


def test_a_crash_while_writing_leaves_the_old_map_intact(tmp_path, monkeypatch):
    target = tmp_path / "m"
    save_map(random_map(0), target)
    before = snapshot(target)

    def boom(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(native.np, "savez", boom)
    with pytest.raises(OSError, match="disk full"):
        save_map(random_map(1), target)
    assert snapshot(target) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m"]


def test_refuses_to_overwrite_a_directory_with_other_files(tmp_path):
    d = tmp_path / "precious"
    d.mkdir()
    (d / "notes.txt").write_text("keep me")
    with pytest.raises(InputError, match="refusing to overwrite"):
        save_map(random_map(), d)
    assert (d / "notes.txt").read_text() == "keep me" and len(list(d.iterdir())) == 1


def test_truncated_npz_is_a_clear_error_and_files_are_untouched(tmp_path):
    save_map(random_map(), tmp_path / "m")
    npz = tmp_path / "m" / "state.npz"
    npz.write_bytes(npz.read_bytes()[: npz.stat().st_size // 2])
    before = snapshot(tmp_path / "m")
    with pytest.raises(MapFormatError, match="corrupt or truncated"):
        load_map(tmp_path / "m")
    assert snapshot(tmp_path / "m") == before


@pytest.mark.parametrize(
    ("edit", "pattern"),
    [
        (lambda m: m.update(version=99), "version 99 is not supported"),
        (lambda m: m.update(format="other"), "not a torchratslam-map"),
        (lambda m: m["arrays"]["exp_pose"].update(shape=[2, 3]), "'exp_pose' is float64"),
        (lambda m: m["arrays"].pop("link_dt"), "disagree"),
        (lambda m: m["ids"].pop("current_exp"), "'current_exp' missing"),
        (lambda m: m["ids"].update(current_exp=50), "current_exp = 50"),
        (lambda m: m["config"].update(pc_dim_th=12), "activity has shape"),
        (lambda m: m["config"].update(template_x_size=4), "templates have shape"),
    ],
)
def test_inconsistent_metadata_is_named(tmp_path, edit, pattern):
    save_map(random_map(), tmp_path / "m")
    j = tmp_path / "m" / "state.json"
    meta = json.loads(j.read_text())
    edit(meta)
    j.write_text(json.dumps(meta))
    with pytest.raises(MapFormatError, match=pattern):
        load_map(tmp_path / "m")


def test_bad_json_and_missing_files(tmp_path):
    save_map(random_map(), tmp_path / "m")
    (tmp_path / "m" / "state.json").write_text('{"format": "torchratslam-map", "vers')
    with pytest.raises(MapFormatError, match="not valid JSON"):
        load_map(tmp_path / "m")
    with pytest.raises(InputError, match="not found"):
        load_state(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="holds no saved map"):
        load_state(tmp_path / "empty")


@pytest.mark.parametrize(
    ("field", "value", "pattern"),
    [
        ("exp_pose", np.full((9, 3), np.nan), "NaN"),
        ("link_to", np.full(11, 9), "link"),
        ("exp_template", np.full(9, 6), "template id outside"),
        ("exp_pc", np.zeros((8, 3)), "'exp_pc' has shape"),
        ("template_frame", np.zeros(6), "expected integers"),
    ],
)
def test_validation_names_the_problem(field, value, pattern):
    s = random_map()
    setattr(s, field, value)
    with pytest.raises(MapFormatError, match=pattern):
        s.validate()


def test_invalid_map_is_never_written(tmp_path):
    s = random_map()
    s.exp_pose[0, 0] = np.inf
    with pytest.raises(MapFormatError):
        save_map(s, tmp_path / "m")
    assert not (tmp_path / "m").exists() and not list(tmp_path.iterdir())


def test_config_compatibility(tmp_path):
    s = random_map()
    check_compatible(
        s,
        load_config(
            **{
                k: CONFIG[k]
                for k in (
                    "pc_dim_xy",
                    "pc_dim_th",
                    "template_x_size",
                    "template_y_size",
                    "vt_shift_match",
                )
            },
            vt_match_threshold=0.2,
        ),
    )
    with pytest.raises(MapFormatError, match=r"pc_dim_xy = 7 in the map but 21 in the config"):
        check_compatible(s, load_config())
    save_map(s, tmp_path / "m")
    with pytest.raises(MapFormatError, match="template_x_size"):
        load_state(tmp_path / "m", load_config(pc_dim_xy=7, pc_dim_th=10, template_y_size=3))


def test_saved_files_do_not_need_pickle(tmp_path):
    save_map(random_map(), tmp_path / "m")
    with np.load(tmp_path / "m" / "state.npz", allow_pickle=False) as z:
        assert all(z[k].dtype != object for k in z.files)
    assert os.path.getsize(tmp_path / "m" / "state.json") < 20000
