"""graph: the torch-free experience map and pose-graph backends.

This package must never import ``torchratslam`` (a test enforces the direction).
"""

import logging

from ratslam_graph.backends import make_backend
from ratslam_graph.errors import (
    ConfigError,
    GraphError,
    InputError,
    MapFormatError,
    RatSLAMError,
)
from ratslam_graph.messages import Action, ActionKind
from ratslam_graph.params import ExperienceMapParams, Params
from ratslam_graph.posegraph import PoseGraph

logging.getLogger(__name__).addHandler(logging.NullHandler())

__all__ = [
    "Action",
    "ActionKind",
    "ConfigError",
    "ExperienceMapParams",
    "GraphError",
    "InputError",
    "MapFormatError",
    "Params",
    "PoseGraph",
    "RatSLAMError",
    "make_backend",
]
