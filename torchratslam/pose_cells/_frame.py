"""One frame of the pose-cell stage compiled with numba (imported lazily).

:func:`frame_step` is what :meth:`~torchratslam.pose_cells.stage.PoseCells.on_frame` does
with one CPU network in one call: the view template's bookkeeping and injection
(:func:`view_update`, :func:`inject_cell`), the network's step on the packet's crop
(:func:`step_span`, around :func:`~torchratslam.pose_cells._step.step_crop`) and the
action rule (:func:`decide`). The pieces are also what the separate calls
(``on_view_template``, ``on_odometry``) run, so both ways give the same bits: every
operation keeps the order and the dtype of the Python it stands for (``math.exp`` is the
C library's in both; ``np.maximum``'s NaN; Python's ``%`` on integers; ``int()``'s
truncation).

The stage keeps its scalars in two small arrays the kernels read and write in place
(:mod:`~torchratslam.pose_cells._layout`).

The experiences learnt with each template are a chain: ``t_chain[t] = (first, last)``
and ``e_next[e]`` the next one (``-1``: none), in creation order.

The network's engine keeps its ``span`` (int64, 9): the non-zero arcs ``(start,
length)`` per axis (th, y, x), then the box (theta, y, x cells) the last step computed on.

Compiled functions are cached on disk by numba (``cache=True``).
"""

from __future__ import annotations

import math

import numpy as np

from ratslam_graph._jit import njit_cached
from torchratslam.pose_cells._layout import (
    ALL_ZERO,
    BAD_CELL,
    BAD_ENERGY,
    BAD_ID,
    BAD_ODOMETRY,
    BEST,
    CUR_EXP,
    CUR_VT,
    DIED,
    F_ACTIVE,
    F_CELL,
    F_DIMS,
    F_ENERGY,
    F_RESTORE,
    F_THRESHOLD,
    GROW,
    I_RULE,
    N_E,
    N_T,
    ODO_UPD,
    PREV_VT,
    RECENT,
    REL_RAD,
    VT_DELTA,
    VT_UPD,
)
from torchratslam.pose_cells._step import step_crop

__all__ = ["arc_with", "decide", "frame_step", "inject_cell", "step_span", "view_update"]


@njit_cached(nogil=True)
def arc_with(s: int, ln: int, p: int, n: int) -> tuple[int, int]:  # pragma: no cover
    """A short circular arc (on a ring of ``n``) holding the arc ``(s, ln)`` and the cell ``p``
    (:func:`~torchratslam.pose_cells.functional.arc_with`)."""
    if ln == 0:
        return p, 1
    if (p - s) % n < ln:
        return s, ln
    fwd = (p - s) % n + 1  # extend the end up to p
    back = (s + ln - 1 - p) % n + 1  # extend the start down to p
    if fwd <= back:
        return s, fwd
    return p, back


@njit_cached(nogil=True)
def inject_cell(
    act: np.ndarray, span: np.ndarray, th: int, y: int, x: int, energy: float, keep: bool
) -> None:  # pragma: no cover - compiled
    """Add ``energy`` (float64, then rounded to ``act``'s dtype) at cell ``(th, y, x)``;
    with ``keep``, widen the arcs of ``span`` to hold the cell."""
    act[th, y, x] = act[th, y, x] + energy
    if energy != 0 and keep:
        cell = (th, y, x)
        for ax in range(3):
            s, ln = arc_with(span[2 * ax], span[2 * ax + 1], cell[ax], act.shape[ax])
            span[2 * ax] = s
            span[2 * ax + 1] = ln


