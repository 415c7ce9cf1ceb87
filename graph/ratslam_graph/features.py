"""The experience-map paper's equations as array functions.

Milford, Wyeth & Prasser, "RatSLAM on the Edge: Revealing a Coherent Representation from
an Overloaded Rat Brain" (IROS 2006), ``shared/papers/experience-map.txt``:

* experience activity from pose-cell and view distances, zone constants and the peak
  experience (Eqs. 1-4): :func:`experience_activity`, :func:`peak_experience`;
* averaging of repeated transitions (Eq. 6): :func:`average_transition`;
* rotation of a link's (dx, dy) when map correction rotates its source (Eq. 8):
  :func:`rotate_link_components`;
* link confidence (Eq. 9): :func:`link_confidence`;
* the temporal map (Eqs. 10-11) and routes: :func:`temporal_map`, :class:`Route`.

Transitions are written ``[dx, dy, dth]`` everywhere in this project (the pose of the
target in the source's frame, as in :class:`ratslam_graph.posegraph.PoseGraph`); the paper
writes the same vector as ``(dth, dx, dy)``. Angles are wrapped to ``(-pi, pi]`` as
OpenRatSLAM's ``clip_rad_180`` does (``geometry.wrap_angle(..., include_pi=True)``).
Everything here is numpy only (no torch).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ratslam_graph.errors import InputError
from ratslam_graph.geometry import ring_distance, signed_delta, wrap_angle

__all__ = [
    "Route",
    "average_transition",
    "experience_activity",
    "link_confidence",
    "peak_experience",
    "rotate_link_components",
    "temporal_map",
]


def experience_activity(
    pc_experiences: np.ndarray,
    vt_experiences: np.ndarray,
    pc_current: np.ndarray,
    vt_current: int,
    *,
    zone_xy: float,
    zone_th: float,
    dims: tuple[float, ...] | None = None,
) -> np.ndarray:
    """Activity of every experience (Eqs. 1-4 of the experience-map paper).

    ``r = hypot(x'_pc - x'_i, y'_pc - y'_i) / r_a`` (Eq. 1), ``t = |th'_pc - th'_i| / th_a``
    (Eq. 2); ``E = 0`` if ``r > 1`` or ``t > 1``, else ``2 - r - t`` (Eq. 3); and the view
    switches an experience off unless its template is the current one (Eq. 4).

    Args:
        pc_experiences: pose-cell coordinates ``(x', y', th')`` of every experience (cells).
        vt_experiences: the template (visual scene) id of every experience.
        pc_current: pose-cell coordinates of the dominant activity packet (cells).
        vt_current: the current template id.
        zone_xy: ``r_a``, the zone constant in the ``(x', y')`` plane (cells).
        zone_th: ``th_a``, the zone constant along ``th'`` (cells).
        dims: ``(X, Y, TH)`` (or ``(XY, TH)``, a square network) to measure differences
            the short way round the wrapping pose-cell network; None measures them
            plainly, as Eqs. 1-2 print.

    Shape:
        pc_experiences: (N, 3); vt_experiences: (N,); pc_current: (3,). Returns (N,),
        values in ``[0, 2]``.
    """
    pc = np.asarray(pc_experiences, dtype=np.float64).reshape(-1, 3)
    vt = np.asarray(vt_experiences).reshape(-1)
    cur = np.asarray(pc_current, dtype=np.float64).reshape(3)
    if len(vt) != len(pc):
        raise InputError(f"{len(pc)} experience pose-cell coordinates but {len(vt)} template ids")
    if zone_xy <= 0 or zone_th <= 0:
        raise InputError(f"zone constants must be > 0, got r_a={zone_xy}, th_a={zone_th}")
    if dims is None:
        dx = dy = dth = None
    elif len(dims) == 2:
        dx, dth = dims
        dy = dx
    else:
        dx, dy, dth = dims
    r = np.hypot(ring_distance(cur[0], pc[:, 0], dx), ring_distance(cur[1], pc[:, 1], dy)) / zone_xy
    t = ring_distance(cur[2], pc[:, 2], dth) / zone_th
    e = np.where((r > 1.0) | (t > 1.0), 0.0, 2.0 - r - t)  # Eq. 3
    return np.where(vt == vt_current, e, 0.0)  # Eq. 4


def peak_experience(activity: np.ndarray) -> tuple[int, float]:
    """The most active experience (the paper's "peak experience").

    Shape:
        activity: (N,).

    Returns:
        ``(id, activity)``; ``(-1, 0.0)`` when no experience is active. The paper learns a
        new experience when the peak's activity drops below a threshold.
    """
    a = np.asarray(activity, dtype=np.float64).reshape(-1)
    if a.size == 0:
        return -1, 0.0
    i = int(np.argmax(a))
    return (i, float(a[i])) if a[i] > 0.0 else (-1, 0.0)


def average_transition(old: np.ndarray, current: np.ndarray) -> np.ndarray:
    """Average a repeated transition into the stored one (Eq. 6 of the experience-map paper).

    ``dp_new = A dp_old + B dp_curr``: the heading change is the mean of the two
    (``A`` and ``B`` carry 1/2 on it), and the stored ``(dx, dy)`` is rotated by
    ``dth = (atan(curr) - atan(old)) / 2`` and scaled by ``d_s = (d_curr + d_old) / (2 d_old)``,
    i.e. the new displacement has the mean length and the mid bearing of the two.

    Deviations (documented): the bearings use ``atan2`` and their difference is wrapped to
    ``(-pi, pi]`` (Eq. 6's ``tan^-1(dy/dx)`` loses the quadrant), and the mean heading
    change is taken the short way round (``old + wrap(curr - old) / 2``), which equals the
    printed ``(old + curr) / 2`` whenever no wrap-around is involved. When the stored
    displacement has zero length (``d_s`` undefined) the result points along the current
    one with half its length, the limit of the mean length.

    Shape:
        old, current: (..., 3) ``[dx, dy, dth]``, broadcastable. Returns (..., 3).
    """
    old = np.asarray(old, dtype=np.float64)
    cur = np.asarray(current, dtype=np.float64)
    old, cur = np.broadcast_arrays(old, cur)
    d_old = np.hypot(old[..., 0], old[..., 1])
    d_cur = np.hypot(cur[..., 0], cur[..., 1])
    b_old = np.arctan2(old[..., 1], old[..., 0])
    b_cur = np.arctan2(cur[..., 1], cur[..., 0])
    half = 0.5 * signed_delta(b_old, b_cur, include_pi=True)
    zero = d_old == 0.0
    d_s = np.where(zero, 0.0, (d_cur + d_old) / (2.0 * np.where(zero, 1.0, d_old)))
    c, s = np.cos(half), np.sin(half)
    out = np.empty(old.shape, dtype=np.float64)
    out[..., 0] = np.where(zero, 0.5 * cur[..., 0], d_s * (c * old[..., 0] - s * old[..., 1]))
    out[..., 1] = np.where(zero, 0.5 * cur[..., 1], d_s * (s * old[..., 0] + c * old[..., 1]))
    out[..., 2] = wrap_angle(
        old[..., 2] + 0.5 * signed_delta(old[..., 2], cur[..., 2], include_pi=True), include_pi=True
    )
    return out


def rotate_link_components(components: np.ndarray, dtheta: np.ndarray | float) -> np.ndarray:
    """Rotate links' ``(dx, dy)`` by their source's change of orientation (Eq. 8).

    In the paper the transition ``(dx, dy)`` is stored in map coordinates, so when map
    correction turns experience ``i`` by ``dth_i`` its outgoing links must turn with it.
    :class:`ratslam_graph.experience_map.ExperienceMap` stores links relative to the source's
    orientation (as OpenRatSLAM does), which makes Eq. 8 hold by construction; its
    ``link_components("global")`` gives the paper's map-frame components.

    Shape:
        components: (..., 3) ``[dx, dy, dth]``; dtheta: broadcastable to (...,).
        Returns (..., 3); ``dth`` is unchanged.
    """
    comp = np.asarray(components, dtype=np.float64)
    a = np.asarray(dtheta, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    out = np.array(comp, dtype=np.float64, copy=True)
    out[..., 0] = c * comp[..., 0] - s * comp[..., 1]
    out[..., 1] = s * comp[..., 0] + c * comp[..., 1]
    return out


def link_confidence(successes: np.ndarray, trials: np.ndarray) -> np.ndarray:
    """Link confidence ``c_ij = n_ij / n_i,beta_ij`` (Eq. 9 of the experience-map paper).

    Args:
        successes: ``n_ij``, how often the transition ``i -> j`` occurred.
        trials: ``n_i,beta_ij``, how often the robot left ``i`` with the link's behaviour
            (to any experience) since the link was learnt; a transition to another
            experience is a "transition failure" and lowers the confidence.

    Shape:
        successes, trials: (E,). Returns (E,) in ``[0, 1]`` (1 where ``trials`` is 0).
    """
    n = np.asarray(successes, dtype=np.float64)
    m = np.asarray(trials, dtype=np.float64)
    return np.divide(n, m, out=np.ones(np.broadcast(n, m).shape), where=m > 0)


def temporal_map(
    num_nodes: int,
    edges: np.ndarray,
    times: np.ndarray,
    start: int,
    *,
    max_iterations: int | None = None,
) -> np.ndarray:
    """Time stamps of the temporal map by the paper's iteration (Eqs. 10-11).

    The start (peak) experience gets 0 and every other one "a very large value"
    (``inf``); then, synchronously for every link ``i - j`` (in both directions, links
    are traversable either way), ``tau_j = t_i + t_ij`` (Eq. 10) and
    ``t_j <- min(tau, t_j)`` (Eq. 11), until nothing changes. Each iteration is one
    vectorised pass over all links (``np.minimum.at``); the fixed point equals
    Dijkstra's distances.

    Args:
        num_nodes: N.
        edges: link endpoints ``(from, to)``.
        times: the temporal link information ``t_ij`` (seconds, >= 0).
        start: the seeded experience.
        max_iterations: stop after this many passes (default N, always enough).

    Shape:
        edges: (E, 2); times: (E,). Returns (N,) seconds, ``inf`` where unreachable.
    """
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    w = np.asarray(times, dtype=np.float64).reshape(-1)
    if len(w) != len(edges):
        raise InputError(f"{len(edges)} links but {len(w)} link times")
    if not 0 <= start < num_nodes:
        raise InputError(f"start experience {start} is not in [0, {num_nodes})")
    if np.any(w < 0):
        raise InputError("link times must be >= 0 for the temporal map")
    src = np.concatenate([edges[:, 0], edges[:, 1]])
    dst = np.concatenate([edges[:, 1], edges[:, 0]])
    ww = np.concatenate([w, w])
    t = np.full(num_nodes, np.inf)
    t[start] = 0.0
    for _ in range(num_nodes if max_iterations is None else max_iterations):
        proposed = t[src] + ww  # Eq. 10
        new = t.copy()
        np.minimum.at(new, dst, proposed)  # Eq. 11
        if np.array_equal(new, t):
            break
        t = new
    return t


@dataclass(frozen=True)
class Route:
    """A route to a goal: experiences in travel order with their estimated times.

    Attributes:
        ids: experience ids from the start (current / peak experience) to the goal.
        times: estimated time (s) from the start to reach each of them (``times[0] == 0``).
    """

    ids: list[int] = field(default_factory=list)
    times: list[float] = field(default_factory=list)

    @property
    def total_time(self) -> float:
        """Estimated time to the goal (s)."""
        return self.times[-1] if self.times else float("inf")

    def __len__(self) -> int:
        return len(self.ids)
