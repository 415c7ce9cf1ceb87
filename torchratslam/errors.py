"""Errors of torchratslam: the same hierarchy as ``graph.errors`` (one root class)."""

from graph.errors import ConfigError, GraphError, InputError, MapFormatError, RatSLAMError

__all__ = ["ConfigError", "GraphError", "InputError", "MapFormatError", "RatSLAMError"]
