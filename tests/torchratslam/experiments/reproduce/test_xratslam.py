"""The xRatSLAM paper's experiments, quick versions: real behaviour of each report."""

from __future__ import annotations

import numpy as np
import pytest

from torchratslam.experiments.reproduce.catalogue import get_experiment
from torchratslam.experiments.reproduce.report import ExperimentContext, write_report


def rows(report):
    return {r.name: r for r in report.rows}


def test_openratslam_quick_agrees_with_the_cpp(tmp_path):
    report = get_experiment("xratslam/openratslam").run(ExperimentContext(tmp_path, quick=True))
    write_report(report, tmp_path)
    r = rows(report)
    same = r["loop (200 frames): frames with OpenRatSLAM's template"].ours
    assert same == 100.0  # the same template on every frame (openratslam behaviour)
    ours, cpp = r["loop (200 frames): templates, ours / OpenRatSLAM"].ours.split(" / ")
    assert ours == cpp
    sets = report.details["sets"]["loop"]
    assert sets["ours"]["wall_s"] > 0 and sets["frames"] == 200
    if report.details["build"] is not None:  # the C++ ran: the maps are the same
        assert sets["libicp_mse_m2"] < 1e-12
        assert sets["ours"]["experiences"] == sets["openratslam"]["experiences"]
    assert (tmp_path / "fig5_maps.png").is_file() or not report.figures


def test_recoded_lv_quick_reports_speed_and_map_difference(tmp_path):
    report = get_experiment("xratslam/recoded-lv").run(ExperimentContext(tmp_path, quick=True))
    write_report(report, tmp_path)
    r = rows(report)
    exact_ms = r["local view, mean per frame: exact best search"].ours
    rec_ms = r["local view, mean per frame: recoded (newest match first)"].ours
    assert r["local view speed-up"].ours == pytest.approx(exact_ms / rec_ms)
    assert r["local view speed-up"].paper == pytest.approx(14.43 / 4.79, abs=0.01)
    assert 0 <= r["frames whose template differs"].ours < 20  # mostly the same decisions
    assert r["LibICP residual, recoded map onto the exact one"].ours >= 0
    assert report.details["frames"] == 200
    # the last difference says which search was faster, with the measured times
    note = report.differences[-1]
    faster = "times faster" in note
    assert faster == (rec_ms < exact_ms) and ("slower" in note) == (not faster)
    assert f"{rec_ms:.2f} against {exact_ms:.2f} ms per frame" in note
    assert (tmp_path / "fig7_8_local_view_time.png").stat().st_size > 0


def test_odometry_quick_reports_both_ates(tmp_path):
    report = get_experiment("xratslam/odometry").run(ExperimentContext(tmp_path, quick=True))
    write_report(report, tmp_path)
    d = report.details
    wheel, visual = d["sim:lab_tour/session1 wheel"], d["sim:lab_tour/session1 visual"]
    for block in (wheel, visual):
        assert block["ate_m"] is not None and np.isfinite(block["ate_m"])
    assert wheel["ate_m"] < visual["ate_m"]  # wheel odometry closes the loop better
    assert wheel["ate_m"] < 0.5  # the map follows the 6 x 4 m rectangle
    assert (tmp_path / "fig9_odometry.png").stat().st_size > 0
