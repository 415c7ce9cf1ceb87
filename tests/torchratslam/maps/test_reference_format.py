"""Import/export of the reference implementation's text format."""

from __future__ import annotations

import numpy as np
import pytest

from torchratslam.errors import InputError, MapFormatError
from torchratslam.maps.reference_format import FILES, read_reference, write_reference
from torchratslam.maps.state import MapState, load_state

CFG = {"template_x_size": 3, "template_y_size": 2, "pc_dim_xy": 5, "pc_dim_th": 8}

# A tiny map written by hand exactly as reference-save-format.md describes it: ids as
# floats, Python-style lists, TO before FROM in links.txt, 12 significant digits.
HAND = {
    "localviewcells.txt": """6
0.0
0.5
0.1 0.2 0.3 0.4 0.5 0.6
1.0
0.25
0 0.5 0.25 0.25 0.5 0
-
1.0
0.0
""",
    "posecellvisual_templates.txt": """0
2.0
3.0
4.5
1.5
[0]
1
2.5
3.0
7.0
1.0
[1, 2]
-
1
0
""",
    "posecellexperiences.txt": """2.0
3.0
4.5
0.0
2.5
3.0
7.0
1.0
2.6
3.1
6.9
1
-
2.0
1.0
""",
    "experiences.txt": """0.0
0.0
0.0
2.44346095279
0
[0]
[1]
0
0
0
1
-0.766044443119
0.642787609687
2.44346095279
1
[1]
[0]
0
0
0
2.0
-0.9
0.7
2.5
1
[]
[]
0
0
0
-
2
1
""",
    "links.txt": """1.0
0.0
0.0
1
0
3.5
1.0
3.14159265359
0.0
0
1
7.0
-
2
1
""",
}


def write_hand(d):
    d.mkdir()
    for name, text in HAND.items():
        (d / name).write_text(text)


def test_reads_a_hand_written_reference_map(tmp_path):
    write_hand(tmp_path / "ref")
    s = read_reference(tmp_path / "ref", CFG)
    assert s.templates.shape == (2, 2, 3)
    assert s.templates[0].tolist() == [[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]]  # row-major
    assert s.template_pc.tolist() == [[2.0, 3.0, 4.5], [2.5, 3.0, 7.0]]
    assert s.template_decay.tolist() == [1.5, 1.0]
    assert s.exp_template.tolist() == [0, 1, 1]
    assert s.exp_pose[1].tolist() == [-0.766044443119, 0.642787609687, 2.44346095279]
    # links.txt holds TO before FROM
    assert s.link_from.tolist() == [0, 1] and s.link_to.tolist() == [1, 0]
    assert s.link_dt.tolist() == [3.5, 7.0] and s.link_heading[1] == 3.14159265359
    assert (s.current_vt, s.prev_vt, s.current_exp, s.prev_exp) == (1, 0, 2, 1)
    assert s.activity.size == 0
    # a directory in that format is found by load_state too
    assert load_state(tmp_path / "ref", CFG).equals(s)


def test_round_trip_keeps_everything_the_format_holds(tmp_path):
    rng = np.random.default_rng(0)
    n, m, el = 4, 6, 7
    s = MapState(
        config=dict(CFG),
        templates=rng.random((n, 2, 3)),
        template_mean=rng.random(n),
        template_frame=np.full(n, -1),
        template_pc=rng.random((n, 3)) * 5,
        template_decay=rng.random(n),
        exp_pose=rng.normal(size=(m, 3)),
        exp_pc=rng.random((m, 3)) * 5,
        exp_template=np.array([0, 1, 1, 2, 3, 3]),
        exp_frame=np.full(m, -1),
        exp_t=np.zeros(m),
        link_from=np.array([0, 1, 2, 3, 4, 5, 0]),
        link_to=np.array([1, 2, 3, 4, 5, 0, 3]),
        link_d=rng.random(el),
        link_heading=rng.normal(size=el),
        link_facing=rng.normal(size=el),
        link_dt=rng.random(el),
        activity=np.zeros((0, 0, 0)),
        current_vt=3,
        prev_vt=2,
        current_exp=5,
        prev_exp=4,
        scalars={"imported_from": "reference"},
    ).validate()
    write_reference(s, tmp_path / "out")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(FILES)
    back = read_reference(tmp_path / "out", CFG)
    assert back.equals(s)
    # the per-template experience lists and per-experience link lists are consistent
    lines = (tmp_path / "out" / "posecellvisual_templates.txt").read_text().splitlines()
    assert lines[5] == "[0]" and lines[11] == "[1, 2]"
    ex = (tmp_path / "out" / "experiences.txt").read_text().splitlines()
    assert ex[5] == "[0, 6]" and ex[6] == "[5]"  # experience 0: from links 0, 6; to link 5


