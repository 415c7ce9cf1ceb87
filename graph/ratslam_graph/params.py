"""Frozen, validated parameter dataclasses (torch-free base) and the experience-map
parameters.

Every module's parameters are a frozen dataclass deriving from :class:`Params`. Field
names are exactly the OpenRatSLAM / xRatSLAM config keys (see
``shared/reference/parameters.md``); defaults are OpenRatSLAM's. Range constraints are
declared in field metadata (``ge``, ``gt``, ``le``, ``lt``, ``choices``) and checked on
construction, so an invalid value can never reach a module.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeVar

from ratslam_graph.errors import ConfigError, unknown_name_message


def param(default: Any, doc: str = "", **constraints: Any) -> Any:
    """A dataclass field with a default, a one-line description and range constraints."""
    return field(default=default, metadata={"doc": doc, **constraints})


def _coerce(key: str, value: Any, typ: type) -> Any:
    bad = ConfigError(f"parameter {key!r}: expected {typ.__name__}, got {value!r}")
    if typ is bool:
        if isinstance(value, bool):
            return value
        if isinstance(value, (int, float)) and value in (0, 1):
            return bool(value)
        if isinstance(value, str) and value.strip().lower() in ("0", "1", "true", "false"):
            return value.strip().lower() in ("1", "true")
        raise bad
    if typ is int:
        if isinstance(value, bool):
            raise bad
        if isinstance(value, int):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
        if isinstance(value, str):
            try:
                f = float(value)
            except ValueError:
                raise bad from None
            if f.is_integer():
                return int(f)
        raise bad
    if typ is float:
        if isinstance(value, bool):
            raise bad
        if isinstance(value, (int, float)):
            out = float(value)
        elif isinstance(value, str):
            try:
                out = float(value)
            except ValueError:
                raise bad from None
        else:
            raise bad
        if math.isnan(out):
            raise ConfigError(f"parameter {key!r}: value is NaN")
        return out
    if typ is str:
        if isinstance(value, str):
            return value
        raise bad
    return value


P = TypeVar("P", bound="Params")


@dataclass(frozen=True)
class Params:
    """Base class: type coercion and range checks for every field on construction."""

    section: ClassVar[str] = "params"

    def __post_init__(self) -> None:
        hints = typing.get_type_hints(type(self))
        for f in dataclasses.fields(self):
            value = _coerce(f.name, getattr(self, f.name), hints[f.name])
            object.__setattr__(self, f.name, value)
            m = f.metadata
            checks = (
                ("ge", lambda v, b: v >= b, ">="),
                ("gt", lambda v, b: v > b, ">"),
                ("le", lambda v, b: v <= b, "<="),
                ("lt", lambda v, b: v < b, "<"),
            )
            for name, ok, sym in checks:
                if name in m and not ok(value, m[name]):
                    raise ConfigError(
                        f"parameter {f.name!r} = {value!r} is out of range: must be {sym} {m[name]}"
                    )
            if "choices" in m and value not in m["choices"]:
                options = ", ".join(map(str, m["choices"]))
                raise ConfigError(f"parameter {f.name!r} = {value!r} is not one of {options}")

    @classmethod
    def keys(cls) -> list[str]:
        return [f.name for f in dataclasses.fields(cls)]

    @classmethod
    def from_dict(cls: type[P], values: dict[str, Any]) -> P:
        """Build from a mapping; unknown keys raise :class:`ConfigError` with a hint."""
        known = set(cls.keys())
        for key in values:
            if key not in known:
                raise ConfigError(unknown_name_message(f"{cls.section} parameter", key, known))
        return cls(**values)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def replace(self: P, **changes: Any) -> P:
        return self.from_dict({**self.to_dict(), **changes})


@dataclass(frozen=True)
class ExperienceMapParams(Params):
    """Experience-map parameters (OpenRatSLAM names and defaults)."""

    section: ClassVar[str] = "experience map"

    exp_correction: float = param(
        0.5,
        "alpha of the relaxation rule (Eq. 8): 0.5 moves a link's two ends until they agree "
        "(OpenRatSLAM); above 0.5 over-relaxes, which carries loop closures round long "
        "loops in far fewer passes (docs/experience-map.md)",
        gt=0.0,
        le=1.0,
    )
    exp_loops: int = param(10, "relaxation passes per step", ge=0)
    exp_initial_em_deg: float = param(90.0, "initial heading of the map (degrees)")
    exp_backend: str = param(
        "alpha",
        "relaxation backend: alpha | alpha_local | alpha_wave | alpha_reference | gtsam | isam2",
    )
    # Experience-map paper (Milford, Wyeth & Prasser 2006) features; defaults keep
    # OpenRatSLAM's behaviour (no averaging, no link deletion).
    exp_activity_zone_xy: float = param(
        2.0, "r_a of Eq. 1: pose-cell (x', y') zone constant of experience activity (cells)", gt=0.0
    )
    exp_activity_zone_th: float = param(
        2.0,
        "theta_a of Eq. 2: pose-cell theta' zone constant of experience activity (cells)",
        gt=0.0,
    )
    exp_create_rule: str = param(
        "pc_distance",
        "when a new experience is learnt: pc_distance (the pose cells' action, OpenRatSLAM: "
        "no experience of the current view within exp_delta_pc_threshold cells) | activity "
        "(the peak experience's activity, Eqs. 1-4, below exp_activity_threshold)",
        choices=("pc_distance", "activity"),
    )
    exp_activity_threshold: float = param(
        1.0,
        "exp_create_rule=activity: a new experience is learnt when the peak experience's "
        "activity (Eq. 3, in [0, 2]) is below this",
        gt=0.0,
        le=2.0,
    )
    exp_link_averaging: bool = param(
        False, "average repeated transitions into the existing link (Eq. 6); off in OpenRatSLAM"
    )
    exp_link_confidence_threshold: float = param(
        0.0,
        "delete a link when its confidence (Eq. 9) drops below this; 0 never deletes (OpenRatSLAM)",
        ge=0.0,
        le=1.0,
    )
    exp_link_directed: bool = param(
        False,
        "learn each driven transition a -> b as its own link even when b -> a exists (its "
        "own Eq. 9 counts and Eq. 6 average); false: a pair is linked once, either way "
        "(OpenRatSLAM)",
    )
    exp_link_overlap_m: float = param(
        0.0,
        "Eq. 9: a link whose target lies within this (m, in the map, facing within 45 "
        "degrees) of the experience reached is not counted a failure (it predicted the "
        "same place); 0: every other link of the behaviour fails (the paper's rule)",
        ge=0.0,
    )
    # OpenRatSLAM's exact behaviours and the project's alternatives, by name.
    # Defaults are OpenRatSLAM's; the ``behaviour`` profile of torchratslam.config sets
    # several of them at once (docs/openratslam-fidelity.md has each one's measured effect).
    exp_relax: str = param(
        "on_action",
        "when the pipeline relaxes the map: on_action (only on frames with an action, as "
        "OpenRatSLAM's action_callback) | every_frame",
        choices=("on_action", "every_frame"),
    )
    exp_first_at_origin: bool = param(
        False,
        "place the first experience at (0, 0) and restart the accumulators there; false: "
        "at the odometry accumulated so far, accumulators kept (OpenRatSLAM)",
    )
    exp_link_time: str = param(
        "since_start",
        "a link's time: since_start (OpenRatSLAM never resets accum_delta_time_s) | "
        "per_link (time since the previous link)",
        choices=("since_start", "per_link"),
    )
    exp_relax_budget: int = param(
        0,
        "link updates per relaxation at most (alpha backend, openratslam order); 0: "
        "exp_loops whole passes every time, as OpenRatSLAM. While exp_loops x links is "
        "within the budget the passes are OpenRatSLAM's; beyond it each relaxation makes "
        "this many updates, going on round the links where the previous one stopped, so "
        "its cost stays flat as the map grows",
        ge=0,
    )
    exp_relax_order: str = param(
        "openratslam",
        "link order of the alpha backend's sweep: openratslam (by source experience, then "
        "insertion, in place; compiled) | colour (vectorised colour classes, a different "
        "Gauss-Seidel order with a slightly different fixed point)",
        choices=("openratslam", "colour"),
    )
