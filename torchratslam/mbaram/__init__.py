"""MBARAM: the multi-channel ART place recogniser built from laser scans (and odometry)."""

from torchratslam.mbaram.inputs import OdometryIntegrator, frame_inputs
from torchratslam.mbaram.mapper import MBARAMMapper
from torchratslam.mbaram.match import MatchResult
from torchratslam.mbaram.metrics import compression_ratio, localisation_success, quantisation_error
from torchratslam.mbaram.model import MBARAM
from torchratslam.mbaram.params import LASER_CHANNELS, MBARAMParams
from torchratslam.mbaram.run import RunResult, run_mbaram

__all__ = [
    "LASER_CHANNELS",
    "MBARAM",
    "MBARAMMapper",
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
