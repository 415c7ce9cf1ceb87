"""MBARAM's parameters (the paper's Table 3) and its channel names."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ratslam_graph.params import Params, param

__all__ = ["LASER_CHANNELS", "STATE_VERSION", "MBARAMParams"]

LASER_CHANNELS = ("laser_front", "laser_rear")
"""The laser channels of the paper's three-channel setup (the third is ``odometry``)."""

STATE_VERSION = 1
"""Version of the saved map layout (:meth:`MBARAM.get_state`)."""


@dataclass(frozen=True)
class MBARAMParams(Params):
    """MBARAM parameters; defaults are the paper's Table 3 (indoor and outdoor)."""

    section: ClassVar[str] = "mbaram"

    s_max: float = param(1.0, "S_MAX,k: maximal hypervolume det(Sigma) of a node (lasers)", gt=0.0)
    s_max_odometry: float = param(1.0, "S_MAX,k of the odometry channel (Eq. 7)", gt=0.0)
    sigma_init_sq: float = param(0.01, "sigma_init^2: initial variance of a new node", gt=0.0)
    p_init: float = param(1.0, "P(w_j)_init: prior probability of a new node", gt=0.0)
    alpha_laser_front: float = param(0.4, "channel weight alpha of the front laser", ge=0.0)
    alpha_laser_rear: float = param(0.4, "channel weight alpha of the rear laser", ge=0.0)
    alpha_odometry: float = param(0.2, "channel weight alpha of the odometry channel", ge=0.0)
    covariance: str = param(
        "diag", "node covariance: diag (paper) | full", choices=("diag", "full")
    )
    vigilance: str = param(
        "updated",
        "hypervolume tested by Eq. 7: of the node after tentatively learning the input "
        "(updated) or as it stands (current)",
        choices=("updated", "current"),
    )
    var_floor: float = param(1e-6, "lower bound on every laser variance (numerical safety)", gt=0.0)
    var_floor_odometry: float = param(1e-6, "lower bound on every odometry variance", gt=0.0)
    laser_scale: float = param(1.0, "range units per metre fed to the laser channels", gt=0.0)
    laser_max_range: float = param(
        30.0, "ranges are clipped to [0, laser_max_range] metres", gt=0.0
    )
    odo_scale: float = param(1.0, "position units per metre fed to the odometry channel", gt=0.0)
    laser_outlier: float = param(
        0.0,
        "laser channels: weight eps of a uniform outlier density on [0, laser_max_range] "
        "mixed into each beam's Gaussian, p = (1 - eps) N + eps U (0 = off, the paper's "
        "Gaussian); diagonal covariance only",
        ge=0.0,
        lt=1.0,
    )
    loc_threshold: float = param(
        1.0, "Eq. 16: success when node-to-robot distance < this (m)", gt=0.0
    )
    loc_track_hops: int = param(
        0,
        "localisation over consecutive frames (the paper's Section 4 remedy, 'comparing "
        "several time stamps'): a Bayes filter over the nodes in which the robot moves "
        "at most this many edges between frames (0 = off, the paper's single-frame "
        "localisation)",
        ge=0,
    )
    loc_track_jump: float = param(
        0.01,
        "the node filter's probability of a jump to any node between two frames "
        "(recovers from a wrong belief)",
        gt=0.0,
        le=1.0,
    )

    def channel_weights(self) -> dict[str, float]:
        """The paper's three channels and their weights alpha_k."""
        return {
            "laser_front": self.alpha_laser_front,
            "laser_rear": self.alpha_laser_rear,
            "odometry": self.alpha_odometry,
        }
