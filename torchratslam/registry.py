"""Plain registries of swappable modules (xRatSLAM's idea, without an if-chain factory).

Example:
    >>> from torchratslam.registry import LOCAL_VIEWS
    >>> @LOCAL_VIEWS.register("my_view")
    ... class MyView: ...
    >>> LOCAL_VIEWS.get("my_view") is MyView
    True
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any, TypeVar

from torchratslam.graph.errors import ConfigError, unknown_name_message

T = TypeVar("T")


class Registry:
    """A name -> factory mapping for one kind of module."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._items: dict[str, Any] = {}

    def register(self, name: str, obj: Any = None, *, overwrite: bool = False) -> Any:
        """Register ``obj`` under ``name``; usable as a decorator when ``obj`` is omitted."""

        def add(target: T) -> T:
            if name in self._items and not overwrite and self._items[name] is not target:
                raise ConfigError(
                    f"{self.kind} {name!r} is already registered (pass overwrite=True)"
                )
            self._items[name] = target
            return target

        return add(obj) if obj is not None else add

    def get(self, name: str) -> Any:
        if name not in self._items:
            raise ConfigError(unknown_name_message(self.kind, name, self._items))
        return self._items[name]

    def names(self) -> list[str]:
        return sorted(self._items)

    def __contains__(self, name: object) -> bool:
        return name in self._items

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, {self.names()})"


LOCAL_VIEWS = Registry("local view")
POSE_CELLS = Registry("pose-cell module")
EXPERIENCE_MAPS = Registry("experience map")
ODOMETRY = Registry("odometry source")
RANGE_MAPPERS = Registry("range-sensor mapper")
"""Place recognition and mapping from laser scans (the alternative to local view + experience
map for range sensors); ``"mbaram"`` is registered by :mod:`torchratslam.mbaram.model`.
Factory: ``factory(params, *, odometry="groundtruth", dtype, device)``; the mapper has
``learn(frame) -> int``, ``localise(frame, *, odometry=True) -> int`` (the node, -1 = none),
``__len__`` and ``model``."""

Factory = Callable[..., Any]
