"""Plain registries of swappable modules (xRatSLAM's idea, without an if-chain factory).

Each registry is typed with the :mod:`torchratslam.protocols` interface of its stage
and checks what it builds against it (``isinstance`` on the runtime-checkable protocol),
so a module that lacks part of the interface fails at construction with one clear line.

Example:
    >>> from torchratslam.registry import LOCAL_VIEWS
    >>> @LOCAL_VIEWS.register("my_view")
    ... class MyView: ...
    >>> LOCAL_VIEWS.get("my_view") is MyView
    True
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterator
from typing import Any, Generic, TypeVar

from ratslam_graph.errors import unknown_name_message
from torchratslam.errors import ConfigError
from torchratslam.protocols import (
    ExperienceMapModule,
    LocalViewModule,
    OdometrySource,
    PoseCellModule,
    RangeMapper,
)

T = TypeVar("T")
P = TypeVar("P")

Factory = Callable[..., Any]


def _interface(protocol: type) -> list[str]:
    """The members a protocol asks for (its methods, properties and annotated fields)."""
    names: set[str] = set()
    for cls in protocol.__mro__:
        if cls in (object, Generic) or not getattr(cls, "_is_protocol", False):
            continue
        names.update(n for n in vars(cls) if not n.startswith("_") or n in ("__len__", "__call__"))
        names.update(getattr(cls, "__annotations__", {}))
    return sorted(names)


_MISSING = object()


def _has_members(obj: Any, protocol: type) -> bool:
    """Whether ``obj`` has every member of ``protocol`` (:func:`_interface`), looked up as
    Python 3.12's ``isinstance`` does (:func:`inspect.getattr_static`): no property is
    evaluated (3.11's ``hasattr`` would, and an experience map's networkx graph would be
    built, and networkx imported, by the check). False when one is missing (then
    ``isinstance`` decides)."""
    for name in _interface(protocol):
        found = inspect.getattr_static(obj, name, _MISSING)
        if found is _MISSING or (found is None and callable(getattr(protocol, name, None))):
            return False
    return True


class Registry(Generic[P]):
    """A name -> factory mapping for one kind of module.

    Args:
        kind: what the modules are, for messages ("local view").
        protocol: the interface every built module must have (None: no check).
    """

    def __init__(self, kind: str, protocol: type[P] | None = None) -> None:
        self.kind = kind
        self.protocol = protocol
        self._items: dict[str, Factory] = {}

    def register(self, name: str, obj: Any = None, *, overwrite: bool = False) -> Any:
        """Register ``obj`` under ``name``; usable as a decorator when ``obj`` is omitted."""

        def add(target: T) -> T:
            if name in self._items and not overwrite and self._items[name] is not target:
                raise ConfigError(
                    f"{self.kind} {name!r} is already registered (pass overwrite=True)"
                )
            self._items[name] = target  # type: ignore[assignment]
            return target

        return add(obj) if obj is not None else add

    def get(self, name: str) -> Factory:
        """The factory registered under ``name``.

        Raises:
            ConfigError: no such name (the message lists the known ones).
        """
        if name not in self._items:
            raise ConfigError(unknown_name_message(self.kind, name, self._items))
        return self._items[name]

    def build(self, spec: Any, *args: Any, **kwargs: Any) -> P:
        """A module from a registered name, a class (called with the arguments) or an
        instance (used as is), checked against the registry's protocol.

        Raises:
            ConfigError: unknown name, no spec, or a module without the interface.
        """
        if isinstance(spec, str):
            obj = self.get(spec)(*args, **kwargs)
        elif isinstance(spec, type):
            obj = spec(*args, **kwargs)
        elif spec is None:
            raise ConfigError(
                f"no {self.kind} given: pass a registered name ({', '.join(self.names())})"
            )
        else:
            obj = spec
        return self.check(obj)

    def check(self, obj: Any) -> P:
        """``obj`` if it has the protocol's interface.

        Raises:
            ConfigError: naming the members it lacks.
        """
        if (
            self.protocol is not None
            and not _has_members(obj, self.protocol)
            and not isinstance(obj, self.protocol)
        ):
            missing = [m for m in _interface(self.protocol) if not hasattr(obj, m)]
            article = "an" if self.kind[0] in "aeiou" else "a"
            raise ConfigError(
                f"{type(obj).__name__} is not {article} {self.kind}: it lacks "
                f"{', '.join(missing) or 'part of the interface'} "
                f"(see torchratslam.protocols.{self.protocol.__name__})"
            )
        return obj

    def names(self) -> list[str]:
        """The registered names, sorted."""
        return sorted(self._items)

    def __contains__(self, name: object) -> bool:
        return name in self._items

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, {self.names()})"


LOCAL_VIEWS: Registry[LocalViewModule] = Registry("local view", LocalViewModule)
POSE_CELLS: Registry[PoseCellModule] = Registry("pose-cell module", PoseCellModule)
EXPERIENCE_MAPS: Registry[ExperienceMapModule] = Registry("experience map", ExperienceMapModule)
ODOMETRY: Registry[OdometrySource] = Registry("odometry source", OdometrySource)
RANGE_MAPPERS: Registry[RangeMapper] = Registry("range-sensor mapper", RangeMapper)
"""Place recognition and mapping from laser scans (the alternative to local view + experience
map for range sensors); ``"mbaram"`` is registered by :mod:`torchratslam.mbaram.mapper`.
Factory: ``factory(params, *, odometry="groundtruth", dtype, device)``; the mapper has the
:class:`~torchratslam.protocols.RangeMapper` interface."""
