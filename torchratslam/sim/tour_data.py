"""The simulator's tours as data (read by :func:`torchratslam.sim.tour_builder.build_tour`).

* ``virtual_tour`` (multisession paper, Fig. 5): an ellipse (60.7 m lap) in a hall;
  256x64 panoramic, 1 Hz, 150 frames per lap. session1: a 3/4 lap (113 frames);
  session2: 2.9 laps from an unmapped point 0.873 lap round, reaching session1's
  start after 19 frames and replaying its frames from there (436 frames).
* ``lab_tour`` (Fig. 6): two rectangles forming a digital "8"; 640x480 forward camera
  (50 degrees), 1 Hz, 0.25 m/s; corners of ``corner_radius`` (0.6 m) drawn through
  ``arc_points`` (24) points. session1: two CCW laps of the small rectangle (153);
  session2: 1.9 CCW laps of the large one from an unmapped point (206).
* ``irat_like`` (Fig. 7): a 2 x 2 block road network at iRat scale (2.4 x 1.6 m);
  160x96 forward camera (75 degrees), 10 Hz, 0.2 m/s. session1-4: one CCW lap around
  each block (194 each); session5: in along an unmapped spur, then the outer loop,
  which joins all four (433).
* ``new_college`` (Fig. 8): a campus of two quads joined by a lane, buildings round
  and between them; 256x64 panoramic, 1 Hz, 0.5 m/s, wheel odometry. session1: two
  clockwise laps of the west quad (301); session2: two clockwise laps of the east quad
  (301); session3: from a known place on the west quad, along its north side and the
  north lane, a clockwise lap of the east quad (271), merging with both stored maps.
* ``loop``: a corridor loop (38.3 m lap), 256x64 panoramic, 5 Hz, lasers on.
  session1: 6 laps, 1781 frames.
* ``suburb`` (St Lucia-like): an 8 x 8 block street grid (40 m blocks, 12 m streets,
  buildings of varied heights and facades); a car with a 128x64 forward camera
  (60 degrees, 1.5 m up) at 10 m/s, 10 Hz; 20000 frames driving most streets several
  times in both directions.
* ``bicocca_like`` (MBARAM, Rawseeds Bicocca stand-in): two 30 x 20 m buildings, each a
  3 m ring corridor round a core, joined by a 10 m passage; a 197 m figure-of-eight lap at
  1 m/s, 5 Hz, front and rear lasers on (option ``frames``: a drive of that many frames,
  lapping the figure of eight).
* ``bovisa_like`` (MBARAM, Rawseeds Bovisa stand-in): a 120 x 80 m campus of six buildings
  behind a low fence; a 428 m lap round the ring road and down the middle road at
  1.5 m/s, 5 Hz, front and rear lasers on (option ``frames``: a drive of that many
  frames, lapping the route).
"""

from __future__ import annotations

from torchratslam.sim.tour_spec import (
    Box,
    CameraSpec,
    EllipseRoute,
    GridDriveRoute,
    LapFraction,
    Leg,
    NoiseSpec,
    Opt,
    PolygonRoute,
    Polyline,
    SessionSpec,
    Spacing,
    StreetGrid,
    TourSpec,
    WorldSpec,
)

__all__ = [
    "BICOCCA_LIKE",
    "BOVISA_LIKE",
    "IRAT_LIKE",
    "LAB_CORRIDOR",
    "LAB_TOUR",
    "LOOP",
    "SUBURB",
    "TOUR_SPECS",
    "VIRTUAL_TOUR",
]

