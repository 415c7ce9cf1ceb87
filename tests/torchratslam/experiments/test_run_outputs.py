"""metrics.json leaves out what a run did not measure, keeps its key order, and never
holds the scale summary; the printed line reads the same fields."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

from torchratslam.experiments.run_outputs import RunMetrics, summary_line

BASE = RunMetrics(
    frames=10,
    frames_this_run=4,
    templates=3,
    experiences=2,
    links=1,
    wall_s=2.0,
    fps=2.0,
    ms_per_frame={"pose_cells": {"mean_ms": 1.0, "median_ms": 1.0}},
    pipelined=False,
    backend="alpha",
    odometry="given",
    data="sim:loop",
    config="small.yaml",
)


def test_json_drops_unset_fields_and_the_scale_summary():
    m = replace(BASE, ate_rmse_m=0.5, partial=True, stopped_at_frame=10, reason="x")
    m = replace(m, scale={"last_over_first": 1.0, "peak_memory_mb": 2.0})
    got = m.to_json()
    want = [
        "frames", "frames_this_run", "templates", "experiences", "links", "wall_s", "fps",
        "ms_per_frame", "pipelined", "backend", "odometry", "data", "config", "ate_rmse_m",
        "partial", "stopped_at_frame", "reason",
    ]  # fmt: skip
    assert list(got) == want
    assert got["ms_per_frame"] == BASE.ms_per_frame


def test_summary_line_names_what_was_measured():
    out = Path("o")
    assert summary_line(BASE, out) == (
        "4 frames in 2.0 s (2.0 frames/s): 3 templates, 2 experiences, 1 links; wrote o"
    )
    m = replace(BASE, ate_rmse_m=0.25, dead_reckoning_ate_m=1.5, loaded=("a",), merges=[{}])
    assert summary_line(m, out).endswith(
        ", ATE 0.250 m vs dead reckoning 1.500 m, 1 merge; wrote o"
    )
    nan = replace(BASE, ate_rmse_m=math.nan, loaded=("a",), merges=[])
    assert ", ATE" not in summary_line(nan, out) and ", 0 merges" in summary_line(nan, out)


def test_a_measured_ate_names_its_alignment_and_what_it_compares():
    m = replace(BASE, ate_rmse_m=0.5, ate_frames=9).to_json()
    assert m["ate_alignment"] == "SE(2)" and m["ate_frames"] == 9
    assert m["ate_over"] == "the experience current after each frame, at the frame's time"
    assert "ate_alignment" not in BASE.to_json()  # no ground truth: no ATE to name
    line = summary_line(replace(BASE, ate_rmse_m=0.5, ate_frames=9), Path("o"))
    assert "ATE 0.500 m (SE(2)-aligned, over 9 of 10 frames with ground truth)" in line


def test_created_frames_read_from_the_arrays_are_the_graphs():
    """experiences.csv's creation frames come from the map's arrays (no networkx graph
    built for them): the same as each node's ``frame`` in the graph."""
    import numpy as np

    from ratslam_graph.experience_map import ExperienceMap
    from ratslam_graph.messages import Action, ActionKind
    from torchratslam.experiments.run_outputs import _created_frames

    em = ExperienceMap()
    frames = [3, 7, 8, 20]
    for i, frame in enumerate(frames):
        em.on_odometry(1.0, 0.3, 1.0)
        em.apply(Action(ActionKind.CREATE, dest_id=i), frame=frame)
    got = _created_frames(em, len(em))
    g = em.graph
    assert got.dtype == np.int64
    assert got.tolist() == [g.nodes[i]["frame"] for i in range(len(em))] == frames
