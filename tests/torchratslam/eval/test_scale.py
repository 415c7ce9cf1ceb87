"""The scale report: per-tenth costs and map sizes, for torchratslam and OpenRatSLAM."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from torchratslam.errors import InputError
from torchratslam.eval.scale import (
    format_scale_table,
    peak_memory_mb,
    read_openratslam_trace,
    scale_report,
)


def test_scale_report_matches_a_loop_over_the_spans():
    rng = np.random.default_rng(0)
    n, parts = 103, 10
    ms = {"local_view": rng.uniform(1, 2, n), "pose_cells": rng.uniform(0, 1, n)}
    templates = np.cumsum(rng.integers(0, 2, n))
    rep = scale_report(ms, {"templates": templates}, parts=parts)
    assert rep["frames"] == n and len(rep["parts"]) == parts
    covered = []
    for row in rep["parts"]:
        idx = list(range(row["first"], row["last"] + 1))
        covered += idx
        for module, values in ms.items():
            assert row["ms"][module] == pytest.approx(sum(values[i] for i in idx) / len(idx))
        total = sum(ms["local_view"][i] + ms["pose_cells"][i] for i in idx) / len(idx)
        assert row["ms"]["total"] == pytest.approx(total)
        assert row["templates"] == templates[row["last"]]
    assert covered == list(range(n))  # the spans cut the run without gap or overlap
    first, last = rep["parts"][0]["ms"], rep["parts"][-1]["ms"]
    assert rep["last_over_first"]["total"] == pytest.approx(last["total"] / first["total"])
    table = format_scale_table(rep, title="t")
    assert table.count("\n| ") == parts + 1 and "last tenth / first tenth" in table


def test_a_cost_that_grows_with_the_map_shows_in_the_ratio():
    n = 1000
    ms = {"experience_map": 0.01 * np.arange(n) + 1.0}  # linear in the map size
    rep = scale_report(ms, {"experiences": np.arange(n)})
    assert rep["last_over_first"]["experience_map"] == pytest.approx(10.495 / 1.495)


def test_bad_arrays_are_refused_with_one_line():
    with pytest.raises(InputError, match="differ in length"):
        scale_report({"a": np.ones(20)}, {"templates": np.ones(19)})
    with pytest.raises(InputError, match="cannot be cut"):
        scale_report({"a": np.ones(5)}, {"templates": np.ones(5)})


def test_openratslam_trace_is_read_like_the_projects_own(tmp_path):
    rows = ["frame,lv_ms,pc_ms,em_ms,total_ms,vt_id,vt_rad,current_exp_id"]
    vt = [0, 1, 1, 2, 0, 3, 3, 4, 2, 5]
    exp = [0, 0, 1, 2, 2, 3, 1, 4, 5, 5]
    for k in range(10):
        rows.append(f"{k},{k + 1},{0.5},{0.1 * k},{k + 1.5 + 0.1 * k},{vt[k]},0,{exp[k]}")
    path = tmp_path / "frames.csv"
    path.write_text("\n".join(rows) + "\n")
    rep = read_openratslam_trace(path, parts=5)
    assert [r["templates"] for r in rep["parts"]] == [2, 3, 4, 5, 6]
    assert [r["experiences"] for r in rep["parts"]] == [1, 3, 4, 5, 6]
    assert rep["parts"][0]["ms"]["local_view"] == pytest.approx(1.5)
    with pytest.raises(InputError, match="no OpenRatSLAM trace"):
        read_openratslam_trace(tmp_path / "missing.csv")


def test_run_records_the_scale_report(tmp_path):
    from torchratslam.cli import main

    out = tmp_path / "out"
    code = main(
        [
            "run",
            "--config",
            "suburb",
            "--data",
            "sim:suburb?frames=60",
            "--out",
            str(out),
            "--no-progress",
            "--scale-report",
        ]
    )
    assert code == 0
    rep = json.loads((out / "scale.json").read_text())
    assert len(rep["parts"]) == 10 and rep["frames"] == 60
    assert rep["parts"][-1]["links"] == json.loads((out / "metrics.json").read_text())["links"]
    assert rep["peak_memory_mb"] > 0
    assert (out / "scale.png").stat().st_size > 1000 and (out / "scale.md").exists()


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="Linux /proc")
def test_peak_memory_is_the_programs_own_not_its_parents():
    """``ru_maxrss`` survives ``exec``: a child of a large process would report the
    parent's peak. The child here reads its own high-water mark."""
    big = np.ones(400 * 1024 * 1024 // 8)
    big += 1  # touch every page
    code = "from torchratslam.eval.scale import peak_memory_mb; print(peak_memory_mb())"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    child = float(done.stdout.strip())
    assert 0 < child < peak_memory_mb() - 300, (child, peak_memory_mb())
    del big
