"""A built-in simulator with ground truth: textured 2.5D worlds, panoramic and forward
cameras, front and rear lasers, noisy odometry, and tours reproducing the papers'
experiments (see :mod:`torchratslam.sim.tours`).

Example:
    >>> from torchratslam.sim import get_tour, open_sim
    >>> tour = get_tour("virtual_tour")
    >>> [len(s) for s in tour.sessions]
    [113, 436]
    >>> frame = next(open_sim("sim:virtual_tour/session2").frames())
    >>> frame.image.shape
    (64, 256)
"""

from torchratslam.sim.dataset import open_sim, parse_sim_spec, write_dataset
from torchratslam.sim.laser import Laser, scan
from torchratslam.sim.motion import OdometryNoise, Route, odometry_from_poses
from torchratslam.sim.render import Camera, cast_rays, render
from torchratslam.sim.session import Session, Tour
from torchratslam.sim.tours import TOURS, get_tour
from torchratslam.sim.world import World, WorldBuilder

__all__ = [
    "TOURS",
    "Camera",
    "Laser",
    "OdometryNoise",
    "Route",
    "Session",
    "Tour",
    "World",
    "WorldBuilder",
    "cast_rays",
    "get_tour",
    "odometry_from_poses",
    "open_sim",
    "parse_sim_spec",
    "render",
    "scan",
    "write_dataset",
]
