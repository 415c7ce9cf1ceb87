"""The multisession figures draw the maps they name."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

import torchratslam.viz.plots as plots
from torchratslam.eval.icp import libicp_point_to_point
from torchratslam.viz.multisession import _icp_overlay


def test_fig10_draws_the_multisession_map_and_the_single_session_map_moved_onto_it(
    monkeypatch,
):
    """LibICP moves the single-session map (template) onto the multisession map (model):
    the figure draws the multisession map itself, and labels the moved copy as the
    single-session map (it used to draw the single-session map twice)."""
    rng = np.random.default_rng(0)
    multi = rng.random((30, 3)) * 10
    turn = np.array([[np.cos(0.1), -np.sin(0.1)], [np.sin(0.1), np.cos(0.1)]])
    single = multi.copy()
    single[:, :2] = multi[:, :2] @ turn.T + [0.5, -0.2]
    lib = libicp_point_to_point(single[:, :2], multi[:, :2])
    data = {
        "single": SimpleNamespace(exp_pose=single),
        "multi": {"maps": [SimpleNamespace(exp_pose=multi)]},
        "libicp": lib,
    }
    seen = {}
    monkeypatch.setattr(
        plots, "draw_icp_overlay", lambda ax, f, m, **kw: seen.update(f=f, m=m, **kw)
    )
    _icp_overlay(None, data, {})
    assert seen["f"] is multi and seen["fixed_label"] == "multisession"
    assert seen["m"] is lib.aligned and seen["moved_label"].startswith("single session")
    # the moved copy is the single-session map moved: it lands on the multisession map
    assert np.abs(lib.aligned - multi[:, :2]).max() < 1e-3
