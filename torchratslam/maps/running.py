"""The map of a running pipeline: take it out, put it back, save it.

:func:`state_from_slam` reads each stage's ``get_state()`` into its typed record and
composes them into a :class:`~torchratslam.maps.state.MapState`; :func:`apply_state`
decomposes a map and hands each stage its record's dictionary, so the pipeline continues
exactly as the saved run would have. Both talk to the pipeline only through the public
members of :class:`~torchratslam.protocols.SlamSystem` (a ``RatSLAM`` or a
``MultiSessionRatSLAM``).

Example:
    >>> from torchratslam.maps.running import save_state, state_from_slam  # doctest: +SKIP
    >>> save_state(slam, "out/run1/state")  # doctest: +SKIP
    >>> state_from_slam(slam).summary()  # doctest: +SKIP
    {'templates': 31, 'experiences': 40, 'links': 44}
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ratslam_graph.state import ExperienceMapState
from torchratslam.errors import MapFormatError
from torchratslam.local_view.state import LocalViewState
from torchratslam.local_view.template_view import TemplateView
from torchratslam.maps.compat import conform
from torchratslam.maps.native import save_map
from torchratslam.maps.stages import compose, decompose, experience_map_record
from torchratslam.maps.state import MapState
from torchratslam.pose_cells.state import PoseCellState
from torchratslam.protocols import SlamSystem, Stateful

__all__ = ["apply_experience_map", "apply_state", "save_state", "state_from_slam"]


def _stateful(module: object, label: str) -> Stateful:
    if not isinstance(module, Stateful):
        raise MapFormatError(
            f"the {label} ({type(module).__name__}) has no get_state()/set_state(), "
            "so its map cannot be saved"
        )
    return module


def state_from_slam(slam: SlamSystem, *, share: bool = False) -> MapState:
    """The complete state of a running ``RatSLAM`` (or ``MultiSessionRatSLAM``) as a
    :class:`MapState` (from each module's ``get_state()``).

    Args:
        slam: the pipeline.
        share: a template local view's templates as a read-only view of its bank, not a
            copy (for a save done before the next frame, such as :func:`save_state`).

    Raises:
        MapFormatError: a module has no ``get_state`` / ``set_state``
            (:class:`torchratslam.protocols.Stateful`).
    """
    lv = _stateful(slam.local_view, "local view")
    pc = _stateful(slam.pose_cells, "pose cells")
    em = _stateful(slam.experience_map, "experience map")
    odometry = slam.odometry
    return compose(
        slam.config.to_flat(),
        LocalViewState.from_dict(
            lv.get_state(share=True) if share and isinstance(lv, TemplateView) else lv.get_state()
        ),
        PoseCellState.from_dict(pc.get_state()),
        ExperienceMapState.from_dict(em.get_state()),
        slam.session,
        odometry.get_state() if isinstance(odometry, Stateful) else None,
    )


def save_state(slam: SlamSystem, directory: str | Path) -> Path:
    """Save the complete state of a running ``RatSLAM`` (or ``MultiSessionRatSLAM``)
    to ``directory`` atomically (native format, see
    :func:`~torchratslam.maps.native.save_map`)."""
    return save_map(state_from_slam(slam, share=True), directory)


def apply_state(state: MapState, slam: SlamSystem, *, exp_ids: np.ndarray | None = None) -> None:
    """Load ``state`` into a running ``RatSLAM`` (or ``MultiSessionRatSLAM``) through each
    module's ``set_state``, so that it continues exactly as the saved run would have.

    Args:
        state: the map (checked against the slam's config first).
        slam: the pipeline.
        exp_ids: after a merge, the old -> new experience id map of the running map, used
            to re-point the per-frame history (``trajectory()``) into the merged map.

    Raises:
        MapFormatError: the map is incompatible with the slam's config.
    """
    parts = decompose(conform(state, slam.config))
    local_view = _stateful(slam.local_view, "local view")
    lv = parts.local_view
    if lv.kind is None or lv.version is None:  # not saved (an imported map): the module's own
        own = local_view.get_state()
        lv = lv.replace(
            kind=own.get("kind", "ratslam") if lv.kind is None else lv.kind,
            version=own.get("version", 1) if lv.version is None else lv.version,
        )
    local_view.set_state(lv.to_dict())
    _stateful(slam.pose_cells, "pose cells").set_state(parts.pose_cells.to_dict())
    _stateful(slam.experience_map, "experience map").set_state(parts.experience_map.to_dict())
    if isinstance(slam.odometry, Stateful) and parts.odometry:
        slam.odometry.set_state(parts.odometry)
    slam.session = parts.session
    if exp_ids is not None:
        slam.remap_experiences(np.asarray(exp_ids, np.int64))


def apply_experience_map(state: MapState, config: Any, *, passes: int | None = None) -> MapState:
    """Relax ``state``'s experience map once with the configured backend
    (``exp_backend``, ``exp_loops`` passes unless ``passes`` is given); returns a copy
    with the new poses."""
    from ratslam_graph.experience_map import ExperienceMap

    params = config.experience_map
    if passes is not None:
        params = params.replace(exp_loops=int(passes))
    em = ExperienceMap(params)
    em.set_state(experience_map_record(state).to_dict())
    em.iterate()
    out = state.copy()
    out.exp_pose = np.asarray(em.poses, np.float64).copy()
    return out
