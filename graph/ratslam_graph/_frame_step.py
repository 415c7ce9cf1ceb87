"""The experience map's frame compiled with numba (imported lazily): odometry, the
pose-cell action (create / link / set) and OpenRatSLAM's relaxation in one call.

The arithmetic is the Python path's, operation for operation, so the map is the same
bit for bit:

* angles wrap as :func:`ratslam_graph.geometry.wrap_angle` does with ``include_pi``:
  ``pi - (pi - a) % 2pi`` with Python's float remainder (numba's ``%`` on floats is
  CPython's), wrapped as many times as the Python path wraps them;
* a link's length is :func:`math.hypot` as CPython computes it (its correctly rounded
  ``vector_norm``, ported below; the C library's ``hypot`` differs in the last bit of
  some values);
* ``cos``, ``sin``, ``atan2`` are the C library's, as Python's ``math`` calls them;
* the relaxation is :func:`ratslam_graph.backends._sweep.sweep` on the links in
  OpenRatSLAM's order, kept current by :func:`ratslam_graph.backends._sweep.insert_link`.

Each experience's out-links are a list threaded through the link rows (``out_ends``:
first and last link leaving each experience, ``out_next``: the next one), so a pair's
link is found by walking an experience's few out-links. Compiled functions are cached
on disk by numba (``cache=True``); the first use in a fresh environment compiles them.
Call them through :mod:`ratslam_graph.frame_step`.
"""

from __future__ import annotations

import math

import numpy as np

from ratslam_graph._jit import njit_cached
from ratslam_graph.backends._sweep import insert_link, sweep
from ratslam_graph.frame_step import (
    FALLBACK,
    FIXED,
    GROW,
    LINK_ADDED,
    NODE_ADDED,
    REFUSED,
    RELAXED,
)

PI = math.pi
TWO_PI = 2.0 * math.pi
_SPLIT = 134217729.0  # 2**27 + 1, Veltkamp's splitter for doubles

CREATE = 1
LINK = 2
SET = 3


@njit_cached(nogil=True, inline="always")
def wrap_pi(a: float) -> float:  # pragma: no cover - compiled
    """``wrap_angle(a, include_pi=True)`` on a float: ``pi - (pi - a) % 2pi``."""
    return PI - (PI - a) % TWO_PI


