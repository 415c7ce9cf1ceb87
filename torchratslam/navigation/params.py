"""The navigator's settings and the RatSLAM configuration of the office robot.

Example:
    >>> from torchratslam.navigation.params import office_config
    >>> office_config(28, 36).pose_cells.pc_dim_xy
    28
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from torchratslam.config import RatSLAMConfig
from torchratslam.errors import ConfigError

__all__ = ["NavParams", "office_config"]


@dataclass(frozen=True)
class NavParams:
    """How the navigator plans and chooses behaviours.

    Attributes:
        lookahead_m: arbitration compares local paths with the route's first metres.
        turn_margin_m: turning around must beat the best forward path by this (m).
        turn_cooldown_s: no deliberate turn-around within this long of the last one.
        blocked_cooldown_s: nor within this long of obstacle avoidance turning the
            robot around (it drives away before trying again).
        replan_s: the route is found afresh at least this often (and whenever the
            current experience changes).
        arrive_m: the robot believes it has arrived when its map position is this close
            to the goal experience's (and, with ``arrive_at_place``, its current
            experience stands for the goal's place).
        arrive_at_place: the robot has arrived only when its current (peak) experience
            is the goal experience or one recognised as its place: learnt with the same
            view template, or within ``arrive_links`` links of it (either way). Near a
            corner the map can hold metres of floor in less than ``arrive_m``, and map
            distance alone stops the robot short; the paper's robot is at the goal when
            its peak experience is the goal's. False: map distance alone.
        arrive_links: see ``arrive_at_place`` (0: the goal experience and those sharing
            its view template only).
        route_keep_s: route hysteresis: a route found afresh replaces the one being
            followed only when it is at least this much faster (s) than rejoining the
            old one (by the fastest way in the new temporal map) and following it on
            from there; a route whose remaining links are gone is replaced at once.
            Two routes of about equal time otherwise take turns as the current
            experience changes, and the robot turns back and forth between them.
            0: always the fresh route (the paper's constant replanning).
        reach_m: a trial succeeds when the ground truth is this close to the goal (m).
        recovery_timeout_s: route-loss recovery relies on the last route this long.
        time_factor: a trial's time limit is this times the shortest path's driving time,
            plus ``time_slack_s``.
        time_slack_s: see ``time_factor``.
        junction_m: the held branch behaviour labels frames within this of a junction.
        overlap_m: experiences this close to the robot's map pose (facing its way) are
            other representations of its place: the planner seeds them and a blocked
            transition counts against their links.
        junction_turns: routes may turn at junctions from one representation onto
            another (``plan_route(..., turns=True)``) and arbitration compares the local
            paths with the route's shape from the robot on (``arbitrate(...,
            from_robot=True)``); needed where a route must take a turn the robot never
            drove there (edge/adaptation).
        turn_back: a route may begin by turning around at the current experience and
            follow links against the way they were driven (``plan_route(...,
            turn_back=True)``, at the turn-around's time): the paper's links are
            traversable both ways. Routes then end at the goal's place (with
            ``arrive_at_place``: :meth:`NavigationAgent.goal_place`'s experiences within
            1 m of the goal experience in the map), where the robot believes it has
            arrived, not at any experience near the goal: turned back, a route reaches
            experiences near the goal facing other ways, whose view is not the goal's.
            False: a route leads on only the way each link was driven (from a place
            driven one way only, round a loop or to where the robot once turned around).
        back_step_m: above 0: a route may also follow a link of at most this length
            (m, its odometric length) between two experiences facing the same way
            (within 45 degrees) against its way (``plan_route(..., back_step_m=...)``),
            never two such steps (nor a step and a junction turn) in a row. An
            experience learnt a few centimetres behind the current one is linked from
            it backwards, and the transition the robot then drove (the other way) is
            never learnt, a pair being linked once: a chain of driven links ends there
            although the robot drove on, and a route along it is lost. 0: off.
    """

    lookahead_m: float = 3.0
    turn_margin_m: float = 0.6
    turn_cooldown_s: float = 4.0
    blocked_cooldown_s: float = 8.0
    replan_s: float = 1.0
    arrive_m: float = 0.8
    arrive_at_place: bool = True
    arrive_links: int = 0
    route_keep_s: float = 5.0
    reach_m: float = 1.5
    recovery_timeout_s: float = 10.0
    time_factor: float = 4.0
    time_slack_s: float = 60.0
    junction_m: float = 1.5
    overlap_m: float = 1.0
    junction_turns: bool = False
    turn_back: bool = False
    back_step_m: float = 0.0

    def __post_init__(self) -> None:
        for name in (
            "lookahead_m",
            "arrive_m",
            "reach_m",
            "time_factor",
            "junction_m",
            "overlap_m",
        ):
            if not getattr(self, name) > 0:
                raise ConfigError(f"NavParams.{name}={getattr(self, name)} must be > 0")
        if not self.back_step_m >= 0:
            raise ConfigError(f"NavParams.back_step_m={self.back_step_m} must be >= 0")
        if not self.route_keep_s >= 0:
            raise ConfigError(f"NavParams.route_keep_s={self.route_keep_s} must be >= 0")
        if self.arrive_links < 0:
            raise ConfigError(f"NavParams.arrive_links={self.arrive_links} must be >= 0")


def office_config(
    pc_dim_xy: int,
    pc_dim_th: int = 36,
    *,
    create_rule: str = "pc_distance",
    confidence_threshold: float = 0.5,
    **overrides: Any,
) -> RatSLAMConfig:
    """RatSLAM for the office robot: 12 x 8 grey views, 0.25 m x 10 degree pose cells
    (as the paper's), links deleted below ``confidence_threshold`` (Eq. 9).

    Args:
        pc_dim_xy, pc_dim_th: the pose-cell matrix.
        create_rule: ``exp_create_rule`` (``pc_distance`` or ``activity``).
        confidence_threshold: ``exp_link_confidence_threshold``.
        overrides: any other config keys.
    """
    flat: dict[str, Any] = {
        "pc_dim_xy": pc_dim_xy,
        "pc_dim_th": pc_dim_th,
        "pc_cell_x_size": 0.25,
        "exp_delta_pc_threshold": 1.0,
        "pc_decode": "exact",
        "pc_axis": "math",
        "skip_first_odometry": False,
        "template_x_size": 12,
        "template_y_size": 8,
        "vt_shift_match": 0,
        "vt_step_match": 1,
        "vt_match_threshold": 0.05,
        "pc_vt_inject_energy": 0.1,
        "exp_first_at_origin": True,
        "exp_link_time": "per_link",
        "exp_link_confidence_threshold": confidence_threshold,
        "exp_create_rule": create_rule,
        "exp_activity_zone_xy": 2.0,
        "exp_activity_zone_th": 2.0,
        "exp_activity_threshold": 1.0,
    }
    flat.update(overrides)
    return RatSLAMConfig.from_flat(flat, source="office_config")
