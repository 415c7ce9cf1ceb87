"""Readers: datasets (image folders, videos, ROS 1/2 bags, CSV odometry) and visual odometry.

The names load on first use, so a light import (``torchratslam.readers.limits``, the
CLI's parser) does not pull in torch.
"""

from __future__ import annotations

import importlib
from typing import Any

_HOMES = {
    "BagReader": "bags",
    "IMAGE_EXTENSIONS": "datasets",
    "VIDEO_EXTENSIONS": "datasets",
    "DirectoryReader": "datasets",
    "Reader": "datasets",
    "VideoReader": "datasets",
    "open_data": "datasets",
    "read_groundtruth_csv": "datasets",
    "read_odometry_csv": "datasets",
    "GivenOdometry": "visual_odometry",
    "VisualOdometry": "visual_odometry",
    "best_shift": "visual_odometry",
    "intensity_profile": "visual_odometry",
}

__all__ = sorted(_HOMES)


def __getattr__(name: str) -> Any:
    if name in _HOMES:
        return getattr(importlib.import_module(f"{__name__}.{_HOMES[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
