"""Readers: datasets (image folders, videos, ROS 1/2 bags, CSV odometry) and visual odometry."""

from torchratslam.readers.bags import BagReader
from torchratslam.readers.datasets import (
    IMAGE_EXTENSIONS,
    VIDEO_EXTENSIONS,
    DirectoryReader,
    Reader,
    VideoReader,
    open_data,
    read_groundtruth_csv,
    read_odometry_csv,
)
from torchratslam.readers.visual_odometry import (
    GivenOdometry,
    VisualOdometry,
    best_shift,
    intensity_profile,
)

__all__ = [
    "IMAGE_EXTENSIONS",
    "VIDEO_EXTENSIONS",
    "BagReader",
    "DirectoryReader",
    "GivenOdometry",
    "Reader",
    "VideoReader",
    "VisualOdometry",
    "best_shift",
    "intensity_profile",
    "open_data",
    "read_groundtruth_csv",
    "read_odometry_csv",
]