# smooth textures (the paper's virtual world has smooth imagery): turning by one template
# column (2.8 degrees) changes a view far less than vt_match_threshold, so the published
# vt_step_match = 2 works; the far hall walls get 3x wider features
VIRTUAL_TOUR = TourSpec(
    name="virtual_tour",
    description="multisession Fig. 5: ellipse, 3/4 lap, then 2.9 laps from an unmapped point",
    options={"frames_per_lap": 150, "hz": 1.0, "session2_start": 0.873},
    positive=(("frames_per_lap", 3.0), ("hz", 0.0)),
    world=WorldSpec(
        walls=(
            Polyline(((-18, -13), (18, -13), (18, 13), (-18, 13)), scale=3.0),
            Box(0.0, 0.0, 10.0, 4.0, height=3.0),
            Box(-7.5, 0.0, 1.0, 1.0, height=2.5),
            Box(7.5, 0.5, 1.2, 1.2, height=2.5),
            Box(0.0, 10.0, 2.0, 1.0, height=2.5),
            Box(-9.0, -9.5, 1.5, 1.5, height=2.5),
            Box(10.0, -9.0, 1.0, 2.0, height=2.5),
            Box(14.5, 2.0, 1.0, 1.0, height=2.5),
            Box(-14.5, -3.0, 1.0, 1.5, height=2.5),
            Box(4.0, -10.5, 1.0, 1.0, height=2.5),
        ),
        wall_height=5.0,
        style="smooth",
    ),
    routes={"ellipse": EllipseRoute(12.0, 7.0, start_deg=-90.0)},
    sessions=(
        SessionSpec("session1", "ellipse", laps=0.75),
        SessionSpec(
            "session2",
            "ellipse",
            laps=2.9,
            start=LapFraction("session2_start", low=0.75, high=1.0, default=0.873),
        ),
    ),
    spacing=Spacing("per_lap"),
    camera=CameraSpec("panoramic", width=256, height=64, cam_height=1.0),
    noise=NoiseSpec(
        scale_error=0.03,
        rot_scale_error=0.01,
        heading_bias=0.001,
        trans_noise=0.01,
        rot_noise=0.005,
    ),
    lasers=False,
    main_route="ellipse",
    obstacle_offset=2.5,
    clearance=1.5,
    # continuous run: on along the ellipse through the unmapped quarter to session 2
    bridges=((Leg("ellipse"),),),
)

# the lab's corners: radius and the points each arc is drawn through (tour options)
_LAB_R, _LAB_ARC = Opt("corner_radius"), Opt("arc_points")

LAB_TOUR = TourSpec(
    name="lab_tour",
    description="multisession Fig. 6: two CCW laps of the small rectangle, 1.9 of the large",
    options={"speed": 0.25, "hz": 1.0, "corner_radius": 0.6, "arc_points": 24},
    positive=(("speed", 0.0), ("hz", 0.0), ("corner_radius", 0.0), ("arc_points", 2.0)),
    world=WorldSpec(
        walls=(
            Polyline(((-2.5, -2.5), (8.5, -2.5), (8.5, 10.5), (-2.5, 10.5))),
            Box(3.0, 6.0, 4.0, 2.0),  # desks inside the small loop
            Box(3.0, 2.0, 4.0, 2.0),  # desks inside the lower loop
            Box(-2.0, 2.0, 0.8, 2.0, height=1.2),
            Box(8.0, 6.5, 0.8, 1.6, height=1.2),
            Box(4.0, 10.0, 2.0, 0.8, height=1.2),
            Box(1.0, -2.0, 1.6, 0.8, height=1.2),
            Box(7.5, -1.5, 1.0, 1.0, height=1.2),
            Box(-1.7, 9.5, 1.2, 1.2, height=1.2),
        ),
        wall_height=2.5,
    ),
    routes={
        "small": PolygonRoute(((0, 4), (6, 4), (6, 8), (0, 8)), _LAB_R, arc_points=_LAB_ARC),
        "large": PolygonRoute(((0, 0), (6, 0), (6, 8), (0, 8)), _LAB_R, arc_points=_LAB_ARC),
    },
    # the small loop starts mid-bar heading +x; the large one mid-bottom heading +x
    sessions=(
        SessionSpec("session1", "small", laps=2.0, start=(3.0, 4.0)),
        SessionSpec("session2", "large", laps=1.9, start=(3.0, 0.0)),
    ),
    spacing=Spacing("speed"),
    camera=CameraSpec("forward", width=640, height=480, fov_deg=50.0, cam_height=0.3),
    noise=NoiseSpec(
        scale_error=0.03,
        rot_scale_error=0.02,
        heading_bias=0.002,
        trans_noise=0.01,
        rot_noise=0.01,
    ),
    lasers=False,
    main_route="large",
    obstacle_size=0.6,
    obstacle_offset=0.9,
    pedestrian_offset=0.6,
    obstacle_height=1.0,
    clearance=0.8,
    # continuous run: on round the small rectangle to its left side (shared with the large
    # one, same direction), then down the large one to session 2's start
    bridges=((Leg("small", None, (0.0, 6.0)), Leg("large", (0.0, 6.0), None)),),
)

