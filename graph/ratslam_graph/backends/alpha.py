"""The RatSLAM relaxation rule ("alpha rule", Eq. 8 of the multisession paper).

For every link ``f -> t`` with measurement ``(dx, dy, dth)`` (``d``, ``heading``,
``facing`` in RatSLAM terms) and correction ``c`` (``exp_correction``):

    lx, ly = (x_f, y_f) + R(th_f) (dx, dy)       # where the link puts t
    ex, ey = (x_t, y_t) - (lx, ly)
    x_f += c ex;  y_f += c ey;  x_t -= c ex;  y_t -= c ey
    df = signed_delta(th_f + dth, th_t)
    th_f = wrap(th_f + c df);  th_t = wrap(th_t - c df)

Three implementations:

- :func:`sweep_openratslam` (``AlphaBackend(schedule="openratslam")``, what the
  experience map uses by default, ``exp_relax_order: openratslam``): OpenRatSLAM's own
  ``ExperienceMap::iterate`` loop, compiled with numba (``_sweep.py``), with the C++'s
  arithmetic (``clip_rad_180``/``clip_rad_360`` loops, ``get_signed_delta_rad``), in
  place. Bit-identical to a Python transcription of the loop (tested); as fast per link
  as the C++.
- :class:`AlphaReferenceBackend` ("alpha_reference"): OpenRatSLAM's order, a plain
  Python loop over nodes in row order and their outgoing links in insertion order,
  updating poses in place (Gauss-Seidel). Slow; the reference for tests.
- :class:`AlphaBackend` ("alpha"): the same rule, vectorised. Updating every link at
  once from the same old poses (Jacobi, scatter-add) DIVERGES for ``c = 0.5``, because
  a node with k links receives k full corrections. Instead the links are coloured
  greedily (in reference order) so that no two links of one colour share a node; the
  colour classes are then applied one after another, each as a handful of numpy array
  operations. Inside a class the updates touch disjoint nodes, so applying them at once
  is exactly applying them one by one: every pass is a true Gauss-Seidel sweep, only in
  a different link order than the reference. With ``c = 0.5`` every link update is a
  full projection (a Kaczmarz step), and the limit of a Kaczmarz sweep on an
  inconsistent graph depends on the order: on w100 the reference order stops at graph
  error 1.077, the colour order at 1.147, least squares at 0.569 (random sequential
  orders land anywhere in 1.04-1.30). ``schedule="reference"`` (dependency levels)
  reproduces the reference order exactly, at about one numpy step per link on chains.
  The colouring is cached and extended incrementally when links are appended (the
  RatSLAM online case); any other change of the edge list recolours from scratch.
  Small graphs (few links per colour) run the same schedule as a plain Python loop.

Early stop: ``relax(..., tol=...)`` (:class:`AlphaBackend` only) stops after the first
pass when that pass moved no coordinate by more than ``tol`` (metres, radians): the
graph is at the sweep's fixed point (to rounding) and the remaining passes would only
shuffle rounding noise. ``last_passes`` and ``last_converged`` say what happened. The
default ``tol=0`` stops only when the first pass changed nothing at all, which leaves
the result bit-identical to running every pass.
"""

from __future__ import annotations

import math

import numpy as np

from ratslam_graph.errors import ConfigError
from ratslam_graph.geometry import TWO_PI, wrap_angle
from ratslam_graph.posegraph import PoseGraph


def _check(passes: int, correction: float) -> None:
    if not isinstance(passes, (int, np.integer)) or passes < 0:
        raise ConfigError(f"passes must be a non-negative integer, got {passes!r}")
    if not 0.0 < correction <= 1.0:
        raise ConfigError(f"correction (exp_correction) must be in (0, 1], got {correction!r}")


def reference_order(edges: np.ndarray) -> np.ndarray:
    """Link order of OpenRatSLAM: by source row, then insertion order.

    Shape:
        edges: (E, 2). Returns (E,) int64 indices into ``edges``.
    """
    return np.argsort(edges[:, 0], kind="stable")