@njit_cached(nogil=True)
def step_span(
    act: np.ndarray,
    span: np.ndarray,
    trans: float,
    rot: float,
    eh: int,
    w_e: np.ndarray,
    w_i: np.ndarray,
    inhib: float,
    coef: np.ndarray,
    steps: np.ndarray,
    one_cell: bool,
    edge: np.ndarray,
    cells: np.ndarray,
    lookups: np.ndarray,
    c: int,
) -> tuple[int, int, tuple[float, float, float]]:  # pragma: no cover - compiled
    """One step of the network ``act`` in place on the crop around its arcs (``span``):
    the box (the arcs plus the excitation's reach ``eh`` and the move), then
    :func:`~torchratslam.pose_cells._step.step_crop`; the new arcs and the box go to
    ``span``.

    Args:
        coef, steps, edge, cells: :func:`step_crop`'s tables for both directions of
            travel (first axis: forwards, backwards).

    Returns:
        ``(status, peak, centre)``: status 0, :data:`ALL_ZERO` or :data:`DIED`
        (nothing written); the flat index of the most active cell; the centre.

    Shape:
        act: ``(TH, Y, X)``; span: ``(9,)``; coef, steps, edge: ``(2, 2, TH)`` (edge
        ``(2, 0, 0)`` without the edge loss); cells: ``(2, TH, 3, 2)``.
    """
    m_xy = eh + (math.ceil(abs(trans)) + 1 if trans != 0 else 0)
    m_th = eh + (math.ceil(abs(rot)) + 1 if rot != 0 else 0)
    box = np.empty((3, 5), np.int64)
    for ax in range(3):
        n = act.shape[ax]
        m = m_th if ax == 0 else m_xy
        start, ln = span[2 * ax], span[2 * ax + 1]
        if ln == 0:
            return ALL_ZERO, -1, (0.0, 0.0, 0.0)
        if ln + 2 * m < n:
            box[ax, 0], box[ax, 1], box[ax, 2] = (start - m) % n, ln + 2 * m, 0
            box[ax, 3], box[ax, 4] = m, m + ln
        elif start + ln <= n:  # the whole ring, the arc not across its end
            box[ax, 0], box[ax, 1], box[ax, 2], box[ax, 3], box[ax, 4] = 0, n, 1, start, start + ln
        else:
            box[ax, 0], box[ax, 1], box[ax, 2], box[ax, 3], box[ax, 4] = 0, n, 1, 0, n
    d = 1 if trans < 0 else 0
    status, peak, arcs, centre = step_crop(
        act, box, w_e, w_i, inhib, trans, rot, coef[d], steps[d], one_cell, edge[d],
        cells[d], lookups, c, 0,
    )  # fmt: skip
    if status:
        return DIED, -1, centre
    for m in range(6):
        span[m] = arcs[m]
    for ax in range(3):
        span[6 + ax] = box[ax, 1]
    return 0, peak, centre


@njit_cached(nogil=True)
def view_update(
    ist: np.ndarray, fst: np.ndarray, t_pc: np.ndarray, t_decay: np.ndarray, vt: int, rad: float
) -> tuple[int, int, int, int, float]:  # pragma: no cover - compiled
    """A view template's bookkeeping (``on_view_template`` without the injection itself):
    learn a new template at the centre, or raise a re-seen one's decay and work out its
    injection; relax every decay; the current and previous template.

    Returns:
        ``(status, th, y, x, energy)``: status 0, :data:`BAD_ID` (nothing changed),
        :data:`BAD_CELL` or :data:`BAD_ENERGY` (nothing more changed after the decay and
        the angle); the cell (before wrapping) and energy to inject (energy 0: none).
    """
    n = ist[N_T]
    if vt < 0 or vt > n:
        return BAD_ID, 0, 0, 0, 0.0
    fst[REL_RAD] = rad
    active = fst[F_ACTIVE]
    ix, iy, it, energy = 0, 0, 0, 0.0
    if vt == n:
        for m in range(3):
            t_pc[n, m] = fst[BEST + m]
        t_decay[n] = active
        ist[N_T] = n + 1
    elif vt < n - RECENT or (ist[I_RULE] != 0 and n < RECENT):
        # (OpenRatSLAM's unsigned "size - 10" wraps while fewer than 10 exist)
        if vt == ist[CUR_VT]:
            t_decay[vt] += active
        e = fst[F_ENERGY] / 30.0 * (30.0 - math.exp(1.2 * t_decay[vt]))
        if e > 0:
            n_th = fst[F_DIMS + 2]
            delta = rad / (2.0 * math.pi) * n_th
            fst[VT_DELTA] = delta
            pc_x, pc_y = t_pc[vt, 0], t_pc[vt, 1]
            th = t_pc[vt, 2] + delta
            if th < 0:
                th += n_th
            if th >= n_th:
                th -= n_th
            if not (math.isfinite(pc_x) and math.isfinite(pc_y) and math.isfinite(th)):
                return BAD_CELL, 0, 0, 0, 0.0
            if not math.isfinite(e):
                return BAD_ENERGY, 0, 0, 0, e
            ix, iy, it, energy = int(pc_x), int(pc_y), int(th) % int(n_th), e
    restore = fst[F_RESTORE]
    for m in range(ist[N_T]):  # np.subtract, then np.maximum (a NaN stays)
        v = t_decay[m] - restore
        t_decay[m] = active if v < active else v
    ist[PREV_VT] = ist[CUR_VT]
    ist[CUR_VT] = vt
    ist[VT_UPD] = 1
    return 0, it, iy, ix, energy


