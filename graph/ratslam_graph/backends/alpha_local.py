"""The alpha rule where the map changed: relaxation whose cost follows the change.

``alpha`` sweeps every link of the map ``exp_loops`` times (or once, to find that
nothing moves): its cost per frame grows with the map, so a long run slows down frame
by frame. ``alpha_local`` applies the same rule (Eq. 8 of the multisession paper) only
to the links that can have an error:

1. The first sweep of a call visits the links that touch a node that is new or moved
   since the previous call, or a link that is new.
2. Each later sweep visits the links that touch a node the previous sweep moved by more
   than ``tol`` in total (x, y in metres plus th in radians): the correction spreads out
   from the change like a wave and stops where it has died down.
3. At most ``passes`` sweeps (``exp_loops``), as ``alpha``.

Links are visited in creation order, poses updated link after link (Gauss-Seidel, by a
compiled kernel: ``_local_sweep.py``, numba). A new experience whose link agrees with
the odometry costs one sweep of its two links; a loop closure relaxes the loop it
closes, for as many frames as the wave needs. Nodes the wave never reaches stay where
they are, where ``alpha`` would nudge them by less than ``tol`` per sweep: the two maps
differ by that residual (measured effect in docs/experience-map.md).

``carry=True`` (registered as ``alpha_wave``): the nodes still dirty when a call stops
(after ``passes`` sweeps, or ``budget`` link updates) start the next call's wave, so a
correction keeps spreading over the following frames until it dies down below ``tol``
instead of being dropped.
"""

from __future__ import annotations

import math

import numpy as np

from ratslam_graph.backends.alpha import _check
from ratslam_graph.errors import ConfigError
from ratslam_graph.geometry import wrap_angle
from ratslam_graph.posegraph import PoseGraph

__all__ = ["AlphaLocalBackend"]


def _grown(a: np.ndarray, size: int, fill: float | int) -> np.ndarray:
    """``a`` with room for ``size`` entries (doubling), new entries set to ``fill``."""
    if len(a) >= size:
        return a
    out = np.full(max(size, 2 * len(a), 64), fill, dtype=a.dtype)
    out[: len(a)] = a
    return out