class AlphaReferenceBackend:
    """Reference-order alpha rule: a plain Python loop (slow, for tests and checks)."""

    name = "alpha_reference"
    incremental = False

    def relax(self, pg: PoseGraph, *, passes: int, correction: float = 0.5) -> np.ndarray:
        """Run ``passes`` in-place passes of the alpha rule in OpenRatSLAM's order.

        Returns:
            (N, 3) float64 relaxed poses (``pg`` is not modified).
        """
        _check(passes, correction)
        x, y, th = (pg.poses[:, k].tolist() for k in range(3))
        order = reference_order(pg.edges)
        links = [
            (f, t, math.hypot(mx, my), math.atan2(my, mx), mth)
            for (f, t), (mx, my, mth) in zip(
                pg.edges[order].tolist(), pg.measurements[order].tolist()
            )
        ]
        c = float(correction)
        for _ in range(passes):
            for f, t, d, heading, facing in links:
                lx = x[f] + d * math.cos(th[f] + heading)
                ly = y[f] + d * math.sin(th[f] + heading)
                ex, ey = x[t] - lx, y[t] - ly
                x[f] += ex * c
                y[f] += ey * c
                x[t] -= ex * c
                y[t] -= ey * c
                df = wrap_angle(th[t] - (th[f] + facing))
                th[f] = wrap_angle(th[f] + df * c)
                th[t] = wrap_angle(th[t] - df * c)
        return np.stack([np.array(x), np.array(y), np.array(th)], axis=1)

    def reset(self) -> None:
        """Nothing to forget (stateless)."""


def dependency_levels(edges: np.ndarray) -> np.ndarray:
    """Level schedule of the reference order: an edge's level is one more than the
    highest level of the earlier (reference-order) edges that share a node with it.

    Applying the levels one after another, each level at once, is exactly the
    reference Gauss-Seidel sweep (edges of one level touch disjoint nodes and depend
    only on lower levels). Chains of links make the number of levels close to the
    number of links, so this schedule is exact but only fast on bushy graphs.

    Shape:
        edges: (E, 2). Returns (E,) int64 levels.
    """
    last: dict[int, int] = {}
    level = np.empty(len(edges), np.int64)
    order = reference_order(edges)
    for i, (f, t) in zip(order.tolist(), edges[order].tolist()):
        lv = max(last.get(f, -1), last.get(t, -1)) + 1
        level[i] = lv
        last[f] = lv
        last[t] = lv
    return level


class EdgeColouring:
    """Greedy colouring of edges into matchings, extended incrementally.

    Edges are coloured in reference order (by source row, then insertion) with the
    smallest colour unused at both endpoints, so a node's colours are distinct and a
    colour class is a matching. At most ``2 * max_degree - 1`` colours. Appended edges
    are coloured in their insertion order.
    """

    def __init__(self) -> None:
        self.edges = np.zeros((0, 2), np.int64)
        self.colour = np.zeros(0, np.int64)
        self._used: dict[int, int] = {}  # node -> bitmask of colours at that node

    def _colour_new(self, new: np.ndarray) -> np.ndarray:
        used = self._used
        out = np.empty(len(new), np.int64)
        for i, (f, t) in enumerate(new.tolist()):
            uf, ut = used.get(f, 0), used.get(t, 0)
            mask = uf | ut
            free = ~mask & (mask + 1)  # lowest zero bit
            used[f] = uf | free
            used[t] = ut | free
            out[i] = free.bit_length() - 1
        return out

    def update(self, edges: np.ndarray) -> bool:
        """Colour ``edges``; reuse the old colouring if they extend the old list.

        Returns:
            True if the cached colouring was kept (possibly extended), False if rebuilt.
        """
        old = len(self.edges)
        if old and len(edges) >= old and np.array_equal(edges[:old], self.edges):
            if len(edges) > old:
                self.colour = np.concatenate([self.colour, self._colour_new(edges[old:])])
                self.edges = edges.copy()
            return True
        self._used = {}
        self.edges = edges.copy()
        order = reference_order(edges)
        colour = np.empty(len(edges), np.int64)
        colour[order] = self._colour_new(edges[order])
        self.colour = colour
        return False

    @property
    def num_colours(self) -> int:
        return int(self.colour.max()) + 1 if len(self.colour) else 0


