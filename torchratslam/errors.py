"""Errors of torchratslam: the same hierarchy as ``ratslam_graph.errors`` (one root class),
and :func:`option`, which names an option in a message for both callers (the command
line's flag, the Python argument)."""

from ratslam_graph.errors import (
    ConfigError,
    GraphError,
    InputError,
    MapFormatError,
    RatSLAMError,
    for_cli,
    for_python,
    option,
)

__all__ = [
    "ConfigError",
    "GraphError",
    "InputError",
    "MapFormatError",
    "RatSLAMError",
    "for_cli",
    "for_python",
    "option",
]
