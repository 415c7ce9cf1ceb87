"""OpenRatSLAM's ``ExperienceMap::iterate`` loop compiled with numba (imported lazily).

The arithmetic is the C++'s, operation for operation: ``clip_rad_180`` and
``clip_rad_360`` as subtraction loops (kept here, not
:func:`ratslam_graph.geometry.wrap_angle`'s floor remainder, because the two differ
in the last bit and the sweep must reproduce the C++ bit for bit),
``get_signed_delta_rad`` with its two clips, the link as ``(d, heading, facing)``,
poses updated in place link after link. Compiled
functions are cached on disk by numba (``cache=True``); the first use in a fresh
environment compiles them (about a second). Call it through
:func:`ratslam_graph.backends.alpha.sweep_openratslam`.
"""

from __future__ import annotations

import math

import numpy as np

from ratslam_graph._jit import njit_cached

PI = math.pi
TWO_PI = 2.0 * math.pi
IDLE_SHARE = 16
"""Once at least one update in this many changed nothing in a pass, :func:`sweep` goes
on in :func:`sweep_skipping`."""


@njit_cached(nogil=True)
def clip_rad_180(a: float) -> float:  # pragma: no cover - compiled
    """OpenRatSLAM's ``clip_rad_180``: to ``(-pi, pi]`` by whole turns."""
    while a > PI:
        a -= TWO_PI
    while a <= -PI:
        a += TWO_PI
    return a


@njit_cached(nogil=True)
def clip_rad_360(a: float) -> float:  # pragma: no cover - compiled
    """OpenRatSLAM's ``clip_rad_360``: to ``[0, 2 pi)`` by whole turns."""
    while a < 0.0:
        a += TWO_PI
    while a >= TWO_PI:
        a -= TWO_PI
    return a


@njit_cached(nogil=True)
def get_signed_delta_rad(a1: float, a2: float) -> float:  # pragma: no cover - compiled
    """OpenRatSLAM's ``get_signed_delta_rad`` (from ``a1`` to ``a2``)."""
    direction = clip_rad_180(a2 - a1)
    delta = abs(clip_rad_360(a1) - clip_rad_360(a2))
    if delta < TWO_PI - delta:
        return delta if direction > 0 else -delta
    return TWO_PI - delta if direction > 0 else -(TWO_PI - delta)


@njit_cached(nogil=True, inline="always")
def relax_link(
    pose: np.ndarray, f: int, t: int, link: np.ndarray, k: int, c: float
) -> bool:  # pragma: no cover - compiled
    """OpenRatSLAM's update of one link ``k`` (``f -> t``), in place, its arithmetic;
    True if any value changed."""
    xf = pose[f, 0]
    yf = pose[f, 1]
    thf = pose[f, 2]
    xt = pose[t, 0]
    yt = pose[t, 1]
    tht = pose[t, 2]
    d = link[k, 0]
    lx = xf + d * math.cos(thf + link[k, 1])
    ly = yf + d * math.sin(thf + link[k, 1])
    ex = (xt - lx) * c
    ey = (yt - ly) * c
    nxf = xf + ex
    nyf = yf + ey
    nxt = xt - ex
    nyt = yt - ey
    df = get_signed_delta_rad(thf + link[k, 2], tht)
    nthf = clip_rad_180(thf + df * c)
    ntht = clip_rad_180(tht - df * c)
    pose[f, 0] = nxf
    pose[f, 1] = nyf
    pose[t, 0] = nxt
    pose[t, 1] = nyt
    pose[f, 2] = nthf
    pose[t, 2] = ntht
    return nxf != xf or nyf != yf or nxt != xt or nyt != yt or nthf != thf or ntht != tht


@njit_cached(nogil=True, inline="always")
def _settled(pose: np.ndarray, f: int, t: int) -> bool:  # pragma: no cover - compiled
    """True if no coordinate of the two ends is zero (a product that underflows to zero
    only says False, the safe answer): for non-zero floats an equal value is an equal
    bit pattern, so an update that changed no value changed no bit."""
    return pose[f, 0] * pose[f, 1] * pose[f, 2] * pose[t, 0] * pose[t, 1] * pose[t, 2] != 0.0


@njit_cached(nogil=True, inline="always")
def _idle_pass(
    pose: np.ndarray, src: np.ndarray, dst: np.ndarray, link: np.ndarray, c: float
) -> int:  # pragma: no cover - compiled
    """One pass over the links in the given order; how many updates changed nothing."""
    idle = 0
    for k in range(src.shape[0]):
        if not relax_link(pose, src[k], dst[k], link, k, c):
            idle += 1
    return idle


