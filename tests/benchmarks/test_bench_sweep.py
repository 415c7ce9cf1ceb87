"""The sweep benchmark's command-line measurement: both commands run, tables compared."""

from __future__ import annotations

from benchmarks import bench_sweep


def test_measure_cli_runs_both_commands_and_compares_their_tables(tmp_path, monkeypatch):
    monkeypatch.setattr(bench_sweep, "CLI_BASES", (("virtual_tour", "virtual_tour", ""),))
    real = bench_sweep._sweep_file
    monkeypatch.setattr(bench_sweep, "_sweep_file", lambda f, b, n: real(f, b, 12))
    monkeypatch.setattr(bench_sweep, "_combos", lambda: {"exp_correction": [0.5, 0.6, 0.7]})
    (row,) = bench_sweep.measure_cli(tmp_path)
    assert row["runs"] == 3 and row["frames"] == 12 and row["equal"]
    assert 1 <= row["distinct"] <= 3
    assert row["separate_s"] > 0 and row["group_s"] > 0
    for mode in ("separate", "grouped"):
        assert (tmp_path / "sweep" / "virtual_tour" / mode / "results.csv").exists()
