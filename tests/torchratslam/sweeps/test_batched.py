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


def _count_calls(monkeypatch, owner, name):
    calls = []
    original = getattr(owner, name)

    def counted(self, *args, **kwargs):
        calls.append(id(self))
        return original(self, *args, **kwargs)

    monkeypatch.setattr(owner, name, counted)
    return calls


def test_runs_with_the_same_inputs_share_their_work(monkeypatch):
    """One lap re-sees no template, so the injected energy cannot act: the runs that
    differ only in it compute the same pose cells and the same map. The group steps one
    pose-cell module per distinct set of pose-cell keys and replays one map per distinct
    set of inputs and keys, and every row still equals its separate run's."""
    import torchratslam.sweeps.replay as replay

    spec = from_dict(
        {
            "base": "virtual_tour",
            "set": {"exp_loops": 20},
            "parameters": {
                "pc_vt_inject_energy": [0.05, 0.3, 0.05],
                "exp_correction": [0.5, 0.7],
            },
            "datasets": ["sim:loop?laps=1&frames=40&lasers=0"],
        }
    )
    runs = spec.runs()
    assert len(runs) == 6 and len({batch_key(r) for r in runs}) == 1
    separate = [_strip(run_one(r)) for r in runs]
    by_correction = {}
    for r, s in zip(runs, separate):  # the energy is inert here: one map per correction
        by_correction.setdefault(r.params["exp_correction"], []).append(
            {k: v for k, v in s.items() if k not in ("index", "run_id", "pc_vt_inject_energy")}
        )
    assert all(all(m == maps[0] for m in maps) for maps in by_correction.values())
    assert by_correction[0.5][0] != by_correction[0.7][0]
    replays = _count_calls(monkeypatch, replay._ReplayPoseCells, "__init__")
    steps = _count_calls(monkeypatch, PoseCells, "on_odometry")
    grouped = run_group(runs)
    assert [_strip(g) for g in grouped] == separate
    assert len(replays) == 2  # one map per exp_correction
    # two distinct pose-cell configurations (0.05 twice), each stepped once a frame
    assert len(set(steps)) == 2
    assert len(steps) == 2 * (separate[0]["frames"] - 1)  # no step at frame 0
