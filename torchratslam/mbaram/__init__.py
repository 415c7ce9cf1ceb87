"""MBARAM: the multi-channel ART place recogniser built from laser scans (and odometry)."""

from torchratslam.mbaram.model import (
    LASER_CHANNELS,
    MBARAM,
    MatchResult,
    MBARAMParams,
    OdometryIntegrator,
    RunResult,
    compression_ratio,
    frame_inputs,
    localisation_success,
    quantisation_error,
    run_mbaram,
)

__all__ = [
    "LASER_CHANNELS",
    "MBARAM",
    "MBARAMParams",
    "MatchResult",
    "OdometryIntegrator",
    "RunResult",
    "compression_ratio",
    "frame_inputs",
    "localisation_success",
    "quantisation_error",
    "run_mbaram",
]
