"""The "Reproducing the papers" page from a ``reproduce all`` folder."""

from __future__ import annotations

import json

import pytest

from torchratslam.errors import InputError
from torchratslam.experiments.reproduce.docs_page import main, write_page
from torchratslam.experiments.reproduce.report import Report, Row, write_report


def test_page_has_every_table_difference_and_figure(tmp_path):
    results = tmp_path / "papers"
    ok = results / "xratslam" / "recoded-lv"
    ok.mkdir(parents=True)
    (ok / "fig8.png").write_bytes(b"\x89PNG fake")
    rep = Report(
        "xratslam/recoded-lv",
        "xratslam",
        "RecodedLV",
        (Row("local view", 4.79, 2.5, "ms"), Row("frames differing", None, 1.5, "%")),
        ("fig8.png",),
        ("simulated data, not the iRat",),
        quick=True,
    )
    write_report(rep, ok)
    index = [
        {
            "experiment": "xratslam/recoded-lv",
            "folder": "xratslam/recoded-lv",
            "seconds": 3.2,
            "error": None,
            "rows": None,
        },
        {
            "experiment": "multisession/lab-tour",
            "folder": "multisession/lab-tour",
            "seconds": 0.1,
            "error": "no such data",
            "rows": None,
        },
    ]
    (results / "index.json").write_text(json.dumps(index))
    docs = tmp_path / "docs"
    (docs / "img" / "reproduce").mkdir(parents=True)
    (docs / "img" / "reproduce" / "stale.png").write_bytes(b"old")
    page = write_page(results, docs / "reproducing.md", docs / "img" / "reproduce").read_text()
    assert page.startswith("# Reproducing the papers")
    assert "| local view | 4.79 ms | 2.5 ms |" in page and "| frames differing | – | 1.5% |" in page
    assert "- simulated data, not the iRat" in page and "quick versions" in page
    assert "![xratslam/recoded-lv: fig8](img/reproduce/xratslam_recoded-lv_fig8.png)" in page
    assert (docs / "img" / "reproduce" / "xratslam_recoded-lv_fig8.png").read_bytes() == (
        b"\x89PNG fake"
    )
    assert not (docs / "img" / "reproduce" / "stale.png").exists()
    assert "Failed: no such data" in page
    # papers in the catalogue's order: multisession before xratslam
    assert page.index("Multi-session mapping") < page.index("xRatSLAM")


def test_needs_a_finished_run(tmp_path, capsys):
    with pytest.raises(InputError, match=r"index\.json"):
        write_page(tmp_path, tmp_path / "p.md", tmp_path / "img")
    with pytest.raises(SystemExit):
        main([])