def sweep_openratslam(
    poses: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    link: np.ndarray,
    passes: int,
    correction: float,
) -> int:
    """OpenRatSLAM's relaxation (``ExperienceMap::iterate``), compiled, in place.

    Visits the links in the order given (pass them in :func:`reference_order` for
    OpenRatSLAM's), each link moving both ends in place before the next is read. A pass
    that changes no value at all ends the sweep (every later pass would repeat it), so
    the result is bit-identical to running every pass.

    Args:
        poses: experience poses ``[x, y, th]``, float64, C-contiguous; updated in place.
        src, dst: link endpoints (int64), in visiting order.
        link: ``[d, heading, facing]`` of each link (float64), in visiting order.
        passes: number of passes (``exp_loops``).
        correction: ``exp_correction``.

    Returns:
        The number of passes run (fewer than ``passes`` after a pass changed nothing).

    Shape:
        poses: (N, 3); src, dst: (E,); link: (E, 3).
    """
    _check(passes, correction)
    if poses.dtype != np.float64 or not poses.flags.c_contiguous or not poses.flags.writeable:
        raise ConfigError("sweep_openratslam needs writeable C-contiguous float64 poses")
    if passes == 0 or len(src) == 0:
        return 0
    from ratslam_graph.backends._sweep import sweep

    return int(
        sweep(
            poses,
            np.ascontiguousarray(src, dtype=np.int64),
            np.ascontiguousarray(dst, dtype=np.int64),
            np.ascontiguousarray(link, dtype=np.float64),
            int(passes),
            float(correction),
        )
    )


SCHEDULES = ("colour", "reference", "openratslam")
SCALAR_EDGES_PER_CLASS = 24
"""Below this many links per class on average, a pass runs as a plain Python loop."""


