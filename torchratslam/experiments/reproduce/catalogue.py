"""Every reproducible experiment, listed in one static place.

An experiment module defines ``EXPERIMENTS: tuple[Experiment, ...]``; add the module
to :data:`MODULES` below and its experiments appear in ``torchratslam reproduce``.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType, ModuleType

from ratslam_graph.errors import unknown_name_message
from torchratslam.errors import InputError
from torchratslam.experiments.reproduce import (
    edge,
    edge_goal_memory,
    edge_long,
    mbaram,
    multisession,
    robodeck,
    xratslam,
)
from torchratslam.experiments.reproduce.report import Experiment

__all__ = ["all_experiments", "get_experiment"]

MODULES: tuple[ModuleType, ...] = (
    edge,
    edge_goal_memory,
    edge_long,
    mbaram,
    multisession,
    xratslam,
    robodeck,
)
"""The experiment modules (each with an ``EXPERIMENTS`` tuple), in the listing's order."""


def all_experiments() -> Mapping[str, Experiment]:
    """Every experiment by id, in the catalogue's order.

    Raises:
        InputError: two experiments share an id.
    """
    found: dict[str, Experiment] = {}
    for module in MODULES:
        for exp in vars(module)["EXPERIMENTS"]:
            if exp.id in found:
                raise InputError(f"two experiments named {exp.id!r}")
            found[exp.id] = exp
    return MappingProxyType(found)


def get_experiment(name: str) -> Experiment:
    """The experiment called ``name``.

    Raises:
        InputError: no such experiment (with the closest ids).
    """
    known = all_experiments()
    if name not in known:
        raise InputError(unknown_name_message("experiment", name, list(known)))
    return known[name]
