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
    assert "its runs took 0 min" in page  # 3.2 s (the failed run's 0.1 s not counted)
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


def _write(results, exp, figures, quick):
    folder = results / exp
    folder.mkdir(parents=True)
    for f in figures:
        (folder / f).write_bytes(b"\x89PNG " + f.encode())
    rep = Report(
        exp, exp.split("/")[0], exp, (Row("n", 1, 2),), tuple(figures), ("d",), quick=quick
    )
    write_report(rep, folder)
    return {"experiment": exp, "folder": exp, "seconds": 1.0, "error": None, "rows": None}


def test_page_shows_the_first_figures_and_names_which_runs_are_quick(tmp_path):
    """Full and quick runs on one page: the note names the quick ones; each experiment
    shows its first PAGE_FIGURES figures and names the rest (nothing else copied)."""
    from torchratslam.experiments.reproduce.docs_page import PAGE_FIGURES

    results = tmp_path / "papers"
    many = [f"f{i}.png" for i in range(PAGE_FIGURES + 2)]
    index = [
        _write(results, "multisession/virtual-tour", many, quick=False),
        _write(results, "edge/adaptation", ["a.png"], quick=True),
    ]
    (results / "index.json").write_text(json.dumps(index))
    img = tmp_path / "img"
    page = write_page(results, tmp_path / "p.md", img).read_text()
    assert "except `edge/adaptation`" in page and "This page shows the quick versions" not in page
    assert "--run --quick --out" in page  # a quick run on the page: regenerated quick
    assert "(full version, seed 0" in page and "(quick version, seed 0" in page
    copied = sorted(p.name for p in img.iterdir())
    assert copied == sorted(
        [f"multisession_virtual-tour_{f}" for f in many[:PAGE_FIGURES]] + ["edge_adaptation_a.png"]
    )
    assert f"`{many[-1]}`" in page and f"`{many[-2]}`" in page and "not copied here" in page
    # only full runs: no note, and the command to regenerate it has no --quick
    (results / "index.json").write_text(json.dumps(index[:1]))
    page = write_page(results, tmp_path / "p.md", img).read_text()
    assert "!!! note" not in page and "docs_page --run --out out/papers" in page


def test_a_png_figure_is_copied_with_a_palette_and_the_same_pixels(tmp_path):
    """A plot-like PNG (few colours) comes out as a palette PNG with identical pixels;
    a file PIL cannot read is copied byte for byte."""
    import numpy as np
    from PIL import Image

    from torchratslam.experiments.reproduce.docs_page import copy_figure

    rgb = np.full((60, 80, 3), 255, np.uint8)
    rgb[10:20, :, :] = (31, 119, 180)  # a blue band
    rgb[:, 40:42, :] = (255, 127, 14)  # an orange line
    Image.fromarray(rgb).save(tmp_path / "plot.png")
    out = copy_figure(tmp_path / "plot.png", tmp_path / "copy.png")
    with Image.open(out) as im:
        assert im.mode == "P" and im.size == (80, 60)
        assert np.array_equal(np.asarray(im.convert("RGB")), rgb)
    (tmp_path / "bad.png").write_bytes(b"\x89PNG broken")
    assert copy_figure(tmp_path / "bad.png", tmp_path / "b2.png").read_bytes() == b"\x89PNG broken"
