"""graph: the torch-free experience map and pose-graph backends.

This package must never import ``torchratslam`` (a test enforces the direction).
"""

from graph.backends import make_backend
from graph.errors import ConfigError, GraphError, InputError, MapFormatError, RatSLAMError
from graph.messages import Action, ActionKind
from graph.params import ExperienceMapParams, Params
from graph.posegraph import PoseGraph

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