class AlphaBackend:
    """Vectorised alpha rule: matchings of links applied one after another.

    Args:
        schedule: "colour" (default, fast): greedy edge colouring, about
            ``2 * max_degree`` numpy steps per pass; a Gauss-Seidel sweep in colour
            order, whose fixed point differs slightly from the reference order's (the
            alpha rule with ``c = 0.5`` is a Kaczmarz sweep, and the limit of an
            inconsistent Kaczmarz sweep depends on the order). "reference": the
            dependency-level schedule, which reproduces ``alpha_reference`` exactly (to
            rounding) but needs about one numpy step per link on chain-like graphs.
            "openratslam": OpenRatSLAM's own loop, compiled with numba
            (:func:`sweep_openratslam`): the reference order with the C++'s arithmetic,
            in place; ``tol`` is ignored (it stops only after a pass that changed
            nothing, which is exact). The experience map's ``exp_relax_order`` picks
            between "openratslam" and "colour".
    """

    name = "alpha"
    incremental = True
    accepts_tol = True

    def __init__(self, schedule: str = "colour") -> None:
        if schedule not in SCHEDULES:
            raise ConfigError(
                f"unknown alpha schedule {schedule!r} (valid: {', '.join(SCHEDULES)})"
            )
        self.schedule = schedule
        self._colouring = EdgeColouring()
        self._level_edges: np.ndarray | None = None
        self._group = np.zeros(0, np.int64)
        self._plan_key: tuple[int, int] | None = None
        self._perm = np.zeros(0, np.int64)
        self._splits: list[int] = []
        self.last_passes = 0
        """Passes the last :meth:`relax` ran (fewer than asked after an exact fixed point)."""
        self.last_converged = False
        """True if the first pass of the last :meth:`relax` moved nothing by more than ``tol``."""

    def reset(self) -> None:
        """Forget the cached schedule."""
        self.__init__(self.schedule)  # type: ignore[misc]

    @property
    def num_classes(self) -> int:
        """Number of sequential steps per pass in the current schedule."""
        return len(self._splits)

    def _plan(self, pg: PoseGraph) -> None:
        if self.schedule == "colour":
            kept = self._colouring.update(pg.edges)
            group = self._colouring.colour
        else:
            kept = self._level_edges is not None and np.array_equal(self._level_edges, pg.edges)
            if not kept:
                self._level_edges = pg.edges.copy()
                self._group = dependency_levels(pg.edges)
            group = self._group
        key = (len(pg.edges), int(group.max()) + 1 if len(group) else 0)
        if kept and key == self._plan_key:
            return
        self._perm = np.lexsort((np.arange(len(group)), group))
        self._splits = np.cumsum(np.bincount(group)).tolist() if len(group) else []
        self._plan_key = key

    def relax(
        self, pg: PoseGraph, *, passes: int, correction: float = 0.5, tol: float = 0.0
    ) -> np.ndarray:
        """Run ``passes`` Gauss-Seidel passes of the alpha rule, vectorised per class.

        Args:
            pg: the graph.
            passes: number of passes.
            correction: ``exp_correction`` (the rule's ``c``).
            tol: stop after the first pass if it moved no x, y (m) or th (rad) by more
                than this (the graph is at a fixed point; see the module doc).

        Returns:
            (N, 3) float64 relaxed poses, angles in ``[-pi, pi)`` (``pg`` is not modified).
        """
        _check(passes, correction)
        if not tol >= 0.0:
            raise ConfigError(f"tol must be >= 0, got {tol!r}")
        p = pg.poses.copy()
        self.last_passes, self.last_converged = 0, pg.num_edges == 0
        if passes == 0 or pg.num_edges == 0:
            return p
        if self.schedule == "openratslam":
            order = reference_order(pg.edges)
            m = pg.measurements[order]
            link = np.stack(
                [np.hypot(m[:, 0], m[:, 1]), np.arctan2(m[:, 1], m[:, 0]), m[:, 2]], axis=1
            )
            p = np.ascontiguousarray(p)
            e = pg.edges[order]
            self.last_passes = sweep_openratslam(p, e[:, 0], e[:, 1], link, passes, correction)
            self.last_converged = self.last_passes < passes
            return p
        self._plan(pg)
        e = pg.edges[self._perm]
        m = pg.measurements[self._perm]
        if pg.num_edges < SCALAR_EDGES_PER_CLASS * len(self._splits):
            # few links per class: numpy's per-call overhead dominates, so run the SAME
            # schedule (colour by colour) link by link in plain Python
            out, self.last_passes = _relax_scalar(
                p, e.tolist(), m.tolist(), passes, float(correction), tol
            )
            self.last_converged = self.last_passes < passes
            return out
        mz = m[:, 0] + 1j * m[:, 1]
        mth = m[:, 2] - math.pi  # folds the +pi of the angle wrap into the constant
        classes = []
        start = 0
        for stop in self._splits:
            sl = slice(start, stop)
            classes.append((e[sl, 0].copy(), e[sl, 1].copy(), mz[sl], mth[sl]))
            start = stop
        z = p[:, 0] + 1j * p[:, 1]
        if correction == 0.5:
            out, self.last_passes = _relax_half(z, p[:, 2], classes, passes, tol)
            self.last_converged = self.last_passes < passes
            return out
        th = p[:, 2].copy()  # unwrapped inside the loop; only differences matter
        c = float(correction)
        pi, two_pi = math.pi, TWO_PI
        exp, rint = np.exp, np.rint
        self.last_passes = passes
        z0, th0 = z.copy(), th.copy()
        for done in range(passes):
            for f, t, lz, lth in classes:
                thf = th[f]
                tht = th[t]
                zf = z[f]
                zt = z[t]
                err = (zt - zf - exp(1j * thf) * lz) * c
                z[f] = zf + err
                z[t] = zt - err
                raw = tht - thf - lth - pi
                df = (raw - two_pi * rint(raw * (1.0 / two_pi))) * c
                th[f] = thf + df
                th[t] = tht - df
            if done == 0 and passes > 1 and _moved(z, z0, th - th0) <= tol:
                self.last_passes = 1
                break
        self.last_converged = self.last_passes < passes
        return np.stack([z.real, z.imag, wrap_angle(th)], axis=1)


