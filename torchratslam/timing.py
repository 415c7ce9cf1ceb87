"""Per-module time logger, like xRatSLAM's: milliseconds per frame for each module.

Each module's work on one frame is timed on its own (``time.perf_counter`` around the
call), so the figures exclude time spent waiting on queues in the pipelined mode and
time spent reading the data. Recording is thread-safe: in the pipelined mode every
worker thread records its own module.

Example:
    >>> from torchratslam.timing import TimeLogger
    >>> log = TimeLogger()
    >>> with log.section("local_view"):
    ...     pass
    >>> log.summary()["local_view"]["count"]
    1
"""

from __future__ import annotations

import logging
import threading
import time
from array import array
from types import TracebackType
from typing import Any

import numpy as np

__all__ = ["MODULES", "TimeLogger", "watch_compiles"]

log = logging.getLogger(__name__)

MODULES = ("odometry", "local_view", "pose_cells", "experience_map")
"""The modules the pipeline times, in per-frame order."""


class _Section:
    """The ``with`` block of :meth:`TimeLogger.section` (a plain class: a generator-based
    context manager costs several microseconds a frame)."""

    __slots__ = ("_log", "_module", "_t0")

    def __init__(self, log: TimeLogger, module: str) -> None:
        self._log = log
        self._module = module
        self._t0 = 0.0

    def __enter__(self) -> None:
        self._t0 = time.perf_counter()

    def __exit__(
        self,
        kind: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._log.record(self._module, time.perf_counter() - self._t0)


class TimeLogger:
    """Collects one duration per frame for each named module, compactly (8 bytes a
    duration, in :class:`array.array`).

    Args:
        modules: names known from the start (they appear in :meth:`summary` even when
            never timed); other names are added on first use.
    """

    def __init__(self, modules: tuple[str, ...] | list[str] = MODULES) -> None:
        self._lock = threading.Lock()
        self._ms: dict[str, array] = {name: array("d") for name in modules}

    def record(self, module: str, seconds: float) -> None:
        """Append one frame's duration (seconds) for ``module``."""
        with self._lock:
            values = self._ms.get(module)
            if values is None:
                values = self._ms[module] = array("d")
            values.append(seconds * 1000.0)

    def section(self, module: str) -> _Section:
        """Time the body of a ``with`` block as one frame of ``module``."""
        return _Section(self, module)

    def reset(self) -> None:
        """Forget every recorded duration (module names are kept)."""
        with self._lock:
            for name in self._ms:
                self._ms[name] = array("d")

    @property
    def modules(self) -> list[str]:
        """Module names in first-use order."""
        return list(self._ms)

    def per_frame_ms(self, module: str) -> np.ndarray:
        """The recorded durations of ``module`` in milliseconds, in frame order.

        Shape:
            returns ``(F,)`` float64, F the number of frames recorded for the module.
        """
        with self._lock:
            return np.array(self._ms.get(module, ()), dtype=np.float64)

    def count(self, module: str) -> int:
        """How many durations ``module`` has recorded."""
        with self._lock:
            return len(self._ms.get(module, ()))

    def ms_at(self, module: str, index: int) -> float:
        """The ``index``-th recorded duration of ``module`` (ms); NaN if not recorded."""
        with self._lock:
            values = self._ms.get(module, ())
            return float(values[index]) if 0 <= index < len(values) else float("nan")

    def summary(self) -> dict[str, dict[str, Any]]:
        """Per module: ``count``, ``mean_ms``, ``median_ms``, ``max_ms``, ``total_s``.

        A ``"total"`` entry sums the modules frame by frame (over the frames that
        every timed module recorded).
        """
        out: dict[str, dict[str, Any]] = {}
        columns = []
        for name in self.modules:
            ms = self.per_frame_ms(name)
            out[name] = _stats(ms)
            if ms.size:
                columns.append(ms)
        if columns:
            n = min(c.size for c in columns)
            out["total"] = _stats(np.sum([c[:n] for c in columns], axis=0))
        else:
            out["total"] = _stats(np.zeros(0))
        return out

    def table(self) -> str:
        """A Markdown table of :meth:`summary`."""
        lines = ["| module | frames | mean ms | median ms | max ms |", "|---|---|---|---|---|"]
        for name, s in self.summary().items():
            lines.append(
                f"| {name} | {s['count']} | {s['mean_ms']:.3f} | {s['median_ms']:.3f} "
                f"| {s['max_ms']:.3f} |"
            )
        return "\n".join(lines)


def _stats(ms: np.ndarray) -> dict[str, Any]:
    if ms.size == 0:
        return {"count": 0, "mean_ms": 0.0, "median_ms": 0.0, "max_ms": 0.0, "total_s": 0.0}
    return {
        "count": int(ms.size),
        "mean_ms": float(ms.mean()),
        "median_ms": float(np.median(ms)),
        "max_ms": float(ms.max()),
        "total_s": float(ms.sum() / 1000.0),
    }


_WATCHING = {"on": False, "said": False}


def watch_compiles() -> None:
    """Say once per process, before it starts, that numba is compiling torchratslam's
    kernels (the first use after installing or updating: up to ~15 s; numba caches them
    on disk, so later runs load them in a moment). Idempotent and cheap after the first
    call; nothing happens without numba."""
    if _WATCHING["on"]:
        return
    _WATCHING["on"] = True
    try:
        from numba.core import event
    except ImportError:  # pragma: no cover - numba is a dependency
        return

    class _Notice(event.Listener):
        def on_start(self, ev: Any) -> None:
            if _WATCHING["said"]:
                return
            fn = getattr(ev.data.get("dispatcher"), "py_func", None)
            if not str(getattr(fn, "__module__", "")).startswith("torchratslam."):
                return
            _WATCHING["said"] = True
            log.warning(
                "compiling torchratslam's numba kernels (the first use after installing or "
                "updating: up to ~15 s, once; they are cached on disk, and a run's frames/s "
                "leaves this start-up out)"
            )

        def on_end(self, ev: Any) -> None:
            pass

    event.register("numba:compile", _Notice())