# irat_like is drawn at 10x (_GX, _GY, _HALF, _SPUR) and scaled by _K to iRat size
_K = 0.1
_GX, _GY, _HALF, _SPUR = 12.0, 8.0, 1.5, 6.0
_R = 0.8 * _K


def _irat_block(bx: int, by: int) -> PolygonRoute:
    x0, y0 = _GX * bx * _K, _GY * by * _K
    return PolygonRoute(
        ((x0, y0), (x0 + _GX * _K, y0), (x0 + _GX * _K, y0 + _GY * _K), (x0, y0 + _GY * _K)),
        radius=_R,
    )


IRAT_LIKE = TourSpec(
    name="irat_like",
    description="multisession Fig. 7: four inner loops, then the outer loop joining them",
    options={"speed": 0.2, "hz": 10.0},
    positive=(("speed", 0.0), ("hz", 0.0)),
    world=WorldSpec(
        walls=(
            # outer wall with an opening on the left road where a spur (driveway) joins
            Polyline(
                (
                    (-_HALF, _GY - _HALF),
                    (-_HALF, -_HALF),
                    (2 * _GX + _HALF, -_HALF),
                    (2 * _GX + _HALF, 2 * _GY + _HALF),
                    (-_HALF, 2 * _GY + _HALF),
                    (-_HALF, _GY + _HALF),
                ),
                closed=False,
            ),
            Polyline(
                (
                    (-_HALF, _GY - _HALF),
                    (-_HALF - _SPUR, _GY - _HALF),
                    (-_HALF - _SPUR, _GY + _HALF),
                    (-_HALF, _GY + _HALF),
                ),
                closed=False,
            ),
            *(
                Box(_GX * (bx + 0.5), _GY * (by + 0.5), _GX - 2 * _HALF, _GY - 2 * _HALF)
                for bx in range(2)
                for by in range(2)
            ),
        ),
        wall_height=3.0,
        scale=_K,
    ),
    routes={
        "block1": _irat_block(0, 0),
        "block2": _irat_block(1, 0),
        "block3": _irat_block(1, 1),
        "block4": _irat_block(0, 1),
        "outer": PolygonRoute(
            ((0, 0), (2 * _GX * _K, 0), (2 * _GX * _K, 2 * _GY * _K), (0, 2 * _GY * _K)),
            radius=_R,
        ),
        # session 5 comes in along the spur (unmapped), turns south, drives the outer loop
        # and passes the junction again
        "session5": PolygonRoute(
            (
                (-(_HALF + _SPUR - 1.5) * _K, _GY * _K),
                (0, _GY * _K),
                (0, 0),
                (2 * _GX * _K, 0),
                (2 * _GX * _K, 2 * _GY * _K),
                (0, 2 * _GY * _K),
                (0, _GY * _K - 1.5 * _HALF * _K),
            ),
            radius=_R,
            closed=False,
        ),
    },
    sessions=(
        SessionSpec("session1", "block1", start=(_GX * _K / 2, 0.0)),
        SessionSpec("session2", "block2", start=(1.5 * _GX * _K, 0.0)),
        SessionSpec("session3", "block3", start=(1.5 * _GX * _K, 2 * _GY * _K)),
        SessionSpec("session4", "block4", start=(_GX * _K / 2, 2 * _GY * _K)),
        SessionSpec("session5", "session5", count="floor"),
    ),
    spacing=Spacing("speed"),
    camera=CameraSpec("forward", width=160, height=96, fov_deg=75.0, cam_height=0.06),
    noise=NoiseSpec(
        scale_error=0.03,
        rot_scale_error=0.02,
        heading_bias=0.005,
        trans_noise=0.005,
        rot_noise=0.02,
    ),
    lasers=False,
    main_route="outer",
    obstacle_size=0.06,
    obstacle_offset=0.09,
    pedestrian_offset=0.07,
    obstacle_height=0.15,
    scale=_K,
    clearance=0.1,
    # continuous run: sessions 1-4 end where the next begins along the outer loop's straight
    # roads; after session 4 the robot drives down the left road, turns into the spur,
    # drives out to session 5's start and turns on the spot
    bridge_routes={
        "into_spur": PolygonRoute(
            ((0.0, _GY * _K + 4 * _R), (0.0, _GY * _K), (-(_HALF + _SPUR - 1.5) * _K, _GY * _K)),
            radius=_R,
            closed=False,
        )
    },
    bridges=(
        (Leg("outer"),),
        (Leg("outer"),),
        (Leg("outer"),),
        (
            Leg("outer", None, (0.0, _GY * _K + 4 * _R)),
            Leg("into_spur", (0.0, _GY * _K + 4 * _R), None),
        ),
    ),
)

