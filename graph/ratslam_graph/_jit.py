"""numba's ``njit`` with its disk cache, and without it where numba can write no cache.

Every compiled kernel of the project is cached on disk by numba (``cache=True``): beside
its source (``__pycache__``), or, where that is read-only (an installed package), in the
user's cache directory (``NUMBA_CACHE_DIR``, else the platform's). Where neither can be
written, numba refuses to define a cached function at all; :func:`njit_cached` then
defines it uncached, so the package still imports and runs, compiling its kernels in
each process (a one-off cost of seconds; the results are the same).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from numba import njit

__all__ = ["njit_cached"]

log = logging.getLogger(__name__)


def njit_cached(**options: Any) -> Callable[[Callable[..., Any]], Any]:
    """``numba.njit(cache=True, **options)``, or ``cache=False`` when numba finds no
    directory it can write the cache to."""

    def decorate(fn: Callable[..., Any]) -> Any:
        try:
            return njit(cache=True, **options)(fn)
        except RuntimeError as exc:  # numba: "cannot cache function ...: no locator"
            if "no locator available" not in str(exc):
                raise
            log.debug("numba cannot cache %s (%s): compiled in this process only", fn, exc)
            return njit(cache=False, **options)(fn)

    return decorate
