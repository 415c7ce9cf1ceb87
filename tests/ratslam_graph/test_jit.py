"""njit_cached: numba's disk cache where it can write one; where it cannot (a read-only
install with no writable cache directory), the same kernel, uncached."""

from __future__ import annotations

import numpy as np
import pytest
from numba.core import caching

from ratslam_graph._jit import njit_cached


def _twice_sum(a):
    s = 0.0
    for v in a:
        s += 2.0 * v
    return s


def test_a_kernel_is_cached_where_numba_can_write_a_cache():
    f = njit_cached(nogil=True)(_twice_sum)
    assert f._cache.__class__.__name__ == "FunctionCache"
    assert f(np.arange(4.0)) == 12.0


def test_without_a_writable_cache_directory_the_kernel_is_compiled_uncached(monkeypatch):
    monkeypatch.setattr(caching.CacheImpl, "_locator_classes", [])
    with pytest.raises(RuntimeError, match="no locator available"):
        from numba import njit

        njit(cache=True)(_twice_sum)
    f = njit_cached(nogil=True)(_twice_sum)
    assert f._cache.__class__.__name__ == "NullCache"
    x = np.random.default_rng(0).random(50)
    assert f(x) == _twice_sum(x)