@njit_cached(nogil=True, inline="always")
def _two_square(x: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """``x * x`` and its exact rounding error (Dekker's product, no fused multiply-add)."""
    z = x * x
    c = _SPLIT * x
    hi = c - (c - x)
    lo = x - hi
    return z, ((hi * hi - z) + 2.0 * (hi * lo)) + lo * lo


@njit_cached(nogil=True)
def py_hypot(x: float, y: float) -> float:  # pragma: no cover - compiled
    """:func:`math.hypot` of two finite floats as CPython computes it (``vector_norm``:
    scaled, squared without error, compensated sum, one correction of the root)."""
    ax = abs(x)
    ay = abs(y)
    mx = max(ax, ay)
    if mx == 0.0 or math.isinf(mx):
        return mx
    if math.isnan(x) or math.isnan(y):
        return math.nan
    _, max_e = math.frexp(mx)
    if max_e < -1023:  # subnormal: CPython rescales by DBL_MIN and recurses
        tiny = 2.2250738585072014e-308
        return tiny * py_hypot(x / tiny, y / tiny)
    scale = math.ldexp(1.0, -max_e)
    csum = 1.0
    frac1 = 0.0
    frac2 = 0.0
    for v in (ax, ay):
        hi, lo = _two_square(v * scale)
        s = csum + hi
        frac2 += (csum - s) + hi
        csum = s
        frac1 += lo
    h = math.sqrt(csum - 1.0 + (frac1 + frac2))
    phi, plo = _two_square(h)
    phi = -phi
    plo = -plo
    s = csum + phi
    frac2 += (csum - s) + phi
    csum = s
    frac1 += plo
    v = csum - 1.0 + (frac1 + frac2)
    h += v / (2.0 * h)
    return h / scale


@njit_cached(nogil=True)
def find_link(out_ends: np.ndarray, out_next: np.ndarray, dst: np.ndarray, a: int, b: int) -> int:
    # pragma: no cover - compiled
    """Row of the link ``a -> b`` (that direction), or -1."""
    k = out_ends[a, 0]
    while k >= 0:
        if dst[k] == b:
            return k
        k = out_next[k]
    return -1


@njit_cached(nogil=True)
def count_transition(
    counts: np.ndarray,
    behaviour: np.ndarray,
    dst: np.ndarray,
    edge_dirty: np.ndarray,
    out_ends: np.ndarray,
    out_next: np.ndarray,
    a: int,
    b: int,
    beh: int,
) -> None:  # pragma: no cover - compiled
    """Eq. 9's counts of a transition ``a -> b`` (no removal: threshold 0)."""
    kp = find_link(out_ends, out_next, dst, a, b)
    if kp < 0:
        kp = find_link(out_ends, out_next, dst, b, a)
    k = out_ends[a, 0]
    while k >= 0:
        if behaviour[k] == beh:
            counts[k, 2] += 1
            if dst[k] == b:
                counts[k, 1] += 1
            edge_dirty[k] = 1
        k = out_next[k]
    if kp >= 0:
        counts[kp, 0] += 1
        edge_dirty[kp] = 1


@njit_cached(nogil=True)
def odometry(fs: np.ndarray, vtrans: float, vrot: float, dt: float) -> None:  # pragma: no cover
    """The odometry since the current experience, in place (``ExperienceMap.on_odometry``):
    the facing turns by ``vrot dt``, then ``vtrans dt`` along it; ``fs`` as
    :func:`frame_step`'s."""
    step = vtrans * dt
    fs[2] = wrap_pi(fs[2] + vrot * dt)
    fs[0] += step * math.cos(fs[2])
    fs[1] += step * math.sin(fs[2])
    fs[3] += dt


@njit_cached(nogil=True)
def odometry_frame(
    fs: np.ndarray, ist: np.ndarray, vtrans: float, vrot: float, dt: float
) -> int:  # pragma: no cover - compiled
    """A frame without action or relaxation: :func:`odometry`; returns the current
    experience (``ist`` as :func:`frame_step`'s)."""
    odometry(fs, vtrans, vrot, dt)
    return ist[0]


@njit_cached(nogil=True)
def frame_step(
    fs: np.ndarray,
    ist: np.ndarray,
    pose: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    link: np.ndarray,
    meas: np.ndarray,
    counts: np.ndarray,
    behaviour: np.ndarray,
    edge_dirty: np.ndarray,
    out_ends: np.ndarray,
    out_next: np.ndarray,
    order: np.ndarray,
    rsrc: np.ndarray,
    rdst: np.ndarray,
    rlink: np.ndarray,
    vtrans: float,
    vrot: float,
    dt: float,
    kind: int,
    dest: int,
    rel: float,
    beh: int,
    n: int,
    e: int,
    flags: int,
    loops: int,
    correction: float,
) -> tuple[int, int]:  # pragma: no cover - compiled
    """One frame of the experience map, in place; the result's bits say what changed,
    and the current experience after it.

    Args:
        fs: ``[accum_x, accum_y, accum_facing, accum_time, relative_rad]``.
        ist: ``[current_id, prev_id]``.
        pose .. out_next: the map's arrays (an action needs room for one more
            experience and link).
        order, rsrc, rdst, rlink: the links in OpenRatSLAM's order (creation rows,
            sources, targets, values), current (``e`` rows in use; an action needs room
            for one more).
        vtrans, vrot, dt: the odometry; flags bit 1: apply it.
        kind, dest, rel, beh: the action, its target, relative angle and behaviour.
        n, e: experiences and links in use.
        flags: bit 1 odometry, 2 relax, 4 the map was at a fixed point before this frame,
            8 ``exp_first_at_origin``, 16 ``exp_link_time="per_link"``.
        loops, correction: ``exp_loops``, ``exp_correction``.

    Returns:
        :mod:`ratslam_graph.frame_step`'s ``REFUSED``, ``GROW`` or ``FALLBACK``, or its bits
        ``NODE_ADDED``, ``LINK_ADDED``, ``RELAXED``, ``FIXED``; and ``ist[0]``.
    """
    if kind == CREATE:
        if dest != -1 and dest != n:
            return REFUSED, ist[0]
    elif kind != 0 and not 0 <= dest < n:
        return REFUSED, ist[0]
    if kind != 0 and (
        n >= min(pose.shape[0], out_ends.shape[0])
        or e >= min(src.shape[0], dst.shape[0], link.shape[0], meas.shape[0], counts.shape[0])
        or e >= min(behaviour.shape[0], edge_dirty.shape[0], out_next.shape[0])
        or e >= min(order.shape[0], rsrc.shape[0], rdst.shape[0], rlink.shape[0])
    ):
        return GROW, ist[0]
    ref_n = e  # the order is current: one row a link
    if flags & 1:
        odometry(fs, vtrans, vrot, dt)
    cur = ist[0]
    out = 0
    x = y = th = 0.0
    src_id = -1  # the link's source, when one is to be made
    new_dst = -1
    lrel = 0.0
    if kind == CREATE:
        if cur < 0:
            x, y = (0.0, 0.0) if flags & 8 else (fs[0], fs[1])
        else:
            x = pose[cur, 0] + fs[0]
            y = pose[cur, 1] + fs[1]
        th = wrap_pi(wrap_pi(fs[2]))
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(th)):
            return FALLBACK, ist[0]
        if cur >= 0:
            src_id = cur
            new_dst = n
    elif kind == LINK and cur >= 0 and cur != dest:
        if find_link(out_ends, out_next, dst, cur, dest) < 0:
            if find_link(out_ends, out_next, dst, dest, cur) < 0:
                src_id = cur
                new_dst = dest
                lrel = rel
    d = h = f = 0.0
    if src_id >= 0:  # the link's values, checked before anything changes
        tsrc = pose[src_id, 2]
        ax, ay = fs[0], fs[1]
        d = py_hypot(ax, ay)
        h = wrap_pi(wrap_pi(math.atan2(ay, ax) - tsrc))
        f = wrap_pi(wrap_pi(wrap_pi(fs[2] + lrel) - tsrc))
        if not (
            math.isfinite(d) and math.isfinite(h) and math.isfinite(f) and math.isfinite(fs[3])
        ):
            return FALLBACK, ist[0]
    target = dest
    if kind == CREATE:
        pose[n, 0] = x
        pose[n, 1] = y
        pose[n, 2] = th
        out |= NODE_ADDED
        target = n
        if cur < 0 and not flags & 8:
            ist[0] = n  # OpenRatSLAM: the accumulators run on
            target = -1
        elif cur >= 0:
            count_transition(counts, behaviour, dst, edge_dirty, out_ends, out_next, cur, n, beh)
        rel = 0.0
    elif kind != 0 and cur >= 0 and cur != dest:
        count_transition(counts, behaviour, dst, edge_dirty, out_ends, out_next, cur, dest, beh)
    if src_id >= 0:
        k = e
        src[k] = src_id
        dst[k] = new_dst
        link[k, 0] = d
        link[k, 1] = h
        link[k, 2] = f
        link[k, 3] = fs[3]
        meas[k, 0] = d * math.cos(h)
        meas[k, 1] = d * math.sin(h)
        meas[k, 2] = f
        counts[k, 0] = 1
        counts[k, 1] = 1
        counts[k, 2] = 1
        behaviour[k] = beh
        edge_dirty[k] = 1
        out_next[k] = -1
        if out_ends[src_id, 0] < 0:
            out_ends[src_id, 0] = k
        else:
            out_next[out_ends[src_id, 1]] = k
        out_ends[src_id, 1] = k
        insert_link(order, rsrc, rdst, rlink, ref_n, k, src_id, new_dst, link[k])
        ref_n += 1
        out |= LINK_ADDED
        if flags & 16:
            fs[3] = 0.0
    if kind != 0 and target >= 0 and target != ist[0]:  # on_set_experience
        ist[1] = ist[0]
        ist[0] = target
        fs[0] = 0.0
        fs[1] = 0.0
        fs[2] = wrap_pi(pose[target, 2] + rel)
        fs[4] = rel
    nn = n + (out & NODE_ADDED)
    ne = e + (out & LINK_ADDED) // LINK_ADDED
    if not flags & 2 or nn < 2 or ne == 0 or loops == 0:
        return out, ist[0]
    if flags & 4 and out == 0:
        return out, ist[0]
    ran = sweep(pose, rsrc[:ref_n], rdst[:ref_n], rlink[:ref_n], loops, correction)
    out |= RELAXED
    if ran < loops:
        out |= FIXED
    return out, ist[0]
