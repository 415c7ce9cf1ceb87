"""Evaluation: trajectory error, alignment, dead reckoning and ICP between maps."""

from torchratslam.eval.metrics import (
    IcpResult,
    Se2Alignment,
    align_se2,
    apply_se2,
    ate_rmse,
    dead_reckoning,
    icp,
    icp_rmse,
    interpolate_groundtruth,
)

__all__ = [
    "IcpResult",
    "Se2Alignment",
    "align_se2",
    "apply_se2",
    "ate_rmse",
    "dead_reckoning",
    "icp",
    "icp_rmse",
    "interpolate_groundtruth",
]