@pytest.mark.parametrize(
    ("name", "cut", "pattern"),
    [
        ("localviewcells.txt", 4, "unexpected end of file"),
        ("experiences.txt", 12, "unexpected end of file"),
        ("links.txt", 3, "unexpected end of file"),
    ],
)
def test_truncated_files_give_located_errors(tmp_path, name, cut, pattern):
    write_hand(tmp_path / "ref")
    p = tmp_path / "ref" / name
    p.write_text("\n".join(p.read_text().splitlines()[:cut]) + "\n")
    before = p.read_bytes()
    with pytest.raises(MapFormatError, match=f"{name}.*{pattern}"):
        read_reference(tmp_path / "ref", CFG)
    assert p.read_bytes() == before


def test_malformed_values_and_sizes(tmp_path):
    write_hand(tmp_path / "ref")
    with pytest.raises(MapFormatError, match=r"6 values but .* 4 x 2 = 8"):
        read_reference(tmp_path / "ref", {**CFG, "template_x_size": 4})
    p = tmp_path / "ref" / "posecellvisual_templates.txt"
    p.write_text(p.read_text().replace("[1, 2]", "[1, 2"))
    with pytest.raises(MapFormatError, match=r"line 12.*expected a list"):
        read_reference(tmp_path / "ref", CFG)
    p.write_text(p.read_text().replace("[1, 2", "[1, 2]"))
    (tmp_path / "ref" / "links.txt").unlink()
    with pytest.raises(MapFormatError, match=r"links\.txt is missing"):
        read_reference(tmp_path / "ref", CFG)


def test_export_refuses_a_directory_with_other_files(tmp_path):
    write_hand(tmp_path / "ref")
    s = read_reference(tmp_path / "ref", CFG)
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "mine.txt").write_text("keep")
    with pytest.raises(InputError, match="other than a reference map"):
        write_reference(s, tmp_path / "x")
    assert (tmp_path / "x" / "mine.txt").read_text() == "keep"


def test_a_reference_map_runs_in_the_pipeline(tmp_path):
    """Imported (no activity, no config in the files), then loaded into a RatSLAM."""
    import torch

    from torchratslam.config import load_config
    from torchratslam.maps.state import apply_state, state_from_slam
    from torchratslam.pipeline import RatSLAM

    write_hand(tmp_path / "ref")
    cfg = load_config(**CFG, vt_shift_match=0, vt_step_match=1)
    s = load_state(tmp_path / "ref")  # without a config: templates read as (1, 6)
    assert s.templates.shape == (2, 1, 6)
    slam = RatSLAM(cfg, dtype=torch.float64)
    apply_state(s, slam)
    back = state_from_slam(slam)
    assert np.array_equal(back.templates, s.templates.reshape(2, 2, 3))
    assert np.array_equal(back.exp_pose, s.exp_pose)
    assert np.array_equal(back.template_pc, s.template_pc)
    assert back.current_exp == 2 and back.activity.shape == (8, 5, 5)
    # the packet restarts at the current experience's cell
    th, y, x = np.unravel_index(np.argmax(back.activity), back.activity.shape)
    assert (x, y, th) == (2, 3, 6)
    slam.step(np.full((2, 3), 128, np.uint8), (0.1, 0.0, 1.0))  # and it keeps mapping
    assert len(slam.local_view) >= 2
