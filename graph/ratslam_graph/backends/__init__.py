"""Pose-graph relaxation backends behind one interface, chosen by name.

    backend = make_backend("alpha")            # or "alpha_reference", "gtsam", "isam2"
    new_poses = backend.relax(posegraph, passes=20, correction=0.5)

- "alpha": the RatSLAM rule (Eq. 8), vectorised over colour classes of links (fast).
- "alpha_reference": the same rule in OpenRatSLAM's order, a plain Python loop (slow).
- "alpha_wave": "alpha_local" whose wave goes on at the next call where it stopped
  (the front is carried over), waking links where a node moved by more than 1e-4.
- "alpha_local": the same rule (colour order) only on the links the change since the
  previous call reaches, sweep after sweep until it dies down: a per-frame cost that
  follows the change, not the map's size (long runs).
- "gtsam": batch Levenberg-Marquardt (ignores ``passes``).
- "isam2": incremental iSAM2; keeps its state between calls and only adds what was
  appended to the graph (rebuilds after any other change).

Every backend returns the new ``(N, 3)`` poses and never modifies the graph it is given.
gtsam is imported only when a gtsam backend (or one of the gtsam helpers re-exported
here) is first used, so the alpha rule works without loading it.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from ratslam_graph.backends.alpha import AlphaBackend, AlphaReferenceBackend
from ratslam_graph.backends.alpha_local import AlphaLocalBackend
from ratslam_graph.errors import ConfigError, unknown_name_message
from ratslam_graph.posegraph import PoseGraph


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


if TYPE_CHECKING:
    from ratslam_graph.backends.gtsam_backend import (
        GraphErrorEvaluator,
        GtsamBackend,
        ISAM2Backend,
        factor_graph,
        graph_error,
    )

# Names served by gtsam_backend, imported (with gtsam) on first access.
_GTSAM_NAMES = frozenset(
    {"GraphErrorEvaluator", "GtsamBackend", "ISAM2Backend", "factor_graph", "graph_error"}
)


def __getattr__(name: str) -> Any:
    if name in _GTSAM_NAMES:
        module = importlib.import_module("ratslam_graph.backends.gtsam_backend")
        return getattr(module, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _lazy_gtsam(class_name: str) -> Callable[..., Any]:
    """A constructor that imports the gtsam backend module only when called."""

    def build(**options: Any) -> Any:
        return __getattr__(class_name)(**options)

    build.__name__ = build.__qualname__ = class_name
    return build


BACKENDS: dict[str, Callable[..., Any]] = {
    "alpha": AlphaBackend,
    "alpha_reference": AlphaReferenceBackend,
    "alpha_local": AlphaLocalBackend,
    "alpha_wave": lambda **options: AlphaLocalBackend(**{"tol": 1e-4, **options}, carry=True),
    "gtsam": _lazy_gtsam("GtsamBackend"),
    "isam2": _lazy_gtsam("ISAM2Backend"),
}


def make_backend(name: str, **options: Any) -> Backend:
    """Create a backend by name.

    Args:
        name: "alpha", "alpha_reference", "alpha_local", "alpha_wave", "gtsam" or
            "isam2".
        **options: constructor options of that backend (e.g. ``sigmas=(0.1, 0.1, 0.05)``
            for gtsam/isam2, ``schedule="openratslam"`` (the compiled reference-order
            sweep) or ``"reference"`` for alpha).

    Raises:
        ConfigError: unknown name or option.
    """
    if name not in BACKENDS:
        raise ConfigError(unknown_name_message("pose-graph backend", name, BACKENDS))
    try:
        backend: Backend = BACKENDS[name](**options)
    except TypeError as exc:
        raise ConfigError(f"bad option for backend {name!r}: {exc}") from None
    return backend


__all__ = [
    "BACKENDS",
    "AlphaBackend",
    "AlphaLocalBackend",
    "AlphaReferenceBackend",
    "Backend",
    "GraphErrorEvaluator",
    "GtsamBackend",
    "ISAM2Backend",
    "factor_graph",
    "graph_error",
    "make_backend",
]