# new_college: the west quad (session 1) and the east quad (session 2) are laps round a
# building each, 24 x 16 m, 12 m apart; a lane along their south sides joins them.
# Smooth textures and 0.5 m between frames: the 60 x 10 panoramic templates of Table 1
# then recognise a place from the next lap (with sharp textures every frame is new).
# Every session drives clockwise: a place seen the other way round differs by more than
# vt_match_threshold (0.09 at the best turn, 0.2 m apart), so it would never merge
_WEST = ((0.0, 0.0), (0.0, 16.0), (24.0, 16.0), (24.0, 0.0))  # clockwise
_EAST = ((36.0, 0.0), (36.0, 16.0), (60.0, 16.0), (60.0, 0.0))  # clockwise
NEW_COLLEGE = TourSpec(
    name="new_college",
    description=(
        "multisession Fig. 8: two quads mapped in two sessions, a third session from a "
        "known place in the first joins both"
    ),
    options={"speed": 0.5, "hz": 1.0},
    positive=(("speed", 0.0), ("hz", 0.0)),
    world=WorldSpec(
        walls=(
            Polyline(((-7, -7), (67, -7), (67, 23), (-7, 23))),  # the college's outer ranges
            Box(12.0, 8.0, 16.0, 8.0, height=8.0),  # the west quad's hall
            Box(48.0, 8.0, 16.0, 8.0, height=10.0),  # the east quad's chapel
            Box(30.0, 8.0, 4.0, 10.0, height=6.0),  # the range between the quads
            Box(-3.5, 5.0, 1.0, 1.0, height=3.0),  # trees and lamp posts
            Box(12.0, -3.5, 1.2, 1.2, height=3.0),
            Box(30.0, -3.5, 1.0, 1.0, height=3.0),
            Box(48.0, 19.5, 1.2, 1.2, height=3.0),
            Box(63.5, 9.0, 1.0, 1.5, height=3.0),
            Box(-3.5, 14.0, 1.5, 1.0, height=3.0),
            Box(20.0, 19.5, 1.0, 1.0, height=3.0),
            Box(42.0, -3.5, 1.5, 1.0, height=3.0),
        ),
        wall_height=12.0,
        style="smooth",
        floor=0.4,
        ceiling=0.9,
    ),
    routes={
        "west": PolygonRoute(_WEST, radius=3.0),
        "east": PolygonRoute(_EAST, radius=3.0),
        # session 3: north up the west quad's west side, east along the north sides and
        # the north lane, then clockwise round the east quad and along its north side
        "session3": PolygonRoute(
            (
                (0.0, 8.0),
                (0.0, 16.0),
                (60.0, 16.0),
                (60.0, 0.0),
                (36.0, 0.0),
                (36.0, 16.0),
                (48.0, 16.0),
            ),
            radius=3.0,
            closed=False,
        ),
    },
    # both stored sessions start on their quad's south side, heading west
    sessions=(
        SessionSpec("session1", "west", laps=2.0, start=(20.0, 0.0)),
        SessionSpec("session2", "east", laps=2.0, start=(48.0, 0.0)),
        SessionSpec("session3", "session3", count="floor"),
    ),
    spacing=Spacing("speed"),
    camera=CameraSpec("panoramic", width=256, height=64, cam_height=1.0),
    noise=NoiseSpec(
        scale_error=0.02,
        rot_scale_error=0.01,
        heading_bias=0.001,
        trans_noise=0.02,
        rot_noise=0.01,
    ),
    lasers=False,
    main_route="west",
    obstacle_size=1.0,
    obstacle_offset=2.5,
    pedestrian_offset=1.5,
    clearance=1.5,
    # continuous run: east along the west quad's south side and the south lane to
    # session 2's start; then west along the south sides and the lane, and round the west
    # quad's south-west corner to session 3's start
    bridge_routes={
        "lane_east": PolygonRoute(((24.0, 0.0), (36.0, 0.0)), radius=3.0, closed=False),
        "lane_west": PolygonRoute(((36.0, 0.0), (24.0, 0.0)), radius=3.0, closed=False),
        "west_ccw": PolygonRoute(tuple(reversed(_WEST)), radius=3.0),
        "east_ccw": PolygonRoute(tuple(reversed(_EAST)), radius=3.0),
    },
    bridges=(
        (Leg("west_ccw", None, (24.0, 0.0)), Leg("lane_east"), Leg("east_ccw", (36.0, 0.0), None)),
        (Leg("east", None, (36.0, 0.0)), Leg("lane_west"), Leg("west", (24.0, 0.0), None)),
    ),
)

