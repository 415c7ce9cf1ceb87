"""Typed interfaces of the torch-free pluggable stages: the experience map and the
relaxation backend it calls.

They are ``runtime_checkable`` so that code handed a module can check it with
``isinstance`` (which tests that the named methods and attributes exist) instead of
probing attribute by attribute; the torch-side stages are in
:mod:`torchratslam.protocols`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from ratslam_graph.messages import Action
from ratslam_graph.posegraph import PoseGraph

if TYPE_CHECKING:
    import networkx as nx

__all__ = ["ExperienceMapModule", "RelaxationBackend", "Stateful"]


@runtime_checkable
class Stateful(Protocol):
    """A module whose whole state is a dict of numpy arrays and Python scalars."""

    def get_state(self) -> dict[str, Any]:
        """Everything needed to resume (arrays and scalars only)."""
        ...

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`get_state`'s output."""
        ...


@runtime_checkable
class RelaxationBackend(Protocol):
    """What :meth:`ExperienceMap.iterate` needs from a backend (see
    ``ratslam_graph.backends.Backend`` for the full interface)."""

    def relax(self, pg: PoseGraph, *, passes: int, correction: float = 0.5) -> np.ndarray:
        """Return the relaxed (N, 3) poses of ``pg``."""
        ...


@runtime_checkable
class ExperienceMapModule(Protocol):
    """The experience-map stage: odometry in, pose-cell actions in, map out.

    Saving a map also needs :class:`Stateful` (``get_state`` / ``set_state``).
    """

    current_id: int

    def __len__(self) -> int:
        """Number of experiences."""
        ...

    @property
    def num_links(self) -> int:
        """Number of links."""
        ...

    @property
    def poses(self) -> np.ndarray:
        """Experience poses ``[x, y, th]`` (row = experience id). Shape: ``(N, 3)``."""
        ...

    @property
    def graph(self) -> nx.DiGraph:
        """The map as a :class:`networkx.DiGraph` (read-only)."""
        ...

    def on_odometry(self, vtrans: float, vrot: float, dt: float) -> None:
        """Accumulate one interval of odometry."""
        ...

    def apply(
        self,
        action: Action,
        *,
        frame: int,
        t: float,
        pc: tuple[float, float, float],
        template_id: int,
    ) -> Any:
        """Create, link or jump to an experience as the pose cells' action says."""
        ...

    def iterate(self) -> Any:
        """Relax the map (graph correction)."""
        ...