@njit_cached(nogil=True)
def sweep(
    pose: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    link: np.ndarray,
    passes: int,
    c: float,
) -> int:  # pragma: no cover - compiled
    """``passes`` in-place passes over the links in the given order; returns passes run.

    Stops after a pass that changed no value (every later pass would repeat it). After a
    pass in which at least one update in :data:`IDLE_SHARE` changed nothing, the rest go
    on in :func:`sweep_skipping`, which skips updates that cannot change anything; maps
    that move everywhere (most long ones) are swept without its bookkeeping.

    Shape:
        pose: (N, 3); src, dst: (E,); link: (E, 3) ``[d, heading, facing]``.
    """
    e = src.shape[0]
    for ran in range(1, passes + 1):
        idle = _idle_pass(pose, src, dst, link, c)
        if idle == e:
            return ran
        if IDLE_SHARE * idle >= e and ran < passes:
            return ran + sweep_skipping(pose, src, dst, link, passes - ran, c)
    return passes


@njit_cached(nogil=True)
def sweep_skipping(
    pose: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    link: np.ndarray,
    passes: int,
    c: float,
) -> int:  # pragma: no cover - compiled
    """:func:`sweep`'s passes, skipping exactly the updates that cannot change anything.

    A link whose last update changed no value, and whose two ends have not changed since,
    is skipped: its update is a function of those two poses and the link alone, so it
    would change nothing again. The map is the one every update would make, bit for bit;
    ends with a zero coordinate are never trusted (``0.0 == -0.0`` hides a changed bit).

    Shape:
        pose: (N, 3); src, dst: (E,); link: (E, 3) ``[d, heading, facing]``.
    """
    e = src.shape[0]
    moved = np.zeros(pose.shape[0], np.int64)  # updates that changed each experience
    still = np.full((e, 2), -1, np.int64)  # its ends' counts when a link's update changed nothing
    for ran in range(1, passes + 1):
        changed = False
        for k in range(e):
            f = src[k]
            t = dst[k]
            mf = moved[f]
            mt = moved[t]
            if still[k, 0] == mf and still[k, 1] == mt:
                continue
            xf, yf, thf = pose[f, 0], pose[f, 1], pose[f, 2]
            xt, yt, tht = pose[t, 0], pose[t, 1], pose[t, 2]
            if relax_link(pose, f, t, link, k, c):
                changed = True
                if pose[f, 0] != xf or pose[f, 1] != yf or pose[f, 2] != thf:
                    moved[f] += 1
                if pose[t, 0] != xt or pose[t, 1] != yt or pose[t, 2] != tht:
                    moved[t] += 1
                still[k, 0] = -1
            elif _settled(pose, f, t):
                still[k, 0] = mf
                still[k, 1] = mt
        if not changed:
            return ran
    return passes


@njit_cached(nogil=True)
def sweep_window(
    pose: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    link: np.ndarray,
    start: int,
    count: int,
    c: float,
) -> tuple[int, bool]:  # pragma: no cover - compiled
    """``count`` link updates of :func:`sweep`'s arithmetic, from link ``start`` on,
    round the links in the given order (after the last, the first again).

    Returns:
        (the link to start from next time, True if any value changed).

    Shape:
        pose: (N, 3); src, dst: (E,); link: (E, 3) ``[d, heading, facing]``.
    """
    e = src.shape[0]
    k = start % e
    changed = False
    for _ in range(count):
        if relax_link(pose, src[k], dst[k], link, k, c):
            changed = True
        k += 1
        if k == e:
            k = 0
    return k, changed


@njit_cached(nogil=True)
def insert_link(
    order: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    link: np.ndarray,
    n: int,
    k: int,
    s: int,
    t: int,
    values: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """Insert link ``k`` (``s -> t``, ``values[:3]`` = ``(d, heading, facing)``) into the
    first ``n`` rows of buffers sorted by source (creation order within a source): after
    every row whose source is ``<= s``, the rows behind it moved down one.

    Shape:
        order, src, dst: (C,) with C > n; link: (C, 3); values: (>=3,).
    """
    lo = 0
    hi = n
    while lo < hi:  # the first row whose source is > s
        mid = (lo + hi) // 2
        if src[mid] <= s:
            lo = mid + 1
        else:
            hi = mid
    for i in range(n, lo, -1):
        order[i] = order[i - 1]
        src[i] = src[i - 1]
        dst[i] = dst[i - 1]
        link[i, 0] = link[i - 1, 0]
        link[i, 1] = link[i - 1, 1]
        link[i, 2] = link[i - 1, 2]
    order[lo] = k
    src[lo] = s
    dst[lo] = t
    link[lo, 0] = values[0]
    link[lo, 1] = values[1]
    link[lo, 2] = values[2]