LOOP = TourSpec(
    name="loop",
    description="single-session corridor loop (the classic loop-closure test), lasers on",
    options={"laps": 6.0, "frames": None, "hz": 5.0},
    positive=(("laps", 0.0), ("hz", 0.0), ("frames", 1.0)),
    world=WorldSpec(
        walls=(
            Polyline(((-1.25, -1.25), (13.25, -1.25), (13.25, 9.25), (-1.25, 9.25))),
            Polyline(((1.25, 1.25), (10.75, 1.25), (10.75, 6.75), (1.25, 6.75))),
            # cabinets, pillars and recess frames along the walls (laser and visual landmarks)
            Box(3.0, -1.0, 1.6, 0.5, height=1.8),
            Box(8.5, -1.0, 0.5, 0.5, height=1.8),
            Box(13.0, 3.0, 0.5, 1.2, height=1.8),
            Box(6.0, 9.0, 2.0, 0.5, height=1.8),
            Box(-1.0, 5.5, 0.5, 1.8, height=1.8),
            Box(1.0, 4.0, 0.5, 0.5, height=1.8),
            Box(6.0, 1.0, 1.0, 0.5, height=1.8),
            Box(11.0, 5.0, 0.5, 0.8, height=1.8),
            Box(9.5, 9.0, 0.6, 0.5, height=1.8),
            Box(-1.0, 1.5, 0.5, 0.6, height=1.8),
            Box(4.0, 7.0, 0.8, 0.5, height=1.8),
        ),
        wall_height=2.5,
    ),
    routes={"corridor": PolygonRoute(((0, 0), (12, 0), (12, 8), (0, 8)), radius=1.0)},
    sessions=(SessionSpec("session1", "corridor"),),
    spacing=Spacing("laps", frames_per=1780, laps_per=6),
    camera=CameraSpec("panoramic", width=256, height=64, cam_height=1.0),
    noise=NoiseSpec(
        scale_error=0.02,
        rot_scale_error=0.008,
        heading_bias=0.001,
        trans_noise=0.02,
        rot_noise=0.02,
    ),
    lasers=True,
    main_route="corridor",
    obstacle_size=0.5,
    obstacle_offset=0.8,
    pedestrian_offset=0.7,
    obstacle_height=1.2,
    clearance=0.7,
)