class AlphaLocalBackend:
    """The alpha rule applied only where the map changed (see the module doc).

    Args:
        tol: a node that a sweep moves by more than this (|dx| + |dy| + |dth|, m and
            rad) wakes its links for the next sweep; the caller's ``tol`` is used when
            larger.
        carry: carry the wave's front over to the next call (see the module doc).
    """

    name = "alpha_local"
    incremental = True
    accepts_tol = True

    def __init__(self, tol: float = 1e-6, *, carry: bool = False) -> None:
        if not (isinstance(tol, (int, float)) and tol > 0 and math.isfinite(tol)):
            raise ConfigError(f"alpha_local tol must be a positive number, got {tol!r}")
        self.tol = float(tol)
        self.carry = bool(carry)
        if self.carry:
            self.name = "alpha_wave"
        self._clear()

    def _clear(self) -> None:
        self._nodes = 0
        self._links = 0
        self._head = np.full(0, -1, np.int64)
        self._nxt = np.zeros(0, np.int64)
        self._inc = np.zeros(0, np.int64)
        self._seen = np.full(0, -1, np.int64)
        self._moved = np.zeros(0)
        self._touched = np.zeros(0, np.int64)
        self._active = np.zeros(0, np.int64)
        self._stamp = 0
        self._last: np.ndarray | None = None
        self._edge_prefix = np.zeros((0, 2), np.int64)
        self._front = np.zeros(0, np.int64)  # carry: the wave's front, for the next call

    last_passes = 0
    """Sweeps the last call ran."""
    last_converged = False
    """True if the last call stopped because the wave died down."""
    last_links = 0
    """Link updates the last call made (summed over its sweeps)."""

    def reset(self) -> None:
        """Forget the graph seen so far: the next call relaxes every link once."""
        self._clear()

    def relax_inplace(
        self,
        pose: np.ndarray,
        src: np.ndarray,
        dst: np.ndarray,
        link: np.ndarray,
        *,
        passes: int,
        correction: float = 0.5,
        tol: float = 0.0,
        changed: np.ndarray | None = None,
        budget: int = 0,
    ) -> np.ndarray:
        """Relax the experience map's own arrays in place (no copy of the map).

        The links must extend the ones of the previous call (RatSLAM appends them);
        nodes and links beyond the previous call's, and the ``changed`` nodes (moved by
        someone else since), start the wave. Fewer nodes or links than before: the
        backend starts afresh and relaxes every link once.

        Args:
            pose: poses, updated in place.
            src, dst: the links' ends.
            link: ``[d, heading, facing, ...]`` of each link (relative to the source).
            passes: at most this many sweeps.
            correction: ``exp_correction``.
            tol: the caller's tolerance (the larger of it and the backend's is used).
            changed: nodes moved since the previous call, if any.
            budget: with ``carry``, no new sweep once this many link updates were made
                (0: none); the front goes on at the next call.

        Shape:
            pose: (N, 3) float64, C-contiguous; src, dst: (E,) int64; link: (E, >= 3).

        Returns:
            ``pose``.
        """
        from ratslam_graph.backends._local_sweep import add_links, local_sweeps

        _check(passes, correction)
        n, e = len(pose), len(src)
        old_n, old_e = self._nodes, self._links
        if n < old_n or e < old_e:
            self.reset()
            old_n = old_e = 0
        self._head = _grown(self._head, n, -1)
        self._moved = _grown(self._moved, n, 0.0)
        for name, size, fill in (
            ("_nxt", 2 * e, -1),
            ("_inc", 2 * e, 0),
            ("_seen", e, -1),
            ("_touched", 2 * e + 1, 0),
            ("_active", e, 0),
        ):
            setattr(self, name, _grown(getattr(self, name), size, fill))
        add_links(self._head, self._nxt, self._inc, src, dst, old_e, e)
        parts = [np.arange(old_n, n), src[old_e:], dst[old_e:]]
        if changed is not None:
            parts.append(np.asarray(changed, np.int64))
        if old_e == 0:
            parts.append(np.arange(n))
        if self.carry and len(self._front):
            parts.append(self._front[self._front < n])
        dirty = np.concatenate(parts).astype(np.int64)
        self._nodes, self._links = n, e
        self.last_passes, self.last_links, self.last_converged = 0, 0, True
        if passes == 0 or e == 0:
            return pose
        ran, links, converged, front = local_sweeps(
            pose,
            src,
            dst,
            link,
            self._head,
            self._nxt,
            self._inc,
            dirty,
            len(dirty),
            self._seen,
            self._stamp,
            self._moved,
            self._touched,
            self._active,
            int(passes),
            float(correction),
            max(float(tol), self.tol),
            int(budget) if self.carry else 0,
        )
        self._front = front.copy() if self.carry else self._front[:0]
        self._stamp += int(passes) + 1
        self.last_passes, self.last_links = int(ran), int(links)
        self.last_converged = bool(converged) and not len(self._front)
        return pose

    def relax(
        self, pg: PoseGraph, *, passes: int, correction: float = 0.5, tol: float = 0.0
    ) -> np.ndarray:
        """Relax the links reached by the change since the previous call.

        The generic interface: it compares the graph with the previous call's (new
        nodes and links, moved poses; any other change starts afresh) and copies the
        poses, so it costs O(N) per call; the experience map calls
        :meth:`relax_inplace` on its own arrays instead.

        Args:
            pg: the graph (its edge list should grow by appending, as RatSLAM's does).
            passes: at most this many sweeps.
            correction: ``exp_correction`` (the rule's ``c``).
            tol: the caller's convergence tolerance.

        Shape:
            returns ``(N, 3)`` float64 poses, angles in ``[-pi, pi)``.
        """
        p = np.ascontiguousarray(pg.poses, dtype=np.float64).copy()
        e = pg.num_edges
        old_e = min(self._links, e)
        changed = None
        appended = (
            self._last is not None
            and e >= self._links
            and len(p) >= len(self._last)
            and np.array_equal(pg.edges[:old_e], self._edge_prefix[:old_e])
        )
        if not appended:
            self.reset()
        elif self._last is not None:
            m = len(self._last)
            changed = np.flatnonzero(np.any(p[:m] != self._last, axis=1))
        meas = pg.measurements
        link = np.stack(
            [np.hypot(meas[:, 0], meas[:, 1]), np.arctan2(meas[:, 1], meas[:, 0]), meas[:, 2]], 1
        )
        src = np.ascontiguousarray(pg.edges[:, 0])
        dst = np.ascontiguousarray(pg.edges[:, 1])
        out = self.relax_inplace(
            p, src, dst, link, passes=passes, correction=correction, tol=tol, changed=changed
        )
        out[:, 2] = wrap_angle(out[:, 2])
        self._last = out.copy()
        self._edge_prefix = pg.edges.copy()
        return out