@njit_cached(nogil=True, inline="always")
def _ring(a: float, b: float, n: float) -> float:  # pragma: no cover - compiled
    """The shorter way round a ring of ``n`` cells from ``b`` to ``a``."""
    d = abs(a - b)
    m = d % n
    r = n - m
    return r if r < m else m


@njit_cached(nogil=True)
def decide(
    ist: np.ndarray,
    fst: np.ndarray,
    e_pc: np.ndarray,
    e_template: np.ndarray,
    e_next: np.ndarray,
    t_chain: np.ndarray,
) -> tuple[int, int, int]:  # pragma: no cover - compiled
    """The action rule once a view and odometry have both arrived: create an experience
    at the centre when the current template has none, or when the nearest of its
    experiences (to the centre with theta corrected by the last injection's angle,
    :func:`ratslam_graph.geometry.pc_distance`'s arithmetic, the first nearest as
    OpenRatSLAM's strict ``<``) is not within ``exp_delta_pc_threshold``; link to that
    one when it is and the packet left the current experience or the template changed.
    A created experience needs a free row in ``e_pc``, ``e_template`` and ``e_next``.

    Returns:
        ``(kind, dest, src)``: :class:`~ratslam_graph.messages.ActionKind`'s value
        (0: none, 1: create, 2: link) and the experience ids (-1 for none).
    """
    if not (ist[ODO_UPD] != 0 and ist[VT_UPD] != 0):
        return 0, -1, -1
    ist[ODO_UPD] = 0
    ist[VT_UPD] = 0
    if ist[N_T] == 0:
        return 0, -1, -1
    cur_vt, cur = ist[CUR_VT], ist[CUR_EXP]
    first = t_chain[cur_vt, 0] if 0 <= cur_vt < t_chain.shape[0] else -1
    if ist[N_E] != 0 and first >= 0:
        n_x, n_y, n_th = fst[F_DIMS], fst[F_DIMS + 1], fst[F_DIMS + 2]
        cx, cy = fst[BEST], fst[BEST + 1]
        cth = fst[BEST + 2] - fst[VT_DELTA]  # get_delta_pc's theta
        if cth < 0:
            cth += n_th
        if cth >= n_th:
            cth -= n_th
        threshold = fst[F_THRESHOLD]
        dx = _ring(e_pc[cur, 0], cx, n_x)
        dy = _ring(e_pc[cur, 1], cy, n_y)
        dt = _ring(e_pc[cur, 2], cth, n_th)
        total = dx * dx
        total = total + dy * dy
        total = total + dt * dt
        if not (math.sqrt(total) > threshold or cur_vt != ist[PREV_VT]):
            return 0, -1, -1
        best, best_d = -1, math.inf
        i = first
        while i >= 0:
            if i != cur:
                dx = _ring(e_pc[i, 0], cx, n_x)
                dy = _ring(e_pc[i, 1], cy, n_y)
                dt = _ring(e_pc[i, 2], cth, n_th)
                total = dx * dx
                total = total + dy * dy
                total = total + dt * dt
                d = math.sqrt(total)
                if math.isnan(d):  # numpy's argmin: the first NaN
                    best, best_d = i, d
                    break
                if best < 0 or d < best_d:
                    best, best_d = i, d
            i = e_next[i]
        if best >= 0 and best_d < threshold:
            ist[CUR_EXP] = best
            return 2, best, cur
    new = ist[N_E]
    for m in range(3):
        e_pc[new, m] = fst[BEST + m]
    e_template[new] = cur_vt
    e_next[new] = -1
    if 0 <= cur_vt < t_chain.shape[0]:
        last = t_chain[cur_vt, 1]
        if last >= 0:
            e_next[last] = new
        else:
            t_chain[cur_vt, 0] = new
        t_chain[cur_vt, 1] = new
    ist[N_E] = new + 1
    ist[CUR_EXP] = new
    return 1, new, cur


