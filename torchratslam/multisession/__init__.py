"""Multisession mapping: several sessions mapped one after the other, merged on recognition."""

from torchratslam.multisession.session import (
    MultiSessionRatSLAM,
)

__all__ = ["MultiSessionRatSLAM"]
