"""Pose-graph relaxation backends behind one interface, chosen by name.

    backend = make_backend("alpha")            # or "alpha_reference", "gtsam", "isam2"
    new_poses = backend.relax(posegraph, passes=20, correction=0.5)

- "alpha": the RatSLAM rule (Eq. 8), vectorised over colour classes of links (fast).
- "alpha_reference": the same rule in OpenRatSLAM's order, a plain Python loop (slow).
- "gtsam": batch Levenberg-Marquardt (ignores ``passes``).
- "isam2": incremental iSAM2; keeps its state between calls and only adds what was
  appended to the graph (rebuilds after any other change).

Every backend returns the new ``(N, 3)`` poses and never modifies the graph it is given.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np
from torchratslam.graph.backends.alpha import AlphaBackend, AlphaReferenceBackend
from torchratslam.graph.backends.gtsam_backend import (
    GraphErrorEvaluator,
    GtsamBackend,
    ISAM2Backend,
    factor_graph,
    graph_error,
)
from torchratslam.graph.errors import ConfigError, unknown_name_message
from torchratslam.graph.posegraph import PoseGraph


@runtime_checkable
class Backend(Protocol):
    """What every relaxation backend provides."""

    name: str
    incremental: bool

    def relax(self, pg: PoseGraph, *, passes: int, correction: float = 0.5) -> np.ndarray:
        """Return the relaxed (N, 3) poses of ``pg`` (alpha: ``passes`` passes)."""
        ...

    def reset(self) -> None:
        """Forget any state kept between calls."""
        ...


BACKENDS: dict[str, type] = {
    "alpha": AlphaBackend,
    "alpha_reference": AlphaReferenceBackend,
    "gtsam": GtsamBackend,
    "isam2": ISAM2Backend,
}


def make_backend(name: str, **options: Any) -> Backend:
    """Create a backend by name.

    Args:
        name: "alpha", "alpha_reference", "gtsam" or "isam2".
        **options: constructor options of that backend (e.g. ``sigmas=(0.1, 0.1, 0.05)``
            for gtsam/isam2, ``schedule="openratslam"`` (the compiled reference-order
            sweep) or ``"reference"`` for alpha).

    Raises:
        ConfigError: unknown name or option.
    """
    if name not in BACKENDS:
        raise ConfigError(unknown_name_message("pose-graph backend", name, BACKENDS))
    try:
        return BACKENDS[name](**options)
    except TypeError as exc:
        raise ConfigError(f"bad option for backend {name!r}: {exc}") from None


__all__ = [
    "BACKENDS",
    "AlphaBackend",
    "AlphaReferenceBackend",
    "Backend",
    "GraphErrorEvaluator",
    "GtsamBackend",
    "ISAM2Backend",
    "factor_graph",
    "graph_error",
    "make_backend",
]