# MBARAM's robot corridor (Section 3.4): one 40 x 5 m laboratory corridor, driven down
# one side and back the other (a lap: 117 s, 585 frames at 5 Hz; the paper's robot
# received 1146-1200 scans a loop at 10 Hz, 115-120 s), furniture along both walls
LAB_CORRIDOR = TourSpec(
    name="lab_corridor",
    description="MBARAM's robot corridor: one 40 x 5 m corridor driven down and back, lasers on",
    options={"laps": 10.0, "frames": None, "hz": 5.0},
    positive=(("laps", 0.0), ("hz", 0.0), ("frames", 1.0)),
    world=WorldSpec(
        walls=(
            Polyline(((0, 0), (40, 0), (40, 5), (0, 5))),
            # cabinets, benches, door frames and a fire hose box at irregular places
            Box(3.5, 0.25, 1.6, 0.5, height=1.8),
            Box(9.0, 0.2, 0.4, 0.4, height=2.2),
            Box(14.5, 0.3, 2.4, 0.6, height=0.9),
            Box(21.0, 0.2, 0.4, 0.4, height=2.2),
            Box(27.5, 0.25, 1.0, 0.5, height=1.8),
            Box(35.0, 0.35, 3.0, 0.7, height=0.8),
            Box(6.0, 4.75, 2.0, 0.5, height=1.8),
            Box(12.0, 4.8, 0.4, 0.4, height=2.2),
            Box(18.5, 4.7, 1.2, 0.6, height=1.2),
            Box(25.0, 4.8, 0.4, 0.4, height=2.2),
            Box(31.0, 4.7, 2.6, 0.6, height=0.9),
            Box(38.0, 4.75, 1.0, 0.5, height=1.8),
            Box(39.7, 2.5, 0.6, 1.2, height=1.5),
            Box(0.3, 1.8, 0.6, 0.8, height=1.5),
        ),
        wall_height=2.5,
    ),
    routes={"corridor": PolygonRoute(((2, 1.5), (38, 1.5), (38, 3.5), (2, 3.5)), radius=1.0)},
    sessions=(SessionSpec("session1", "corridor"),),
    spacing=Spacing("laps", frames_per=585, laps_per=1),
    camera=CameraSpec("panoramic", width=256, height=64, cam_height=1.0),
    noise=NoiseSpec(
        scale_error=0.02,
        rot_scale_error=0.008,
        heading_bias=0.001,
        trans_noise=0.02,
        rot_noise=0.02,
    ),
    lasers=True,
    main_route="corridor",
    obstacle_size=0.5,
    obstacle_offset=0.8,
    pedestrian_offset=0.5,
    obstacle_height=1.2,
    clearance=0.5,
)