@njit_cached(nogil=True)
def frame_step(
    act: np.ndarray,
    span: np.ndarray,
    best_out: np.ndarray,
    ist: np.ndarray,
    fst: np.ndarray,
    t_pc: np.ndarray,
    t_decay: np.ndarray,
    e_pc: np.ndarray,
    e_template: np.ndarray,
    e_next: np.ndarray,
    t_chain: np.ndarray,
    eh: int,
    w_e: np.ndarray,
    w_i: np.ndarray,
    inhib: float,
    coef: np.ndarray,
    steps: np.ndarray,
    one_cell: bool,
    edge: np.ndarray,
    cells: np.ndarray,
    lookups: np.ndarray,
    c: int,
    vt: int,
    rad: float,
    vtrans: float,
    vrot: float,
    dt: float,
) -> tuple[int, int, int, int, float, float, float, float]:  # pragma: no cover - compiled
    """One frame: :func:`view_update`, :func:`inject_cell`, the odometry's
    :func:`step_span` (its centre to ``fst`` and ``best_out``) and :func:`decide`.

    Args:
        span: the engine's arcs, valid for ``act``.
        best_out: the network's centre buffer (written).
        eh, w_e ... c: :func:`step_span`'s.
        vt, rad: the view template and its relative angle.
        vtrans, vrot, dt: the odometry.

    Returns:
        ``(status, kind, dest, src, x, y, th, angle)``: status 0, :data:`GROW` (a
        template or experience buffer is full) or an error; the action; the centre;
        the last injection's angle (``vt_delta_pc_th`` in radians).

    Shape:
        e_pc: ``(M', 3)``, e_template, e_next: ``(M',)``; t_pc: ``(N', 3)``, t_decay:
        ``(N',)``, t_chain: ``(N', 2)``; rows past ``N_E`` / ``N_T`` are room.
    """
    vt, rad = int(vt), float(rad)
    vtrans, vrot, dt = float(vtrans), float(vrot), float(dt)
    status, it, iy, ix, energy = view_update(ist, fst, t_pc, t_decay, vt, rad)
    if status:
        return status, 0, -1, -1, 0.0, 0.0, 0.0, 0.0
    n_th = fst[F_DIMS + 2]
    if energy != 0:
        n_t, n_y, n_x = act.shape
        inject_cell(act, span, it % n_t, iy % n_y, ix % n_x, energy, True)
    if not (math.isfinite(vtrans) and math.isfinite(vrot) and math.isfinite(dt)):
        return BAD_ODOMETRY, 0, -1, -1, 0.0, 0.0, 0.0, 0.0
    trans = vtrans * dt / fst[F_CELL]  # cells along each layer's heading
    rot = vrot * dt / (2.0 * math.pi / n_th)  # theta cells
    status, _, centre = step_span(
        act, span, trans, rot, eh, w_e, w_i, inhib, coef, steps, one_cell, edge, cells,
        lookups, c,
    )  # fmt: skip
    if status:
        return status, 0, -1, -1, 0.0, 0.0, 0.0, 0.0
    x, y, th = centre
    fst[BEST], fst[BEST + 1], fst[BEST + 2] = x, y, th
    best_out[0, 0], best_out[0, 1], best_out[0, 2] = x, y, th
    ist[ODO_UPD] = 1
    kind, dest, src = decide(ist, fst, e_pc, e_template, e_next, t_chain)
    full = ist[N_T] >= t_pc.shape[0] or ist[N_E] >= e_pc.shape[0]
    angle = fst[VT_DELTA] * 2.0 * math.pi / n_th
    return (GROW if full else 0), kind, dest, src, x, y, th, angle
