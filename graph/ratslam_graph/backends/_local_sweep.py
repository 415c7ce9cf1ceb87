"""The compiled kernels of ``alpha_local`` (numba; imported lazily by the backend).

Links are ``(d, heading, facing)`` relative to the source's orientation, as the
experience map stores them. Each node keeps a linked list of the links that touch it
(``head[node]`` -> ``nxt[slot]``, ``inc[slot]`` the link), appended as links arrive, so a
sweep finds the links of its dirty nodes without scanning the map. Compiled functions
are cached on disk by numba (``cache=True``); the first use in a fresh environment
compiles them (a second or two).
"""

from __future__ import annotations

import math

import numpy as np

from ratslam_graph._jit import njit_cached

PI = math.pi
TWO_PI = 2.0 * math.pi


@njit_cached(nogil=True)
def add_links(
    head: np.ndarray,
    nxt: np.ndarray,
    inc: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    first: int,
    last: int,
) -> None:  # pragma: no cover - compiled
    """Add links ``first .. last - 1`` to both ends' lists (slots ``2k`` and ``2k + 1``).

    Shape:
        head: (N,) int64, -1 = empty; nxt, inc: (2E,) int64; src, dst: (E,) int64.
    """
    for k in range(first, last):
        for j, node in ((0, src[k]), (1, dst[k])):
            slot = 2 * k + j
            inc[slot] = k
            nxt[slot] = head[node]
            head[node] = slot


@njit_cached(nogil=True)
def local_sweeps(
    pose: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    link: np.ndarray,
    head: np.ndarray,
    nxt: np.ndarray,
    inc: np.ndarray,
    dirty_nodes: np.ndarray,
    n_dirty: int,
    seen: np.ndarray,
    stamp: int,
    moved: np.ndarray,
    touched: np.ndarray,
    active: np.ndarray,
    passes: int,
    c: float,
    wake: float,
    max_links: int = 0,
) -> tuple[int, int, bool, np.ndarray]:  # pragma: no cover - compiled
    """Sweeps of the alpha rule over the links of the dirty nodes, poses in place.

    A sweep gathers the links touching a dirty node, applies the rule to them in
    creation order, link after link (Gauss-Seidel), and makes dirty for the next sweep
    every node that moved by more than ``wake`` (|dx| + |dy| + |dth| summed over the
    sweep). Angles stay in ``(-pi, pi]`` (the experience map's convention). The work is
    proportional to the links of the dirty nodes, never to the map.

    Shape:
        pose: (N, 3) ``[x, y, th]``; src, dst: (E,); link: (E, >= 3) ``[d, heading,
        facing, ...]``; head: (N,); nxt, inc: (2E,); dirty_nodes: (>= n_dirty,) node ids
        (may repeat). Scratch, kept by the caller between calls: seen (>= E,) int64
        stamps (no value >= ``stamp``), moved (>= N,) zeros, touched (>= 2E + 1,),
        active (>= E,).

    ``max_links`` > 0: no new sweep starts once this many link updates were made.

    Returns:
        (sweeps run, link updates made, True if it stopped because nothing was dirty,
        the nodes still dirty when it stopped: the wave's front).
    """
    dirty = dirty_nodes[:n_dirty].copy()
    links = 0
    for sweep in range(passes):
        if max_links > 0 and links >= max_links:
            return sweep, links, False, dirty
        m = 0
        for i in range(dirty.shape[0]):
            slot = head[dirty[i]]
            while slot >= 0:
                k = inc[slot]
                if seen[k] != stamp + sweep:
                    seen[k] = stamp + sweep
                    active[m] = k
                    m += 1
                slot = nxt[slot]
        if m == 0:
            return sweep, links, True, dirty
        order = np.sort(active[:m])
        links += m
        nt = 0
        for idx in range(m):
            k = order[idx]
            f = src[k]
            t = dst[k]
            thf = pose[f, 2]
            d = link[k, 0]
            ex = (pose[t, 0] - pose[f, 0] - d * math.cos(thf + link[k, 1])) * c
            ey = (pose[t, 1] - pose[f, 1] - d * math.sin(thf + link[k, 1])) * c
            raw = pose[t, 2] - thf - link[k, 2]
            df = (raw - TWO_PI * math.floor((raw + PI) / TWO_PI)) * c
            pose[f, 0] += ex
            pose[f, 1] += ey
            pose[t, 0] -= ex
            pose[t, 1] -= ey
            a = thf + df
            pose[f, 2] = a - TWO_PI * math.ceil((a - PI) / TWO_PI)
            b = pose[t, 2] - df
            pose[t, 2] = b - TWO_PI * math.ceil((b - PI) / TWO_PI)
            step = abs(ex) + abs(ey) + abs(df)
            for node in (f, t):
                if moved[node] == 0.0 and step > 0.0:
                    touched[nt] = node
                    nt += 1
                moved[node] += step
        nd = 0
        for i in range(nt):  # keep the nodes that moved enough, reset every counter
            node = touched[i]
            enough = moved[node] > wake
            moved[node] = 0.0
            if enough:
                touched[nd] = node
                nd += 1
        dirty = touched[:nd].copy()
    return passes, links, dirty.shape[0] == 0, dirty
