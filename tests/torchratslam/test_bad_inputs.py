"""Every bad input gets one line from the project's errors, naming the source;
no silent wrong result from the readers (frame order, options, time bases, speeds)."""

from __future__ import annotations

import json
import logging
import shutil

import cv2
import numpy as np
import pytest

from ratslam_graph.io import read_posegraph
from torchratslam.config import check_config_limits, load_config
from torchratslam.errors import ConfigError, InputError, MapFormatError, RatSLAMError
from torchratslam.maps.native import load_map, save_map
from torchratslam.maps.reference_format import read_reference
from torchratslam.readers.datasets import DirectoryReader, natural_key, open_data

from .maps.test_reference_format import CFG as REF_CFG
from .maps.test_reference_format import HAND
from .maps.test_state import random_map


def _one_line(exc_info):
    msg = str(exc_info.value)
    assert "\n" not in msg and isinstance(exc_info.value, RatSLAMError)
    return msg


# ----------------------------------------------------------------------- configs
@pytest.mark.parametrize(
    ("text", "pattern"),
    [("~: 3\n", "key None"), ("5: 4\n", "key 5 (int)"), ("pc_dim_xy: ~\n", "pc_dim_xy")],
)
def test_yaml_keys_null_or_integer_are_one_line(tmp_path, text, pattern):
    p = tmp_path / "c.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert pattern in _one_line(e) and str(p) in str(e.value)


def test_a_bad_set_value_is_blamed_on_set_not_on_the_file(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("pc_dim_xy: 15\n")
    with pytest.raises(ConfigError, match=r"^overrides: parameter 'exp_loops'"):
        load_config(p, exp_loops="-3")
    p.write_text("pc_dim_xy: abc\n")
    with pytest.raises(ConfigError, match=rf"^{p}: parameter 'pc_dim_xy'"):
        load_config(p, exp_loops="3")
    # an override may still fix the file's value
    assert load_config(p, pc_dim_xy="9").pose_cells.pc_dim_xy == 9


def test_sizes_that_cannot_fit_and_crossed_crops_are_refused_before_the_work():
    with pytest.raises(ConfigError, match=r"pc_dim_xy = 100000.*needs about .*TB"):
        check_config_limits(load_config(None, pc_dim_xy=100000))
    # a rectangle is counted as X x Y cells, named by its own keys
    with pytest.raises(
        ConfigError, match=r"pc_dim_x = 2000000, pc_dim_y = 40.*lower pc_dim_x / pc_dim_y"
    ):
        check_config_limits(load_config(None, pc_dim_x=2_000_000, pc_dim_y=40), memory_bytes=10**9)
    check_config_limits(load_config(None, pc_dim_x=100, pc_dim_y=40), memory_bytes=10**9)
    check_config_limits(load_config("virtual_tour"))
    with pytest.raises(ConfigError, match="one template needs about"):
        check_config_limits(load_config(None, template_x_size=10**6, template_y_size=10**6))
    with pytest.raises(ConfigError, match="vrot_image_y_max = 3 must exceed vrot_image_y_min = 5"):
        load_config(None, vrot_image_y_min=5, vrot_image_y_max=3)


# ----------------------------------------------------------------------- native maps
def _edit_json(d, edit):
    meta = json.loads((d / "state.json").read_text())
    edit(meta)
    (d / "state.json").write_text(json.dumps(meta))


@pytest.mark.parametrize(
    ("edit", "pattern"),
    [
        (lambda m: m.update(version="1"), "version '1' is not an integer"),
        (lambda m: m.update(version=0), "re-save the map"),
        (lambda m: m.update(arrays=[1, 2]), "malformed 'arrays'"),
        (lambda m: m["arrays"].update(templates=[3]), "array entry 'templates' is not a mapping"),
        (lambda m: m["config"].update(pc_dim_xy="7"), "pc_dim_xy = '7' is not a positive"),
        (lambda m: m["config"].update(template_x_size=None), "template_x_size = None"),
        (lambda m: m["config"].update(pc_w_e_var=[1]), "config key 'pc_w_e_var' has a list"),
    ],
)
def test_a_state_json_with_wrong_types_is_one_line(tmp_path, edit, pattern):
    save_map(random_map(), tmp_path / "m")
    _edit_json(tmp_path / "m", edit)
    with pytest.raises(MapFormatError) as e:
        load_map(tmp_path / "m")
    assert pattern in _one_line(e)


def test_an_npz_member_declaring_a_huge_shape_is_refused_before_allocating(tmp_path):
    import io
    import zipfile

    save_map(random_map(), tmp_path / "m")
    npz = tmp_path / "m" / "state.npz"
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f8", "fortran_order": False, "shape": (10**6, 10**6)}
    )
    out = io.BytesIO()
    with zipfile.ZipFile(npz) as zin, zipfile.ZipFile(out, "w") as zout:
        for name in zin.namelist():
            data = header.getvalue() if name == "activity.npy" else zin.read(name)
            zout.writestr(name, data)
    npz.write_bytes(out.getvalue())
    with pytest.raises(MapFormatError) as e:  # 8 TB: refused, not a MemoryError
        load_map(tmp_path / "m")
    assert "declares shape (1000000, 1000000)" in _one_line(e)


