"""Runs sharing one batched pose-cell network equal separate runs, bit for bit."""

import math

import pytest

from torchratslam.pose_cells.stage import PoseCells
from torchratslam.sweeps.runner import (
    TIMING_COLUMNS,
    batch_key,
    run_group,
    run_one,
    shares_network,
)
from torchratslam.sweeps.spec import from_dict
from torchratslam.sweeps.sweep import make_units

# two laps in 120 frames: the second lap re-sees old templates, so energy is injected
DATA = "sim:loop?laps=2&frames=120&lasers=0"


def _strip(row):
    return {k: v for k, v in row.items() if k not in TIMING_COLUMNS}


@pytest.mark.parametrize(
    "cells, one_network, torch_step",
    [((21, 36), True, True), ((30, 35), False, True), ((21, 36), False, False)],
    ids=["batched-network", "cropped-networks", "openratslam-behaviour"],
)
def test_batched_group_equals_separate_runs(cells, one_network, torch_step):
    xy, th = cells
    # the torch step in a batch needs a step at frame 0; OpenRatSLAM's behaviour (the
    # default: numpy step, none at frame 0) steps each run's network alone
    behaviour = {"pc_engine": "torch", "skip_first_odometry": False} if torch_step else {}
    spec = from_dict(
        {
            "base": "virtual_tour",
            "set": {
                **behaviour,
                "pc_dim_xy": xy,
                "pc_dim_th": th,
                "exp_loops": 20,
                "vt_match_threshold": 0.08,
            },
            "mode": "list",
            "parameters": {
                "pc_vt_inject_energy": [0.02, 0.3, 0.15],
                "exp_delta_pc_threshold": [4.0, 1.0, 2.0],
                "vt_active_decay": [1.5, 0.5, 1.0],
            },
            "datasets": [DATA],
            "backends": ["alpha"],
        }
    )
    runs = spec.runs()
    assert len({batch_key(r) for r in runs}) == 1  # one group
    # 21x21x36 torch networks step as one batched network; the others share the views only
    pc = runs[0].config().pose_cells
    assert shares_network(PoseCells(pc).network, pc.pc_engine) == one_network
    assert make_units(runs, workers=1) == [runs]
    batched = run_group(runs)
    separate = [run_one(r) for r in runs]
    assert [r["batch"] for r in batched] == [3] * 3
    for b, s in zip(batched, separate):
        assert b["status"] == "ok"
        assert _strip(b) == _strip(s)
        assert math.isfinite(b["ate_m"])
    # the configurations really behave differently (batching keeps them apart)
    assert len({(r["experiences"], r["links"], r["ate_m"]) for r in separate}) == 3


def test_local_view_keys_split_groups():
    spec = from_dict(
        {
            "base": "virtual_tour",
            "set": {"pc_engine": "torch", "skip_first_odometry": False},
            "parameters": {"vt_match_threshold": [0.03, 0.05], "pc_vt_inject_energy": [0.1, 0.2]},
            "datasets": [DATA],
        }
    )
    runs = spec.runs()
    assert len({batch_key(r) for r in runs}) == 2
    units = make_units(runs, workers=1)
    assert [[r.index for r in u] for u in units] == [[0, 1], [2, 3]]
    # every worker gets work: 4 runs on 4 workers are 4 units
    assert sorted(len(u) for u in make_units(runs, workers=4)) == [1, 1, 1, 1]


def test_keys_of_the_network_split_groups_in_every_profile():
    """A key the pose-cell network reads (its size) splits groups, in OpenRatSLAM's
    behaviour as in the torch step."""
    for behaviour in ({}, {"pc_engine": "torch", "skip_first_odometry": False}):
        spec = from_dict(
            {
                "base": "virtual_tour",
                "set": behaviour,
                "parameters": {"pc_dim_xy": [15, 21], "pc_vt_inject_energy": [0.02, 0.3]},
                "datasets": [DATA],
            }
        )
        assert len({batch_key(r) for r in spec.runs()}) == 2
