"""Errors of torchratslam: the same hierarchy as ``ratslam_graph.errors`` (one root class)."""

from ratslam_graph.errors import (
    ConfigError,
    GraphError,
    InputError,
    MapFormatError,
    RatSLAMError,
)

__all__ = ["ConfigError", "GraphError", "InputError", "MapFormatError", "RatSLAMError"]
