"""The multisession tour's runs, as a user sees them on the command line."""

from __future__ import annotations

from torchratslam.config import load_config
from torchratslam.experiments.multisession_tour import run_tour
from torchratslam.sim import get_tour


def test_every_progress_bar_says_which_run_it_is(capsys):
    tour = get_tour("lab_tour")
    run_tour(load_config("lab_tour"), tour, progress=True, max_frames=8)
    err = capsys.readouterr().err
    n = len(tour.sessions)
    for label in ("single session", "sessions concatenated", "last session alone"):
        assert label in err, label
    for i, s in enumerate(tour.sessions):
        assert f"session {i + 1}/{n} {s.name}" in err
