"""``torchratslam reproduce``: the catalogue, the reports and the command."""

import json

import pytest

from torchratslam.cli import main
from torchratslam.errors import InputError
from torchratslam.experiments.reproduce import catalogue
from torchratslam.experiments.reproduce.report import (
    Experiment,
    ExperimentContext,
    Report,
    Row,
    report_markdown,
    write_report,
)
from torchratslam.experiments.reproduce.runner import run_all, run_one


def _fake_run(ctx: ExperimentContext) -> Report:
    (ctx.out / "fig.png").write_bytes(b"png")
    return Report(
        experiment="xratslam/fake",
        paper="xratslam",
        title="a fake experiment",
        rows=(Row("run time", 245.0, 121.5, "s"), Row("templates", None, 12)),
        figures=("fig.png",),
        differences=("simulated data",),
        details={"nan": float("nan"), "seed": ctx.seed, "quick": ctx.quick},
        quick=ctx.quick,
        seed=ctx.seed,
    )


def _failing_run(ctx: ExperimentContext) -> Report:
    raise InputError("no data for this one")


@pytest.fixture
def fake_catalogue(monkeypatch):
    import types

    ok = types.ModuleType("ok")
    ok.EXPERIMENTS = (Experiment("xratslam/fake", "a fake experiment", _fake_run),)
    bad = types.ModuleType("bad")
    bad.EXPERIMENTS = (Experiment("mbaram/broken", "always fails", _failing_run),)
    monkeypatch.setattr(catalogue, "MODULES", (ok, bad))


def test_an_id_names_its_paper():
    with pytest.raises(InputError, match="<paper>/<name>"):
        Experiment("nopaper", "t", _fake_run)
    with pytest.raises(InputError, match="<paper>/<name>"):
        Experiment("physics/x", "t", _fake_run)
    assert Experiment("edge/goal-recall", "t", _fake_run).paper == "edge"


def test_the_report_json_holds_rows_beside_the_papers(tmp_path):
    report = _fake_run(ExperimentContext(out=tmp_path, quick=True, seed=3))
    js, md = write_report(report, tmp_path)
    data = json.loads(js.read_text())
    assert data["experiment"] == "xratslam/fake" and data["paper"] == "xratslam"
    assert data["rows"][0] == {"name": "run time", "paper": 245.0, "ours": 121.5, "unit": "s"}
    assert data["rows"][1]["paper"] is None
    assert data["figures"] == ["fig.png"] and data["details"]["nan"] is None
    text = md.read_text()
    assert "| run time | 245 s | 121.5 s |" in text and "| templates | – | 12 |" in text
    assert "simulated data" in text and "![fig](fig.png)" in text
    assert report_markdown(report) == text


def test_a_report_naming_a_missing_figure_is_refused(tmp_path):
    report = Report("xratslam/x", "xratslam", "t", rows=(), figures=("absent.png",))
    with pytest.raises(InputError, match=r"absent\.png"):
        write_report(report, tmp_path)


def test_run_one_never_overwrites_a_report(tmp_path, fake_catalogue):
    run_one("xratslam/fake", tmp_path / "a", seed=2)
    with pytest.raises(InputError, match="--overwrite"):
        run_one("xratslam/fake", tmp_path / "a")
    assert run_one("xratslam/fake", tmp_path / "a", overwrite=True).seed == 0
    with pytest.raises(InputError, match="did you mean 'xratslam/fake'"):
        run_one("xratslam/fak", tmp_path / "b")


def test_run_all_records_failures_and_goes_on(tmp_path, fake_catalogue):
    outcomes = run_all(tmp_path, quick=True)
    assert [o.experiment for o in outcomes] == ["xratslam/fake", "mbaram/broken"]
    assert outcomes[0].report is not None and outcomes[1].error == "no data for this one"
    index = json.loads((tmp_path / "index.json").read_text())
    assert index[0]["rows"][0]["ours"] == 121.5 and index[1]["rows"] is None
    assert (tmp_path / "xratslam/fake/report.md").is_file()
    assert "failed: no data for this one" in (tmp_path / "index.md").read_text()


def test_a_second_reproduce_all_refuses_and_keeps_the_first(tmp_path, fake_catalogue, capsys):
    assert main(["reproduce", "all", "--out", str(tmp_path), "--quick"]) == 1  # one fails
    files = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    capsys.readouterr()
    assert main(["reproduce", "all", "--out", str(tmp_path), "--quick"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "already holds" in err[0] and "--overwrite" in err[0] and "--debug" in err[-1]
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == files
    assert main(["reproduce", "all", "--out", str(tmp_path), "--quick", "--overwrite"]) == 1


def test_the_command_lists_runs_and_fails_clearly(tmp_path, fake_catalogue, capsys):
    assert main(["reproduce", "--list"]) == 0
    assert capsys.readouterr().out.splitlines() == [
        "xratslam/fake\ta fake experiment",
        "mbaram/broken\talways fails",
    ]
    assert main(["reproduce", "xratslam/fake", "--out", str(tmp_path / "r"), "--quick"]) == 0
    assert "| run time | 245 s | 121.5 s |" in capsys.readouterr().out
    assert main(["reproduce", "xratslam/fake"]) == 2
    assert "--out is required" in capsys.readouterr().err
    assert main(["reproduce", "all", "--out", str(tmp_path / "all")]) == 1
    assert "1 of 2 experiments ran" in capsys.readouterr().out


def test_every_catalogued_experiment_has_a_unique_id():
    ids = list(catalogue.all_experiments())
    assert len(ids) == len(set(ids))
