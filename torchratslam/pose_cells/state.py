"""The pose-cell stage's state as a typed, versioned record.

:class:`PoseCellState` holds what a pose-cell module's ``get_state()`` returns (numpy
arrays and Python scalars) as typed, shape-checked fields; :meth:`~PoseCellState.to_dict`
gives back the dictionary its ``set_state()`` takes. Importing it loads no torch.

Example:
    >>> import numpy as np
    >>> from torchratslam.pose_cells.state import PoseCellState
    >>> s = PoseCellState.empty()
    >>> s.n_templates, s.n_experiences, s.activity.shape
    (0, 0, (0, 0, 0))
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ratslam_graph.state import fields_equal
from torchratslam.errors import MapFormatError

__all__ = ["PoseCellState"]

# the optional scalars, in get_state()'s order, with the type each is read as
_SCALARS: dict[str, type] = {
    "vt_delta_pc_th": float,
    "relative_rad": float,
    "odo_update": bool,
    "vt_update": bool,
    "pc_dim_xy": int,
    "pc_dim_th": int,
    "pc_dim_x": int,
    "pc_dim_y": int,
}
_KNOWN = (
    "activity",
    "template_pc",
    "template_decay",
    "exp_pc",
    "exp_template",
    "best",
    "current_exp",
    "current_vt",
    "prev_vt",
    *_SCALARS,
)


def _array(value: Any) -> np.ndarray:
    return np.asarray(value.detach().cpu().numpy() if hasattr(value, "detach") else value)


def _optional(value: Any, kind: type) -> Any:
    return None if value is None else kind(value)


@dataclass(frozen=True, eq=False)
class PoseCellState:
    """The pose cells: the activity and each template's and experience's cell.

    Attributes:
        activity: ``(TH, Y, X)`` the activity, or ``(0, 0, 0)`` when unknown.
        template_pc: ``(N, 3)`` float64 cell (x, y, th) of each template.
        template_decay: ``(N,)`` float64 decay of each template's injection.
        exp_pc: ``(M, 3)`` float64 cell of each experience.
        exp_template: ``(M,)`` int64 template of each experience.
        best: ``(3,)`` float64 last decoded packet centre (None: not given).
        current_exp, current_vt, prev_vt: ids (None: not given).
        vt_delta_pc_th, relative_rad, odo_update, vt_update, pc_dim_xy, pc_dim_th,
            pc_dim_x, pc_dim_y: the module's scalars (None: not given; a square network
            gives no pc_dim_x / pc_dim_y).
        extra: further keys of the module's dictionary, in its order.
    """

    VERSION: ClassVar[int] = 1

    activity: np.ndarray
    template_pc: np.ndarray
    template_decay: np.ndarray
    exp_pc: np.ndarray
    exp_template: np.ndarray
    best: np.ndarray | None = None
    current_exp: int | None = None
    current_vt: int | None = None
    prev_vt: int | None = None
    vt_delta_pc_th: float | None = None
    relative_rad: float | None = None
    odo_update: bool | None = None
    vt_update: bool | None = None
    pc_dim_xy: int | None = None
    pc_dim_th: int | None = None
    pc_dim_x: int | None = None
    pc_dim_y: int | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = self.template_pc.shape[0] if isinstance(self.template_pc, np.ndarray) else -1
        m = self.exp_pc.shape[0] if isinstance(self.exp_pc, np.ndarray) else -1
        act = self.activity
        act_shape = act.shape if isinstance(act, np.ndarray) and act.ndim == 3 else None
        expect: dict[str, tuple[tuple[int, ...] | None, str]] = {
            "activity": (act_shape, "f"),
            "template_pc": ((n, 3), "f"),
            "template_decay": ((n,), "f"),
            "exp_pc": ((m, 3), "f"),
            "exp_template": ((m,), "iu"),
        }
        if self.best is not None:
            expect["best"] = ((3,), "f")
        for name, (shape, kinds) in expect.items():
            a = getattr(self, name)
            if not isinstance(a, np.ndarray) or a.shape != shape or a.dtype.kind not in kinds:
                got = f"{a.dtype}{a.shape}" if isinstance(a, np.ndarray) else type(a).__name__
                want = "(TH, Y, X)" if name == "activity" else str(shape)
                raise MapFormatError(
                    f"pose-cell state: {name} is {got}, expected {want} "
                    f"{'floats' if kinds == 'f' else 'integers'} (N={n} templates, "
                    f"M={m} experiences); the map is corrupt"
                )

    @property
    def n_templates(self) -> int:
        return int(self.template_pc.shape[0])

    @property
    def n_experiences(self) -> int:
        return int(self.exp_pc.shape[0])

    @classmethod
    def empty(cls) -> PoseCellState:
        """No templates, no experiences, unknown activity."""
        return cls(
            activity=np.zeros((0, 0, 0)),
            template_pc=np.zeros((0, 3)),
            template_decay=np.zeros(0),
            exp_pc=np.zeros((0, 3)),
            exp_template=np.zeros(0, np.int64),
        )

    @classmethod
    def from_dict(cls, state: Mapping[str, Any]) -> PoseCellState:
        """The record of a pose-cell module's ``get_state()`` dictionary.

        Raises:
            MapFormatError: a required key is missing or an array has the wrong shape.
        """
        try:
            best = state.get("best")
            return cls(
                activity=np.ascontiguousarray(_array(state["activity"])),
                template_pc=_array(state["template_pc"]).astype(np.float64).reshape(-1, 3),
                template_decay=_array(state["template_decay"]).astype(np.float64),
                exp_pc=_array(state["exp_pc"]).astype(np.float64).reshape(-1, 3),
                exp_template=_array(state["exp_template"]).astype(np.int64),
                best=None if best is None else _array(best).astype(np.float64).reshape(3),
                current_exp=_optional(state.get("current_exp"), int),
                current_vt=_optional(state.get("current_vt"), int),
                prev_vt=_optional(state.get("prev_vt"), int),
                **{k: _optional(state.get(k), kind) for k, kind in _SCALARS.items()},
                extra={k: v for k, v in state.items() if k not in _KNOWN},
            )
        except MapFormatError:
            raise
        except (KeyError, ValueError, TypeError) as exc:
            raise MapFormatError(
                f"pose-cell state is incomplete or malformed ({exc!r}); was it made by get_state()?"
            ) from None

    def to_dict(self) -> dict[str, Any]:
        """The ``set_state()`` dictionary (keys in ``get_state()``'s order; the optional
        ones only when given)."""
        out: dict[str, Any] = {
            "activity": self.activity.copy(),
            "template_pc": self.template_pc.copy(),
            "template_decay": self.template_decay.copy(),
            "exp_pc": self.exp_pc.copy(),
            "exp_template": self.exp_template.copy(),
        }
        if self.best is not None:
            out["best"] = self.best.copy()
        for name in ("current_exp", "current_vt", "prev_vt", *_SCALARS):
            value = getattr(self, name)
            if value is not None:
                out[name] = value
        out.update(self.extra)
        return out

    def replace(self, **changes: Any) -> PoseCellState:
        """A copy with ``changes`` (checked again)."""
        return dataclasses.replace(self, **changes)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, PoseCellState):
            return NotImplemented
        return fields_equal(self, other)
