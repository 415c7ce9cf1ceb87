"""Evaluation: trajectory error, alignment, dead reckoning and ICP between maps (the
paper's LibICP residual in :mod:`torchratslam.eval.icp`)."""

from torchratslam.eval.icp import (
    DEFAULT_START_ANGLES_DEG,
    PAPER_ICP_MSE_M2,
    LibIcpResult,
    LibIcpStarts,
    compare_icp,
    libicp_point_to_point,
    libicp_starts,
    nearest_neighbours,
)
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
    "DEFAULT_START_ANGLES_DEG",
    "PAPER_ICP_MSE_M2",
    "IcpResult",
    "LibIcpResult",
    "LibIcpStarts",
    "Se2Alignment",
    "align_se2",
    "apply_se2",
    "ate_rmse",
    "compare_icp",
    "dead_reckoning",
    "icp",
    "icp_rmse",
    "interpolate_groundtruth",
    "libicp_point_to_point",
    "libicp_starts",
    "nearest_neighbours",
]
