"""The multisession tour's runs, as a user sees them on the command line."""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest

from torchratslam.config import load_config
from torchratslam.experiments.multisession_report import report_markdown
from torchratslam.experiments.multisession_tour import run_tour
from torchratslam.sim import get_tour


@pytest.fixture(scope="module")
def lab_tour_run():
    """A short lab-tour run with progress bars, and what it wrote to stderr."""
    tour = get_tour("lab_tour")
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        out = run_tour(load_config("lab_tour"), tour, progress=True, max_frames=8)
    return tour, out, err.getvalue()


def test_every_progress_bar_says_which_run_it_is(lab_tour_run):
    tour, _, err = lab_tour_run
    n = len(tour.sessions)
    for label in ("single session", "sessions concatenated", "last session alone"):
        assert label in err, label
    for i, s in enumerate(tour.sessions):
        assert f"session {i + 1}/{n} {s.name}" in err


def test_the_report_says_which_map_the_papers_icp_moves(lab_tour_run):
    """The paper's figure moves the single-session map (LibICP's template) onto the
    multisession map (its model)."""
    _, out, _ = lab_tour_run
    text = report_markdown(out["report"])
    assert "the single-session map moved onto the multisession map" in text


def test_the_report_ate_counts_only_experiences_with_ground_truth_and_names_its_alignment(
    small_run,
):
    from torchratslam.experiments.compare_maps import load_groundtruth
    from torchratslam.experiments.multisession_report import ATE_NOTE
    from torchratslam.experiments.multisession_tour import _map_metrics
    from torchratslam.maps.io import load_state

    state = load_state(small_run.out)
    gt = load_groundtruth("sim:loop?laps=1&frames=40")
    full = _map_metrics(state, gt)
    assert full["ate_poses"] == state.n_experiences and full["ate_alignment"] == "SE(2)"
    part = gt[gt[:, 0] <= float(np.quantile(state.exp_t, 0.6))]
    m = _map_metrics(state, part)
    n = int((state.exp_t <= part[-1, 0] + 1e-9).sum())
    assert m["ate_poses"] == n < state.n_experiences  # none clamped to the last pose
    two = part[part[:, 0] <= float(np.sort(state.exp_t)[1])]
    assert _map_metrics(state, two)["ate_rmse_m"] is None  # under 3 poses: undefined
    assert "SE(2) alignment" in ATE_NOTE and "creation time" in ATE_NOTE