SUBURB = TourSpec(
    name="suburb",
    description=(
        "suburb: {blocks} x {blocks} city blocks, a car drives most streets several "
        "times both ways (St Lucia-like)"
    ),
    options={
        "blocks": 8,
        "block_size": 40.0,
        "street_width": 12.0,
        "frames": 20000,
        "speed": 10.0,
        "hz": 10.0,
    },
    positive=(
        ("blocks", 0.0),
        ("block_size", 0.0),
        ("street_width", 0.0),
        ("speed", 0.0),
        ("hz", 0.0),
        ("frames", 1.0),
    ),
    world=WorldSpec(walls=(StreetGrid(),), wall_height=8.0, floor=0.4, ceiling=0.9),
    routes={"drive": GridDriveRoute(radius=Opt("street_width", div=3.0))},
    sessions=(SessionSpec("session1", "drive"),),
    spacing=Spacing("frames"),
    camera=CameraSpec("forward", width=128, height=64, fov_deg=60.0, cam_height=1.5),
    noise=NoiseSpec(
        scale_error=0.02,
        rot_scale_error=0.01,
        heading_bias=0.001,
        trans_noise=0.05,
        rot_noise=0.01,
    ),
    lasers=False,
    main_route="drive",
    obstacle_size=2.0,
    obstacle_offset=Opt("street_width", div=2.0, add=-1.5),
    pedestrian_offset=Opt("street_width", div=2.0, add=-1.0),
    obstacle_height=1.5,
    scale=4.0,
    clearance=Opt("street_width", div=2.0, add=-0.5),
)

# Rawseeds stand-ins for MBARAM (laser channels front and rear, odometry). The indoor one
# is two buildings, each a 3 m ring corridor round a core, joined by a 10 m passage
# (Bicocca-like); the outdoor one a 120 x 80 m campus of six buildings with 8-16 m roads
# between them and a low fence round it (Bovisa-like).
_BICOCCA_CABINETS = (
    Box(8.0, 0.25, 1.6, 0.5, height=1.8),
    Box(19.0, 0.25, 0.6, 0.5, height=1.8),
    Box(29.75, 4.5, 0.5, 1.2, height=1.8),
    Box(12.0, 19.75, 2.0, 0.5, height=1.8),
    Box(0.25, 12.0, 0.5, 1.8, height=1.8),
    Box(35.0, 8.75, 1.0, 0.5, height=1.8),
    Box(48.0, 0.25, 0.8, 0.5, height=1.8),
    Box(60.0, 0.25, 2.0, 0.5, height=1.8),
    Box(69.75, 7.0, 0.5, 1.0, height=1.8),
    Box(66.0, 19.75, 1.2, 0.5, height=1.8),
    Box(50.0, 19.75, 0.6, 0.5, height=1.8),
    Box(40.25, 15.0, 0.5, 1.4, height=1.8),
    Box(25.0, 2.75, 1.0, 0.5, height=1.8),
    Box(47.0, 17.25, 1.5, 0.5, height=1.8),
)

BICOCCA_LIKE = TourSpec(
    name="bicocca_like",
    description="Rawseeds indoor stand-in: two ring corridors joined by a passage, lasers on",
    options={"speed": 1.0, "hz": 5.0, "frames": None},
    positive=(("speed", 0.0), ("hz", 0.0), ("frames", 1.0)),
    world=WorldSpec(
        walls=(
            Polyline(
                (
                    (0, 0),
                    (30, 0),
                    (30, 8.5),
                    (40, 8.5),
                    (40, 0),
                    (70, 0),
                    (70, 20),
                    (40, 20),
                    (40, 11.5),
                    (30, 11.5),
                    (30, 20),
                    (0, 20),
                )
            ),
            Box(15.0, 10.0, 24.0, 14.0),
            Box(55.0, 10.0, 24.0, 14.0),
            *_BICOCCA_CABINETS,
        ),
        wall_height=2.5,
    ),
    # a figure of eight: A's lower half, the passage, all of B, the passage back, A's upper half
    routes={
        "tour": PolygonRoute(
            (
                (1.5, 1.5),
                (28.5, 1.5),
                (28.5, 10.0),
                (41.5, 10.0),
                (41.5, 1.5),
                (68.5, 1.5),
                (68.5, 18.5),
                (41.5, 18.5),
                (41.5, 10.0),
                (28.5, 10.0),
                (28.5, 18.5),
                (1.5, 18.5),
            ),
            radius=1.0,
        )
    },
    sessions=(SessionSpec("session1", "tour"),),
    spacing=Spacing("speed"),
    camera=CameraSpec("panoramic", width=256, height=64, cam_height=1.0),
    noise=NoiseSpec(
        scale_error=0.02,
        rot_scale_error=0.008,
        heading_bias=0.001,
        trans_noise=0.02,
        rot_noise=0.02,
    ),
    lasers=True,
    main_route="tour",
    obstacle_size=0.5,
    obstacle_offset=0.8,
    pedestrian_offset=0.7,
    obstacle_height=1.2,
    clearance=0.6,
)

