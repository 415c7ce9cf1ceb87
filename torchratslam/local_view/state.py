"""The local view's state as a typed, versioned record.

:class:`LocalViewState` holds what a local view's ``get_state()`` returns (numpy arrays
and Python scalars) as typed, shape-checked fields; :meth:`~LocalViewState.to_dict`
gives back the dictionary its ``set_state()`` takes. Importing it loads no torch.

Example:
    >>> import numpy as np
    >>> from torchratslam.local_view.state import LocalViewState
    >>> s = LocalViewState(templates=np.zeros((2, 3, 4)))
    >>> s.n_templates, s.template_shape, s.frames.tolist()
    (2, (3, 4), [-1, -1])
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ratslam_graph.state import fields_equal
from torchratslam.errors import MapFormatError

__all__ = ["LocalViewState"]

_KNOWN = (
    "kind",
    "version",
    "template_shape",
    "templates",
    "means",
    "frames",
    "current_id",
    "previous_id",
    "frame_counter",
)


def _array(value: Any) -> np.ndarray:
    return np.asarray(value.detach().cpu().numpy() if hasattr(value, "detach") else value)


@dataclass(frozen=True, eq=False)
class LocalViewState:
    """The local view cells: the templates and the current match.

    Attributes:
        templates: ``(N, Y, X)`` the templates (float32 or float64, kept as given).
        means: ``(N,)`` float64 mean of each template (None: computed from the templates).
        frames: ``(N,)`` int64 frame at which each template was learnt (None: all -1).
        current_id, previous_id: the current and previous template (-1: none).
        kind, version: the module's kind and state version (None: not given).
        frame_counter: frames the module has seen (None: not given).
        extra: further keys of the module's dictionary (a subclass's own state), in
            its order.

    Shape:
        templates: ``(N, Y, X)``; means, frames: ``(N,)``.
    """

    VERSION: ClassVar[int] = 1

    templates: np.ndarray
    means: np.ndarray = None  # type: ignore[assignment]  # filled in __post_init__
    frames: np.ndarray = None  # type: ignore[assignment]  # filled in __post_init__
    current_id: int = -1
    previous_id: int = -1
    kind: str | None = None
    version: int | None = None
    frame_counter: int | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = self.templates
        if not isinstance(t, np.ndarray) or t.ndim != 3 or t.dtype.kind != "f":
            got = f"{t.dtype}{t.shape}" if isinstance(t, np.ndarray) else type(t).__name__
            raise MapFormatError(
                f"local view state: templates are {got}, expected (N, Y, X) floats; "
                "the map is corrupt"
            )
        n = t.shape[0]
        if self.means is None:
            means = t.reshape(n, -1).mean(1) if n else np.zeros(0)
            object.__setattr__(self, "means", np.asarray(means, np.float64))
        if self.frames is None:
            object.__setattr__(self, "frames", np.full(n, -1, np.int64))
        for name, kinds in (("means", "f"), ("frames", "iu")):
            a = getattr(self, name)
            if not isinstance(a, np.ndarray) or a.shape != (n,) or a.dtype.kind not in kinds:
                got = f"{a.dtype}{a.shape}" if isinstance(a, np.ndarray) else type(a).__name__
                raise MapFormatError(
                    f"local view state: {name} is {got}, expected ({n},) "
                    f"{'floats' if kinds == 'f' else 'integers'} (one per template)"
                )

    @property
    def n_templates(self) -> int:
        return int(self.templates.shape[0])

    @property
    def template_shape(self) -> tuple[int, int]:
        """``(Y, X)`` of the templates."""
        return int(self.templates.shape[1]), int(self.templates.shape[2])

    @classmethod
    def from_dict(cls, state: Mapping[str, Any]) -> LocalViewState:
        """The record of a local view's ``get_state()`` dictionary.

        Raises:
            MapFormatError: ``templates`` is missing or an array has the wrong shape.
        """
        try:
            templates = np.ascontiguousarray(_array(state["templates"]))
            optional = {
                k: _array(state[k]).astype(kind)
                for k, kind in (("means", np.float64), ("frames", np.int64))
                if state.get(k) is not None
            }
            return cls(
                templates=templates,
                **optional,
                current_id=int(state.get("current_id", -1)),
                previous_id=int(state.get("previous_id", -1)),
                kind=state.get("kind"),
                version=state.get("version"),
                frame_counter=state.get("frame_counter"),
                extra={k: v for k, v in state.items() if k not in _KNOWN},
            )
        except MapFormatError:
            raise
        except (KeyError, ValueError, TypeError) as exc:
            raise MapFormatError(
                f"local view state is malformed ({exc!r}); was it made by get_state()?"
            ) from None

    def to_dict(self) -> dict[str, Any]:
        """The ``set_state()`` dictionary (keys in ``get_state()``'s order; the optional
        ones only when given)."""
        out: dict[str, Any] = {}
        if self.kind is not None:
            out["kind"] = self.kind
        if self.version is not None:
            out["version"] = self.version
        out.update(
            {
                "template_shape": np.asarray(self.template_shape, np.int64),
                "templates": np.ascontiguousarray(self.templates),
                "means": self.means.copy(),
                "frames": self.frames.copy(),
                "current_id": int(self.current_id),
                "previous_id": int(self.previous_id),
            }
        )
        if self.frame_counter is not None:
            out["frame_counter"] = self.frame_counter
        out.update(self.extra)
        return out

    def replace(self, **changes: Any) -> LocalViewState:
        """A copy with ``changes`` (checked again)."""
        return dataclasses.replace(self, **changes)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, LocalViewState):
            return NotImplemented
        return fields_equal(self, other)
