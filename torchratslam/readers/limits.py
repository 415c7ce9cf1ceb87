"""Plausibility limits of the readers (a tiny module so the CLI can show them cheaply)."""

MAX_SPEED = 50.0
"""Default limit (m/s) above which an odometry row is refused as implausible (180 km/h:
above any robot or car dataset RatSLAM has been run on)."""
MAX_TURN_RATE = 50.0
"""Default limit (rad/s) above which an odometry row's turn rate is refused."""
