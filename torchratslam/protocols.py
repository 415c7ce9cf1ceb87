"""Typed interfaces of the pluggable stages, one small ``Protocol`` per stage.

The data flow (see ``docs/DEVELOPING.md``) is::

    FrameSource -> OdometrySource + LocalViewModule -> PoseCellModule
        -> ExperienceMapModule -> RelaxationBackend

The registries in :mod:`torchratslam.registry` are typed with these protocols and check
what they build with ``isinstance`` (the protocols are ``runtime_checkable``: the check
is that the named methods and attributes exist), and the map-state code talks to the
modules only through them. The torch-free ones (experience map, relaxation backend,
:class:`Stateful`) live in :mod:`ratslam_graph.protocols` and are re-exported here.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from ratslam_graph.messages import Action
from ratslam_graph.protocols import ExperienceMapModule, RelaxationBackend, Stateful
from torchratslam.messages import Frame, SessionState, ViewMatch

if TYPE_CHECKING:  # annotations only: importing the protocols does not load torch
    import torch

    from torchratslam.config import RatSLAMConfig

__all__ = [
    "ExperienceMapModule",
    "FrameSource",
    "GroundTruthSource",
    "InjectionAngle",
    "LocalViewModule",
    "OdometrySource",
    "PoseCellModule",
    "RangeMapper",
    "RelaxationBackend",
    "SlamSystem",
    "Stateful",
]


@runtime_checkable
class LocalViewModule(Protocol):
    """The local-view stage: an observation in, the matched (or new) template out.

    Saving a map also needs :class:`Stateful` (``get_state`` / ``set_state``).
    """

    def process(self, observation: Any, frame_index: int | None = None) -> ViewMatch:
        """Match one observation; learn a new template when nothing matches."""
        ...

    def __len__(self) -> int:
        """Number of templates."""
        ...

    @property
    def templates(self) -> torch.Tensor:
        """All templates. Shape: ``(N, Y, X)``."""
        ...


@runtime_checkable
class PoseCellModule(Protocol):
    """The pose-cell stage: view matches and odometry in, experience-map actions out.

    Saving a map also needs :class:`Stateful` (``get_state`` / ``set_state``).
    """

    def on_view_template(self, match: ViewMatch) -> None:
        """Inject the energy of a matched template (or learn the association)."""
        ...

    def on_odometry(self, vtrans: float, vrot: float, dt: float) -> Action:
        """Integrate one interval of odometry and decide the experience-map action."""
        ...

    @property
    def activity(self) -> torch.Tensor:
        """The activity. Shape: ``(TH, Y, X)``."""
        ...

    @property
    def centre(self) -> Any:
        """The packet centre ``(x, y, th)`` in cells (a property, or a method to call)."""
        ...


@runtime_checkable
class InjectionAngle(Protocol):
    """A pose-cell stage that knows the heading of its last view injection.

    Optional beyond :class:`PoseCellModule`: with ``general.action_angle ==
    "injection"`` the pipeline gives the experience map the angle
    ``vt_delta_pc_th * 2 pi / dims[2]`` of a stage that has these members (OpenRatSLAM's
    ``get_relative_rad``), and the action's own angle otherwise.
    """

    dims: tuple[int, int, int]
    """The network's size ``(X, Y, TH)`` in cells."""

    vt_delta_pc_th: float
    """The heading shift (theta cells) of the last view-template injection."""


@runtime_checkable
class OdometrySource(Protocol):
    """Odometry per frame: ``(vtrans m/s, vrot rad/s, dt s)``."""

    def __call__(self, frame: Frame) -> tuple[float, float, float]:
        """The odometry of the interval ending at ``frame``."""
        ...


@runtime_checkable
class FrameSource(Protocol):
    """A reader, dataset or simulator session: anything that yields frames."""

    def frames(self) -> Iterator[Frame]:
        """The frames, in order."""
        ...


@runtime_checkable
class GroundTruthSource(Protocol):
    """A frame source that also knows where the robot was."""

    def groundtruth(self) -> np.ndarray | None:
        """Rows ``[t, x, y, th]`` (None when unknown). Shape: ``(T, 4)``."""
        ...


@runtime_checkable
class RangeMapper(Protocol):
    """A range-sensor mapper (``registry.RANGE_MAPPERS``, e.g. MBARAM): frames with laser
    scans and odometry in, the node of the place out."""

    model: Any
    """The learnt map (for MBARAM an :class:`~torchratslam.mbaram.model.MBARAM`)."""

    def learn(self, frame: Frame) -> int:
        """One mapping step; the winning (or new) node."""
        ...

    def localise(self, frame: Frame, *, odometry: bool = True) -> int:
        """The node of ``frame`` without learning (-1: none), with or without odometry."""
        ...

    def __len__(self) -> int:
        """The number of nodes."""
        ...


@runtime_checkable
class SlamSystem(Protocol):
    """A running RatSLAM system as the saved-map code sees it (``RatSLAM`` and
    ``MultiSessionRatSLAM``): its stages, its configuration and its session record.

    Saving and loading a map (:mod:`torchratslam.maps.running`) use nothing else.
    """

    @property
    def config(self) -> RatSLAMConfig:
        """The configuration the stages were built with."""
        ...

    @property
    def local_view(self) -> LocalViewModule:
        """The local-view stage."""
        ...

    @property
    def pose_cells(self) -> PoseCellModule:
        """The pose-cell stage."""
        ...

    @property
    def experience_map(self) -> ExperienceMapModule:
        """The experience-map stage."""
        ...

    @property
    def odometry(self) -> OdometrySource:
        """The odometry source."""
        ...

    session: SessionState
    """Frames processed and the last time stamp (assigning it restores them)."""

    def remap_experiences(self, old_to_new: np.ndarray) -> None:
        """Re-point the per-frame history at new experience ids (after a merge)."""
        ...
