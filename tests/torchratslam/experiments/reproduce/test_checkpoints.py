"""A long experiment's checkpoints: each finished Rawseeds set is saved in OUT, a rerun
into the same OUT resumes after it, a finished report is kept unless overwritten, and
checkpoints of other settings are refused."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from torchratslam.errors import InputError
from torchratslam.experiments.reproduce import mbaram
from torchratslam.experiments.reproduce.checkpoints import load_part, save_part
from torchratslam.experiments.reproduce.report import CHECKPOINTS, Experiment, ExperimentContext
from torchratslam.experiments.reproduce.runner import run_one

TINY = dataclasses.replace(mbaram._INDOOR, quick_frames=60)
"""The indoor experiment's quick version (a dynamic and a static set) at 60 frames a set."""


def tiny(ctx: ExperimentContext):
    return mbaram._rawseeds(TINY, ctx)


EXP = Experiment("mbaram/rawseeds-indoor", "tiny", tiny)


def counting(monkeypatch) -> list:
    calls: list = []
    real = mbaram._run

    def run(map_laps, loc_laps, preset):
        calls.append(preset)
        return real(map_laps, loc_laps, preset)

    monkeypatch.setattr(mbaram, "_run", run)
    return calls


def test_a_part_round_trips_and_another_key_is_refused(tmp_path):
    arrays = {"a.xy": np.arange(6.0).reshape(3, 2), "a.edges": np.array([[0, 1]], np.int64)}
    save_part(tmp_path, "set_1", {"seed": 1}, {"n": 3, "x": [0.5, float("nan")]}, arrays)
    data, got = load_part(tmp_path, "set_1", {"seed": 1})
    assert data["n"] == 3 and data["x"][0] == 0.5 and np.isnan(data["x"][1])
    assert set(got) == set(arrays)
    for k, v in arrays.items():
        assert np.array_equal(got[k], v) and got[k].dtype == v.dtype
    assert load_part(tmp_path, "set_2", {"seed": 1}) is None
    with pytest.raises(InputError, match="another run"):
        load_part(tmp_path, "set_1", {"seed": 2})
    (tmp_path / CHECKPOINTS / "set_1.npz").write_bytes(b"not an npz")
    with pytest.raises(InputError, match="damaged"):
        load_part(tmp_path, "set_1", {"seed": 1})


def test_a_stopped_run_resumes_without_redoing_its_finished_sets(tmp_path, monkeypatch):
    calls = counting(monkeypatch)
    first = run_one(EXP, tmp_path, quick=True)
    sets = list(first.details["runs"]["recommended"])
    assert len(sets) == 2 and len(calls) == 4  # two sets, two settings each
    for d in sets:
        assert (tmp_path / CHECKPOINTS / f"{d}.json").exists()
        assert (tmp_path / CHECKPOINTS / f"{d}.npz").exists()
    # a finished report is never overwritten without --overwrite
    with pytest.raises(InputError, match="already holds a report"):
        run_one(EXP, tmp_path, quick=True)
    # a run stopped during the second set: its report and that set's checkpoint absent
    for f in ("report.json", "report.md"):
        (tmp_path / f).unlink()
    (tmp_path / CHECKPOINTS / f"{sets[1]}.json").unlink()
    calls.clear()
    second = run_one(EXP, tmp_path, quick=True)
    assert len(calls) == 2  # only the unfinished set ran again
    assert second.rows == first.rows

    def measured(report):  # every number but the seconds taken
        runs = report.details["runs"]
        return {s: {d: {**m, "seconds": 0} for d, m in r.items()} for s, r in runs.items()}

    assert measured(second) == measured(first)
    # the resumed set's numbers are the saved ones, in the same order
    d0 = sets[0]
    assert second.details["runs"]["recommended"][d0] == first.details["runs"]["recommended"][d0]
    assert list(second.details["runs"]["recommended"][d0]) == list(
        first.details["runs"]["recommended"][d0]
    )
    # --overwrite redoes every set
    calls.clear()
    third = run_one(EXP, tmp_path, quick=True, overwrite=True)
    assert len(calls) == 4
    assert third.rows == first.rows


def test_checkpoints_of_another_seed_are_refused(tmp_path, monkeypatch):
    calls = counting(monkeypatch)
    run_one(EXP, tmp_path, quick=True)
    (tmp_path / "report.json").unlink()
    with pytest.raises(InputError, match="another run"):
        run_one(EXP, tmp_path, quick=True, seed=1)
    saved = json.loads(next((tmp_path / CHECKPOINTS).glob("*.json")).read_text())
    assert saved["key"]["seed"] == 1  # the first set's simulator seed at --seed 0
    assert len(calls) == 4