BOVISA_LIKE = TourSpec(
    name="bovisa_like",
    description="Rawseeds outdoor stand-in: a campus of six buildings, lasers on",
    options={"speed": 1.5, "hz": 5.0, "frames": None},
    positive=(("speed", 0.0), ("hz", 0.0), ("frames", 1.0)),
    world=WorldSpec(
        walls=(
            Polyline(((0, 0), (120, 0), (120, 80), (0, 80)), height=1.5),
            Box(20.0, 20.0, 24.0, 16.0, height=12.0),
            Box(60.0, 18.0, 30.0, 14.0, height=9.0),
            Box(100.0, 22.0, 20.0, 20.0, height=15.0),
            Box(22.0, 58.0, 26.0, 18.0, height=10.0),
            Box(62.0, 60.0, 24.0, 22.0, height=8.0),
            Box(100.0, 60.0, 22.0, 18.0, height=12.0),
            # parked cars, kiosks and bins beside the roads
            Box(30.0, 1.5, 4.5, 2.0, height=1.5),
            Box(70.0, 1.5, 4.5, 2.0, height=1.5),
            Box(118.5, 40.0, 2.0, 4.5, height=1.5),
            Box(46.0, 36.0, 2.0, 2.0, height=2.5),
            Box(76.0, 44.0, 4.5, 2.0, height=1.5),
            Box(36.0, 60.0, 1.0, 1.0, height=1.0),
            Box(20.0, 78.5, 4.5, 2.0, height=1.5),
            Box(95.0, 78.5, 4.5, 2.0, height=1.5),
        ),
        wall_height=8.0,
        floor=0.4,
        ceiling=0.9,
    ),
    # the campus ring road with a detour down the middle road between the buildings
    routes={
        "tour": PolygonRoute(
            (
                (4.0, 5.0),
                (116.0, 5.0),
                (116.0, 76.0),
                (82.0, 76.0),
                (82.0, 40.0),
                (40.0, 40.0),
                (40.0, 76.0),
                (4.0, 76.0),
            ),
            radius=3.0,
        )
    },
    sessions=(SessionSpec("session1", "tour"),),
    spacing=Spacing("speed"),
    camera=CameraSpec("forward", width=128, height=64, fov_deg=60.0, cam_height=1.5),
    noise=NoiseSpec(
        scale_error=0.02,
        rot_scale_error=0.01,
        heading_bias=0.001,
        trans_noise=0.05,
        rot_noise=0.01,
    ),
    lasers=True,
    main_route="tour",
    obstacle_size=1.5,
    obstacle_offset=3.0,
    pedestrian_offset=1.5,
    obstacle_height=1.5,
    clearance=1.0,
)

#: Every tour by name.
TOUR_SPECS: dict[str, TourSpec] = {
    t.name: t
    for t in (
        VIRTUAL_TOUR,
        LAB_TOUR,
        IRAT_LIKE,
        NEW_COLLEGE,
        LOOP,
        LAB_CORRIDOR,
        SUBURB,
        BICOCCA_LIKE,
        BOVISA_LIKE,
    )
}
