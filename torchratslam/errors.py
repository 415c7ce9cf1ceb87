"""Errors of torchratslam: the same hierarchy as ``torchratslam.graph.errors`` (one root class)."""

from torchratslam.graph.errors import (
    ConfigError,
    GraphError,
    InputError,
    MapFormatError,
    RatSLAMError,
)

__all__ = ["ConfigError", "GraphError", "InputError", "MapFormatError", "RatSLAMError"]
