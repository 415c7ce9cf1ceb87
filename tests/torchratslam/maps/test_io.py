"""Loading any map format and converting between them (``convert_map``), on saves the
tests write in the authors' byte layout (shared/reference/reference-save-format.md):
savetxt lists (``%.18e`` values each followed by a space; an empty list is an empty
line), Python ``str()`` scalars, ``links.txt`` without a tail, an empty goal list."""

from __future__ import annotations

import logging

import pytest

from torchratslam.errors import MapFormatError
from torchratslam.maps.io import convert_map, load_state
from torchratslam.maps.reference_format import compare_texts, read_texts

CFG = {"template_x_size": 2, "template_y_size": 2, "pc_dim_xy": 5, "pc_dim_th": 8}


def savetxt(values):
    """numpy.savetxt(fh, values, newline=" ") written out by hand."""
    return "".join(f"{float(v):.18e} " for v in values)


def write_save(d, *, template_lists=([0], [1, 2]), lvc=True):
    """Two templates of 2 x 2 values, three experiences (templates 0, 1, 1), links 0->1
    and 1->2; ``template_lists`` are the experience lists posecellvisual_templates.txt
    holds (after the authors' merge, an appended template can list its experience by
    its index in the partial map: a stale list)."""
    d.mkdir()
    files = {
        "localviewcells.txt": "4\n0\n0.25\n"
        + savetxt([0.1, 0.2, 0.3, 0.4])
        + "\n1\n0.5\n"
        + savetxt([0.0, 0.5, 0.25, 0.75])
        + "\n-\n1\n0\n",
        "posecellvisual_templates.txt": "".join(
            f"{i}\n{i + 1.0}\n2.0\n3.5\n1.5\n{savetxt(lst)}\n"
            for i, lst in enumerate(template_lists)
        )
        + "-\n1\n0\n",
        "posecellexperiences.txt": "1.0\n2.0\n3.5\n0\n2.0\n2.0\n3.5\n1\n2.5\n2.0\n3.0\n1\n"
        "-\n2\n1\n",
        "experiences.txt": "0\n0.0\n0.0\n0.5\n0\n"
        + savetxt([0])
        + "\n\n0\n-1\n-1\n"
        + "1\n1.0\n0.0\n0.5\n1\n"
        + savetxt([1])
        + "\n"
        + savetxt([0])
        + "\n0\n-1\n-1\n"
        + "2\n2.0\n0.5\n0.6\n1\n\n"
        + savetxt([1])
        + "\n0\n-1\n-1\n-\n2\n1\n",
        "links.txt": "1.0\n0.0\n0.0\n1\n0\n1.5\n1.1\n0.1\n0.0\n2.0\n1.0\n3.0\n",
        "goal_list.txt": "",
    }
    if not lvc:
        del files["localviewcells.txt"]
    for name, text in files.items():
        (d / name).write_text(text)
    return d


def test_a_stale_template_experience_list_is_reported_as_changed(tmp_path, caplog):
    src = write_save(tmp_path / "merged", template_lists=([0], [0]))  # template 1: [0]
    with caplog.at_level(logging.WARNING, logger="torchratslam"):
        rep = convert_map(src, tmp_path / "native", to="native", config=CFG)
    want = "posecellvisual_templates.txt, template 1: experience list [0] -> [1, 2]"
    assert rep["changed"] == [want]
    assert "template 1 lists [0], experiences.txt gives [1, 2]" in caplog.text
    # and back: the written files differ from the source in that one field only
    back = convert_map(tmp_path / "native", tmp_path / "ref", to="reference", config=CFG)
    assert back["changed"] == []  # a native source: compared field by field, unchanged
    changes = compare_texts(read_texts(src), read_texts(tmp_path / "ref"))
    assert [c.text for c in changes] == [want] and changes[0].derived
    # a source whose lists agree with the ids converts without a change
    ok = write_save(tmp_path / "ok")
    assert convert_map(ok, tmp_path / "ok_native", to="native", config=CFG)["changed"] == []
    assert convert_map(ok, tmp_path / "ok_ref", to="reference", config=CFG)["changed"] == []
    assert compare_texts(read_texts(ok), read_texts(tmp_path / "ok_ref")) == []
    assert read_texts(ok) != read_texts(tmp_path / "ok_ref")  # ids "2.0" are written "2"


def test_any_other_value_that_does_not_survive_is_named_with_its_values(tmp_path, monkeypatch):
    import torchratslam.maps.io as mio

    src = write_save(tmp_path / "s")
    real = mio.reference_texts

    def shifted(state):  # a writer that loses the last digit of an experience's x
        texts = dict(real(state))
        texts["experiences.txt"] = texts["experiences.txt"].replace("\n2.0\n0.5\n", "\n2.5\n0.5\n")
        return texts

    monkeypatch.setattr(mio, "reference_texts", shifted)
    with pytest.raises(MapFormatError) as err:
        convert_map(src, tmp_path / "n", to="native", config=CFG)
    assert "experiences.txt, experience 2: x 2.0 -> 2.5" in str(err.value)
    assert not (tmp_path / "n").exists() and not list(tmp_path.glob(".n.*"))


def test_a_save_without_templates_is_converted_naming_only_the_users_paths(tmp_path, caplog):
    src = write_save(tmp_path / "their", lvc=False)
    dst = tmp_path / "mine"
    with caplog.at_level(logging.INFO, logger="torchratslam"):
        rep = convert_map(src, dst, to="reference", config=CFG)
    assert rep["templates_missing"] == "localviewcells.txt" and rep["templates"] == 2
    assert ".convert-" not in caplog.text and "tmp-" not in caplog.text
    assert f"{src}: localviewcells.txt is missing" in caplog.text
    assert not (dst / "localviewcells.txt").exists()
    full = load_state(write_save(tmp_path / "full"), CFG)
    assert convert_map(tmp_path / "full", tmp_path / "f2", to="native")["templates_missing"] is None
    assert full.n_templates == 2
