"""The default stages, registered in one place.

Importing this module registers, explicitly and once: local views ``"ratslam"``
(:class:`~torchratslam.local_view.view.LocalView`), ``"features"``
(:class:`~torchratslam.local_view.view.FeatureView`) and ``"recoded"``
(:class:`~torchratslam.local_view.recoded.RecodedView`, xRatSLAM's RecodedLV: the newest
matching template) and ``"linear"`` (:class:`~torchratslam.local_view.linear.LinearScanView`,
OpenRatSLAM's linear scan over every template), pose cells ``"ratslam"``
(:class:`~torchratslam.pose_cells.stage.PoseCells`), experience map ``"ratslam"``
(:class:`~ratslam_graph.experience_map.ExperienceMap`) and odometry sources ``"given"``
(the reader's wheel odometry) and ``"visual"`` (intensity-profile visual odometry). The
pipeline imports it; a user's own stages register with the same registries.

Example:
    >>> import torchratslam.pipeline.defaults
    >>> from torchratslam.registry import ODOMETRY
    >>> ODOMETRY.names()[:2]
    ['given', 'visual']
"""

from __future__ import annotations

from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.params import ExperienceMapParams
from torchratslam.config import VisualOdometryParams
from torchratslam.local_view.linear import LinearScanView
from torchratslam.local_view.recoded import RecodedView
from torchratslam.local_view.view import FeatureView, LocalView
from torchratslam.pose_cells.stage import PoseCells
from torchratslam.readers.visual_odometry import GivenOdometry, VisualOdometry
from torchratslam.registry import EXPERIENCE_MAPS, LOCAL_VIEWS, ODOMETRY, POSE_CELLS, Registry

__all__ = ["DEFAULTS"]


def _experience_map(params: ExperienceMapParams) -> ExperienceMap:
    return ExperienceMap(params)


def _given_odometry(params: VisualOdometryParams | None = None) -> GivenOdometry:
    return GivenOdometry(params)


def _visual_odometry(params: VisualOdometryParams | None = None) -> VisualOdometry:
    return VisualOdometry(params)


DEFAULTS: tuple[tuple[Registry, str, object], ...] = (
    (LOCAL_VIEWS, "ratslam", LocalView),
    (LOCAL_VIEWS, "features", FeatureView),
    (LOCAL_VIEWS, "recoded", RecodedView),
    (LOCAL_VIEWS, "linear", LinearScanView),
    (POSE_CELLS, "ratslam", PoseCells),
    (EXPERIENCE_MAPS, "ratslam", _experience_map),
    (ODOMETRY, "given", _given_odometry),
    (ODOMETRY, "visual", _visual_odometry),
)
"""(registry, name, factory) of every default stage."""

for _registry, _name, _factory in DEFAULTS:
    _registry.register(_name, _factory)
