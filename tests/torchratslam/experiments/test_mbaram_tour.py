"""The MBARAM tour's metrics.json: the mapper's metrics first, then the tour's settings."""

from __future__ import annotations

from pathlib import Path

from torchratslam.experiments.mbaram_tour import PAPER, MBARAMTourMetrics, summary_line

MAPPER = {
    "nodes": 6,
    "edges": 5,
    "nodes_per_lap": [6],
    "qe": 0.5,
    "qe_m": 0.25,
    "cr": 4.0,
    "localisation_rate_with_odometry": 0.9,
    "localisation_rate_without_odometry": 0.5,
}


def test_metrics_json_order_and_summary():
    m = MBARAMTourMetrics(dict(MAPPER), "sim:loop", 3, 2, 1, "sim", 1, 1, PAPER)
    got = m.to_json()
    assert list(got) == [
        *MAPPER,
        "data",
        "seed",
        "moving_obstacles",
        "moved_obstacles",
        "preset",
        "laps",
        "loc_laps",
        "paper",
    ]
    assert got["seed"] == 3 and got["paper"] == PAPER and got["nodes"] == 6
    assert summary_line("sim:loop", m, Path("o")) == (
        "MBARAM sim:loop: 6 nodes, 5 edges, nodes per lap [6], QE 0.500 (0.25 m), CR 4:1, "
        "localisation 90.0% with odometry, 50.0% without -> o"
    )
