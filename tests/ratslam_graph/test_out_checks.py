"""The OUT checks every writing command shares: a directory new, empty or holding its
own kind; a single output file never an input, never another command's recorded file,
an existing one replaced only when asked."""

from __future__ import annotations

import pytest

from ratslam_graph.atomic import Manifest
from ratslam_graph.errors import InputError
from ratslam_graph.out_checks import check_out_dir, check_out_file


def test_a_directory_is_new_empty_or_its_own_kind(tmp_path):
    assert check_out_dir(tmp_path / "new", what="sweep", marks=("results.csv",)) is False
    empty = tmp_path / "empty"
    empty.mkdir()
    assert check_out_dir(empty, what="sweep", marks=("results.csv",)) is False
    own = tmp_path / "own"
    own.mkdir()
    (own / "results.csv").write_text("x")
    assert check_out_dir(own, what="sweep", marks=("results.csv",)) is True
    other = tmp_path / "other"
    other.mkdir()
    for i in range(5):
        (other / f"f{i}.txt").write_text("x")
    with pytest.raises(InputError, match=r"holds no sweep \(it holds f0.txt, f1.txt, f2.txt"):
        check_out_dir(other, what="sweep", marks=("results.csv",))
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match="not a directory"):
        check_out_dir(tmp_path / "file", what="sweep", marks=("results.csv",))


def test_an_output_file_never_an_input_nor_recorded_and_replaced_only_when_asked(tmp_path):
    flag = ("--json", "json")
    check_out_file(None, inputs=(), flag=flag)
    check_out_file(tmp_path / "new.json", inputs=(), flag=flag)  # a new file is fine
    data = tmp_path / "data"
    data.mkdir()
    for target in (data, data / "x.json"):
        with pytest.raises(InputError):
            check_out_file(target, inputs=(data,), flag=flag, overwrite=True)
    recorded = tmp_path / "run"
    recorded.mkdir()
    (recorded / "metrics.json").write_text("{}")
    Manifest(recorded).add(["metrics.json"])
    with pytest.raises(InputError, match="manifest"):
        check_out_file(recorded / "metrics.json", inputs=(), flag=flag, overwrite=True)
    mine = tmp_path / "mine.json"
    mine.write_text("mine")
    with pytest.raises(InputError, match="exists") as info:
        check_out_file(mine, inputs=(), flag=flag)
    assert "overwrite=True" in str(info.value) and "--overwrite" in info.value.cli_message()
    check_out_file(mine, inputs=(), flag=flag, overwrite=True)
    assert mine.read_text() == "mine"  # a check writes nothing
