"""Tours: worlds, routes and sessions reproducing the papers' experiments.

Each tour is data (:mod:`torchratslam.sim.tour_data`) read by one builder
(:mod:`torchratslam.sim.tour_builder`).

* ``virtual_tour`` (multisession paper, Fig. 5): an ellipse (60.7 m lap) in a hall;
  256x64 panoramic, 1 Hz, 150 frames per lap. session1: a 3/4 lap (113 frames);
  session2: 2.9 laps from an unmapped point 0.873 lap round, reaching session1's
  start after 19 frames and replaying its frames from there (436 frames).
* ``lab_tour`` (Fig. 6): two rectangles forming a digital "8"; 640x480 forward camera
  (50 degrees), 1 Hz, 0.25 m/s. session1: two CCW laps of the small rectangle (153);
  session2: 1.9 CCW laps of the large one from an unmapped point (206).
* ``irat_like`` (Fig. 7): a 2 x 2 block road network at iRat scale (2.4 x 1.6 m);
  160x96 forward camera (75 degrees), 10 Hz, 0.2 m/s. session1-4: one CCW lap around
  each block (194 each); session5: in along an unmapped spur, then the outer loop,
  which joins all four (433).
* ``loop``: a corridor loop (38.3 m lap), 256x64 panoramic, 5 Hz, lasers on.
  session1: 6 laps, 1781 frames.
* ``suburb`` (St Lucia-like): an 8 x 8 block street grid (40 m blocks, 12 m
  streets, buildings of varied heights and facades); a car with a 128x64 forward camera
  (60 degrees, 1.5 m up) at 10 m/s, 10 Hz; 20000 frames driving most streets several
  times in both directions. Options ``blocks``, ``block_size``, ``street_width``,
  ``frames``, ``speed``, ``hz``.

Every tour takes ``seed`` (textures, odometry noise, obstacles) and these options:

* camera: ``camera`` ("panoramic" or "forward"), ``width``, ``height``, ``fov_deg``,
  ``cam_height``, ``fog`` (m, 0 = off), ``pixel_noise`` (grey levels);
* lasers: ``lasers`` (bool), ``laser_beams`` (682), ``laser_fov_deg`` (240),
  ``laser_max_range`` (30 m), ``laser_noise`` (0.01 m); front and rear scanners;
* odometry: ``scale_error``, ``rot_scale_error``, ``heading_bias`` (rad/s),
  ``trans_noise`` (m/s), ``rot_noise`` (rad/s), or ``exact_odometry=True``;
* motion: ``hz``; ``speed`` (lab_tour, irat_like), ``frames_per_lap`` and
  ``session2_start`` (virtual_tour: where session 2 starts, in laps from session 1's
  start, inside the quarter session 1 leaves unmapped; default 0.873), ``laps`` and
  ``frames`` (loop);
* environment changes: ``illumination`` (relative gain amplitude, 0 = off) with
  ``illumination_mode`` ("session": one gain per session, the first at 1; "lap": one
  per lap; "drift": a slow sinusoid over each session), ``moved_obstacles`` (N boxes
  beside the path that move between laps and sessions), ``moving_obstacles`` (N
  pedestrians walking along the path, seen by camera and lasers).
"""

from __future__ import annotations

from ratslam_graph.errors import unknown_name_message
from torchratslam.errors import InputError
from torchratslam.sim.session import Tour
from torchratslam.sim.tour_builder import build_tour
from torchratslam.sim.tour_data import TOUR_SPECS
from torchratslam.sim.tour_spec import TourSpec

__all__ = ["TOURS", "TOUR_PRESETS", "get_tour"]

#: Every tour's specification by name.
TOURS: dict[str, TourSpec] = TOUR_SPECS

#: The shipped config preset (``configs/NAME.yaml``) that suits each tour; ``torchratslam
#: simulate`` writes it beside the data as an OpenRatSLAM ``config.txt``.
TOUR_PRESETS: dict[str, str] = {
    "virtual_tour": "virtual_tour",
    "lab_tour": "lab_tour",
    "irat_like": "irat",
    "suburb": "suburb",
}


def get_tour(name: str, *, seed: int = 0, **options) -> Tour:
    """Build a tour by name.

    Args:
        name: one of ``TOURS`` (virtual_tour, lab_tour, irat_like, loop, lab_corridor,
            suburb, ...).
        seed: seed of the textures, odometry noise and obstacles.
        **options: common options (module docstring) and the tour's own (``hz``,
            ``speed``, ``frames_per_lap``, ``laps``, ``frames``).

    Returns:
        The tour, with its sessions ready to iterate (frames render lazily).

    Raises:
        InputError: unknown tour or option, or an invalid option value.
    """
    if name not in TOURS:
        raise InputError(unknown_name_message("simulator tour", name, TOURS))
    seed = int(seed)
    try:
        return build_tour(TOURS[name], seed, options)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"tour {name!r}: bad option value ({exc})") from exc