# ----------------------------------------------------------------------- reference maps
@pytest.mark.parametrize("line", ["[[1]]", "1e400", "0 'a'", "[0,'a']"])
def test_reference_format_list_lines_are_one_line(tmp_path, line):
    # a list line (savetxt numbers) holding what no list holds: one line naming it
    d = tmp_path / "ref"
    d.mkdir()
    for name, text in HAND.items():
        if name == "posecellvisual_templates.txt":
            lines = text.splitlines()
            i = next(k for k, v in enumerate(lines) if "e+" in v)  # the first list line
            lines[i] = line
            text = "\n".join(lines) + "\n"
        (d / name).write_text(text)
    with pytest.raises(MapFormatError) as e:
        read_reference(d, REF_CFG)
    assert "posecellvisual_templates.txt, line 6" in _one_line(e)


# ----------------------------------------------------------------------- pose graphs
@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("EDGE2 -1 0 1 0 0\n", "not a non-negative integer"),
        ("EDGE2 0 1000000000000 1 0 0\n", "names vertex 1000000000000 but the file has 1 edges"),
        ("EDGE2 0 1e400 1 0 0\n", "not a non-negative integer"),
        ("EDGE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE2 1 1e12 1 0 0 1 0 0 1 0 1\n", "has 2 edges"),
        ("VERTEX2 -3 0 0 0\nVERTEX2 1.5 0 0 0\n", "not a non-negative integer"),
        ("EDGE2 0 1 1e12 0 1 0.5 0 0\n", "names vertex"),  # city layout, huge id
    ],
)
def test_pose_graph_ids_negative_or_huge_are_one_line(tmp_path, text, pattern):
    p = tmp_path / "g.graph"
    p.write_text(text)
    with pytest.raises(MapFormatError) as e:
        read_posegraph(p)
    assert pattern in _one_line(e)


# ----------------------------------------------------------------------- readers
def _dataset(root, names, *, odometry=True, gt=None):
    (root / "frames").mkdir(parents=True)
    for k, name in enumerate(names):
        img = np.full((6, 8), k * 10, np.uint8)  # brightness encodes the true order
        cv2.imwrite(str(root / "frames" / name), img)
    if odometry:
        rows = "".join(f"{0.1 * k},0.5,0.1\n" for k in range(len(names)))
        (root / "odometry.csv").write_text("t,vtrans,vrot\n" + rows)
    if gt is not None:
        (root / "groundtruth.csv").write_text("t,x,y,theta\n" + gt)
    return root


def test_frames_are_read_in_natural_order_and_the_order_is_reported(tmp_path, caplog):
    names = [f"frame_{k}.png" for k in range(12)]
    d = _dataset(tmp_path / "d", names)
    with caplog.at_level(logging.INFO, logger="torchratslam"):
        r = DirectoryReader(d)
    assert [f.name for f in r.files] == names  # not frame_0, frame_1, frame_10, frame_11, ...
    assert [int(f.image[0, 0]) for f in r] == [10 * k for k in range(12)]
    assert "natural order (not as strings): frame_0.png, frame_1.png, frame_2.png" in caplog.text
    assert natural_key("a10b2") > natural_key("a9b10")