def _moved(z: np.ndarray, z0: np.ndarray, dth: np.ndarray) -> float:
    """Largest change of x, y or (wrapped) th between two states."""
    dz = z - z0
    dth = wrap_angle(dth)
    return float(max(np.abs(dz.real).max(), np.abs(dz.imag).max(), np.abs(dth).max()))


def _relax_scalar(
    p: np.ndarray, edges: list, meas: list, passes: int, c: float, tol: float = 0.0
) -> tuple[np.ndarray, int]:
    """The alpha rule link by link in the given order (small graphs).

    Returns:
        The poses and the number of passes run (1 when the first pass moved nothing by
        more than ``tol``).
    """
    x, y, th = (p[:, k].tolist() for k in range(3))
    cos, sin, pi = math.cos, math.sin, math.pi
    ran = passes
    for done in range(passes):
        for (f, t), (mx, my, mth) in zip(edges, meas):
            cf, sf = cos(th[f]), sin(th[f])
            ex = (x[t] - x[f] - cf * mx + sf * my) * c
            ey = (y[t] - y[f] - sf * mx - cf * my) * c
            x[f] += ex
            y[f] += ey
            x[t] -= ex
            y[t] -= ey
            # geometry.wrap_angle's [-pi, pi) arithmetic, inlined on this hot path
            df = ((th[t] - th[f] - mth + pi) % TWO_PI - pi) * c
            th[f] = (th[f] + df + pi) % TWO_PI - pi
            th[t] = (th[t] - df + pi) % TWO_PI - pi
        if done == 0 and passes > 1:
            z1 = np.array(x) + 1j * np.array(y)
            if _moved(z1, p[:, 0] + 1j * p[:, 1], np.array(th) - p[:, 2]) <= tol:
                ran = 1
                break
    return np.stack([np.array(x), np.array(y), np.array(th)], axis=1), ran


def _relax_half(
    z: np.ndarray, th: np.ndarray, classes: list, passes: int, tol: float = 0.0
) -> tuple[np.ndarray, int]:
    """Alpha rule for c = 0.5 without transcendental functions.

    Orientations are kept as unit complex numbers r = exp(i th). Half the wrapped angle
    error of a link is the principal square root of q = r_t conj(r_f) exp(-i dth), and
    for a unit q that root is (1 + q) / |1 + q| (the half-angle formula). So a link
    costs a few complex multiplications and one absolute value.

    Returns:
        The poses and the number of passes run (1 when the first pass moved nothing by
        more than ``tol``).
    """
    r = np.exp(1j * th)
    ms = [(f, t, lz, np.exp(-1j * (lth + math.pi))) for f, t, lz, lth in classes]
    ran = passes
    z0, r0 = z.copy(), r.copy()
    for done in range(passes):
        for f, t, lz, um in ms:
            rf = r[f]
            rt = r[t]
            zf = z[f]
            zt = z[t]
            err = (zt - zf - rf * lz) * 0.5
            z[f] = zf + err
            z[t] = zt - err
            h = rt * rf.conjugate()
            h *= um
            h += 1.0
            a = np.abs(h)
            if a.min() < 1e-12:  # error of exactly pi: wrap(pi) = -pi, a -pi/2 half-turn
                h[a < 1e-12] = -1j
                a[a < 1e-12] = 1.0
            h /= a
            r[f] = rf * h
            r[t] = rt * h.conjugate()
        r /= np.abs(r)  # keep |r| = 1 against rounding drift
        if done == 0 and passes > 1 and _moved(z, z0, np.angle(r * r0.conjugate())) <= tol:
            ran = 1
            break
    return np.stack([z.real, z.imag, np.angle(r)], axis=1), ran
