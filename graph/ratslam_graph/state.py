"""The experience map's state as a typed, versioned record.

:class:`ExperienceMapState` holds what ``ExperienceMap.get_state()`` returns (numpy
arrays and Python scalars) as typed, shape-checked fields; :meth:`~ExperienceMapState.to_dict`
gives back the dictionary ``ExperienceMap.set_state()`` takes.

Example:
    >>> import numpy as np
    >>> from ratslam_graph.state import ExperienceMapState
    >>> s = ExperienceMapState.empty()
    >>> s.n_experiences, s.n_links
    (0, 0)
    >>> ExperienceMapState.from_dict(s.to_dict()) == s
    True
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ratslam_graph.errors import MapFormatError

__all__ = ["ExperienceMapState", "fields_equal"]

_KNOWN = (
    "format",
    "version",
    "poses",
    "pc",
    "template_id",
    "frame",
    "t",
    "link_ends",
    "link_values",
    "link_counts",
    "link_behaviour",
    "current_id",
    "prev_id",
    "accum_x",
    "accum_y",
    "accum_facing",
    "accum_time",
    "relative_rad",
    "relax_cursor",
)


def _array(value: Any) -> np.ndarray:
    return np.asarray(value.detach().cpu().numpy() if hasattr(value, "detach") else value)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b)


@dataclass(frozen=True, eq=False)
class ExperienceMapState:
    """The experience map: experiences, links and the odometry since the current one.

    Attributes:
        poses: ``(M, 3)`` float64 experience poses [x m, y m, th rad].
        pc: ``(M, 3)`` float64 pose-cell coordinates of each experience.
        template_id: ``(M,)`` int64 template of each experience.
        frame: ``(M,)`` int64 frame at which each experience was created.
        t: ``(M,)`` float64 creation time of each experience (s).
        link_ends: ``(L, 2)`` int64 (from, to) experience ids.
        link_values: ``(L, 4)`` float64 (d, heading, facing, dt) of each link.
        link_counts: ``(L, 3)`` int64 per-link counters.
        link_behaviour: ``(L,)`` int64 behaviour of each link.
        current_id, prev_id: the current and previous experience (-1: none).
        accum_x, accum_y, accum_facing, accum_time: odometry accumulated since the
            current experience (m, m, rad, s).
        format, version: the stage's state format and version (None: not given, e.g.
            a map imported from another format).
        relative_rad: the last action's relative angle (None: not given).
        relax_cursor: where the incremental relaxation stands (None: not given).
        extra: further keys of the stage's dictionary, in its order.
    """

    VERSION: ClassVar[int] = 1
    FORMAT: ClassVar[str] = "ratslam_graph.experience_map"

    poses: np.ndarray
    pc: np.ndarray
    template_id: np.ndarray
    frame: np.ndarray
    t: np.ndarray
    link_ends: np.ndarray
    link_values: np.ndarray
    link_counts: np.ndarray
    link_behaviour: np.ndarray
    current_id: int = -1
    prev_id: int = -1
    accum_x: float = 0.0
    accum_y: float = 0.0
    accum_facing: float = 0.0
    accum_time: float = 0.0
    format: str | None = None
    version: int | None = None
    relative_rad: float | None = None
    relax_cursor: int | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.validate()

    @property
    def n_experiences(self) -> int:
        return int(self.poses.shape[0])

    @property
    def n_links(self) -> int:
        return int(self.link_ends.shape[0])

    @classmethod
    def empty(cls) -> ExperienceMapState:
        """A map with no experiences and no links."""
        return cls(
            poses=np.zeros((0, 3)),
            pc=np.zeros((0, 3)),
            template_id=np.zeros(0, np.int64),
            frame=np.zeros(0, np.int64),
            t=np.zeros(0),
            link_ends=np.zeros((0, 2), np.int64),
            link_values=np.zeros((0, 4)),
            link_counts=np.zeros((0, 3), np.int64),
            link_behaviour=np.zeros(0, np.int64),
        )

    def validate(self) -> None:
        """Check every array's shape and dtype.

        Raises:
            MapFormatError: naming the first field that is wrong.
        """
        m, el = self.poses.shape[0] if self.poses.ndim == 2 else -1, -1
        if self.link_ends.ndim == 2:
            el = self.link_ends.shape[0]
        expect = {
            "poses": ((m, 3), "f"),
            "pc": ((m, 3), "f"),
            "template_id": ((m,), "iu"),
            "frame": ((m,), "iu"),
            "t": ((m,), "f"),
            "link_ends": ((el, 2), "iu"),
            "link_values": ((el, 4), "f"),
            "link_counts": ((el, 3), "iu"),
            "link_behaviour": ((el,), "iu"),
        }
        for name, (shape, kinds) in expect.items():
            a = getattr(self, name)
            if not isinstance(a, np.ndarray) or a.shape != shape or a.dtype.kind not in kinds:
                got = f"{a.dtype}{a.shape}" if isinstance(a, np.ndarray) else type(a).__name__
                raise MapFormatError(
                    f"experience-map state: {name} is {got}, expected shape {shape} of "
                    f"{'floats' if kinds == 'f' else 'integers'} (M={m} experiences, "
                    f"L={el} links); the map is corrupt"
                )

    @classmethod
    def from_dict(cls, state: Mapping[str, Any]) -> ExperienceMapState:
        """The record of an ``ExperienceMap.get_state()`` dictionary.

        Raises:
            MapFormatError: a required key is missing or an array has the wrong shape.
        """
        try:
            ends = _array(state["link_ends"]).reshape(-1, 2)
            vals = _array(state["link_values"]).reshape(-1, 4)
            return cls(
                poses=_array(state["poses"]).astype(np.float64).reshape(-1, 3),
                pc=_array(state["pc"]).astype(np.float64).reshape(-1, 3),
                template_id=_array(state["template_id"]).astype(np.int64),
                frame=_array(state["frame"]).astype(np.int64),
                t=_array(state["t"]).astype(np.float64),
                link_ends=ends.astype(np.int64),
                link_values=vals.astype(np.float64),
                link_counts=_array(state["link_counts"]).astype(np.int64).reshape(-1, 3),
                link_behaviour=_array(state["link_behaviour"]).astype(np.int64).reshape(-1),
                current_id=int(state["current_id"]),
                prev_id=int(state["prev_id"]),
                accum_x=float(state["accum_x"]),
                accum_y=float(state["accum_y"]),
                accum_facing=float(state["accum_facing"]),
                accum_time=float(state["accum_time"]),
                format=state.get("format"),
                version=state.get("version"),
                relative_rad=state.get("relative_rad"),
                relax_cursor=state.get("relax_cursor"),
                extra={k: v for k, v in state.items() if k not in _KNOWN},
            )
        except MapFormatError:
            raise
        except (KeyError, ValueError, TypeError) as exc:
            raise MapFormatError(
                f"experience-map state is incomplete or malformed ({exc!r}); was it made "
                "by get_state()?"
            ) from None

    def to_dict(self) -> dict[str, Any]:
        """The ``ExperienceMap.set_state()`` dictionary (keys in ``get_state()``'s order;
        the optional ones only when given)."""
        out: dict[str, Any] = {}
        if self.format is not None:
            out["format"] = self.format
        if self.version is not None:
            out["version"] = self.version
        out.update(
            {
                "poses": self.poses.copy(),
                "pc": self.pc.copy(),
                "template_id": self.template_id.copy(),
                "frame": self.frame.copy(),
                "t": self.t.copy(),
                "link_ends": self.link_ends.copy(),
                "link_values": self.link_values.copy(),
                "link_counts": self.link_counts.copy(),
                "link_behaviour": self.link_behaviour.copy(),
                "current_id": int(self.current_id),
                "prev_id": int(self.prev_id),
                "accum_x": float(self.accum_x),
                "accum_y": float(self.accum_y),
                "accum_facing": float(self.accum_facing),
                "accum_time": float(self.accum_time),
            }
        )
        if self.relative_rad is not None:
            out["relative_rad"] = self.relative_rad
        if self.relax_cursor is not None:
            out["relax_cursor"] = self.relax_cursor
        out.update(self.extra)
        return out

    def replace(self, **changes: Any) -> ExperienceMapState:
        """A copy with ``changes`` (checked again)."""
        return dataclasses.replace(self, **changes)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ExperienceMapState):
            return NotImplemented
        return fields_equal(self, other)


def fields_equal(a: Any, b: Any) -> bool:
    """Exact equality of two records' fields (arrays: values, dtypes and shapes)."""
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            if not (isinstance(x, np.ndarray) and isinstance(y, np.ndarray) and _same(x, y)):
                return False
        elif isinstance(x, Mapping) and isinstance(y, Mapping):
            if x.keys() != y.keys() or not all(
                _same(np.asarray(x[k]), np.asarray(y[k])) for k in x
            ):
                return False
        elif x != y:
            return False
    return True