def test_names_that_differ_only_in_leading_zeros_are_refused(tmp_path):
    d = _dataset(tmp_path / "d", ["f_1.png", "f_01.png", "f_2.png"])
    with pytest.raises(InputError, match=r"'f_01.png' and 'f_1.png' differ only in leading zeros"):
        DirectoryReader(d)


@pytest.mark.parametrize(
    ("row", "pattern"),
    [
        ("0.2,1e6,0", r"line 4: vtrans = 1e\+06 m/s exceeds 50 m/s"),
        ("0.2,1e300,0", "line 4: vtrans = 1e.300 m/s exceeds"),
        ("0.2,0.5,80", "line 4: vrot = 80 rad/s exceeds 50 rad/s"),
        ("0.2,nan,0", "line 4: NaN or infinite"),
        ("0.2,inf,0", "line 4: NaN or infinite"),
    ],
)
def test_implausible_or_non_finite_odometry_names_the_row(tmp_path, row, pattern):
    d = _dataset(tmp_path / "d", ["a.png", "b.png", "c.png"], odometry=False)
    (d / "odometry.csv").write_text(f"t,vtrans,vrot\n0,0.5,0\n0.1,0.5,0\n{row}\n")
    with pytest.raises(InputError, match=pattern):
        DirectoryReader(d)
    if "exceeds" in pattern:  # the limit is configurable
        assert DirectoryReader(d, max_speed=1e301, max_turn_rate=100).vtrans.size == 3


def test_options_that_do_not_apply_are_errors_and_groundtruth_applies_to_directories(tmp_path):
    with pytest.raises(InputError, match="odometry cannot be given with sim: data"):
        open_data("sim:loop", odometry="x.csv")
    with pytest.raises(InputError, match="groundtruth cannot be given with sim: data"):
        open_data("sim:loop", groundtruth="x.csv")
    d = _dataset(tmp_path / "d", ["a.png", "b.png", "c.png"], gt="0,0,0,0\n0.2,2,0,0\n")
    other = tmp_path / "gt2.csv"
    other.write_text("t,x,y,theta\n0,5,5,0\n0.2,7,5,0\n")
    r = open_data(d, groundtruth=other)  # --groundtruth replaces the directory's file
    assert r.groundtruth()[0].tolist() == [0, 5, 5, 0]
    assert [f.pose[0] for f in r] == pytest.approx([5, 6, 7])


def test_ground_truth_in_another_time_base_is_detected(tmp_path, caplog):
    unix = "1300000000,0,0,0\n1300000001,1,0,0\n"
    d = _dataset(tmp_path / "d", ["a.png", "b.png", "c.png"], gt=unix)
    with pytest.raises(InputError, match=r"cover 0 of 3 frame times.*different time bases"):
        DirectoryReader(d)
    # a partial cover is matched by time and reported
    shutil.rmtree(tmp_path / "d")
    d = _dataset(tmp_path / "d", ["a.png", "b.png", "c.png"], gt="0,0,0,0\n0.1,1,0,0\n")
    with caplog.at_level(logging.WARNING, logger="torchratslam"):
        r = DirectoryReader(d)
    assert "ground truth covers 2 of 3 frames" in caplog.text
    assert [f.pose is None for f in r] == [False, False, True]


def test_a_video_with_visual_odometry_and_ground_truth_in_another_time_base(tmp_path):
    video = tmp_path / "v.avi"
    w = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 5.0, (32, 24), False)
    for k in range(6):
        w.write(np.full((24, 32), 20 * k, np.uint8))
    w.release()
    gt = tmp_path / "gt.csv"  # Unix times, while the video's frame times run from 0 s
    gt.write_text("t,x,y,theta\n1300000000,0,0,0\n1300000002,1,0,0\n")
    with pytest.raises(InputError, match=r"ground-truth times \[1\.3e\+09, .*different time bases"):
        open_data(video, groundtruth=gt)
    gt.write_text("t,x,y,theta\n0,0,0,0\n1,1,0,0\n")  # the same base: matched by time
    r = open_data(video, groundtruth=gt)
    assert [round(f.pose[0], 6) for f in r] == [0.0, 0.2, 0.4, 0.6, 0.8, 1.0]
