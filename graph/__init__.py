"""graph: the torch-free experience map and pose-graph backends.

This package must never import ``torchratslam`` (a test enforces the direction).
"""

from torchratslam.graph.backends import make_backend
from torchratslam.graph.errors import (
    ConfigError,
    GraphError,
    InputError,
    MapFormatError,
    RatSLAMError,
)
from torchratslam.graph.messages import Action, ActionKind
from torchratslam.graph.params import ExperienceMapParams, Params
from torchratslam.graph.posegraph import PoseGraph

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
