"""The alpha rule where the map changed: relaxation whose cost follows the change.

``alpha`` sweeps every link of the map ``exp_loops`` times (or once, to find that
nothing moves): its cost per frame grows with the map, so a long run slows down frame
by frame. ``alpha_local`` applies the same rule (Eq. 8 of the multisession paper, the
same Gauss-Seidel colour order as ``alpha``) only to the links that can have an error:

1. The first sweep of a call visits the links that touch a node that is new or moved
   since the previous call, or a link that is new.
2. Each later sweep visits the links that touch a node the previous sweep moved by more
   than ``tol`` (metres for x and y, radians for th): the correction spreads out from
   the change like a wave and stops where it has died down.
3. At most ``passes`` sweeps (``exp_loops``), as ``alpha``.

A new experience whose link agrees with the odometry costs one sweep of two links; a
loop closure relaxes the loop it closes, for as many frames as the wave needs. Nodes the
wave never reaches stay where they are, where ``alpha`` would nudge them by less than
``tol`` per sweep: the two maps differ by that residual. Finding the links of the
moved nodes is one vectorised mask over the links per sweep (no per-link Python loop).
"""

from __future__ import annotations

import math

import numpy as np

from torchratslam.graph.backends.alpha import EdgeColouring, _check
from torchratslam.graph.errors import ConfigError
from torchratslam.graph.posegraph import TWO_PI, PoseGraph

__all__ = ["AlphaLocalBackend"]


class AlphaLocalBackend:
    """The alpha rule applied only where the map changed (see the module doc).

    Args:
        tol: a node that a sweep moves by more than this (m, rad) wakes its links for
            the next sweep; the experience map's own ``tol`` is used when larger.
    """

    name = "alpha_local"
    incremental = True
    accepts_tol = True

    def __init__(self, tol: float = 1e-6) -> None:
        if not (isinstance(tol, (int, float)) and tol > 0 and math.isfinite(tol)):
            raise ConfigError(f"alpha_local tol must be a positive number, got {tol!r}")
        self.tol = float(tol)
        self._colouring = EdgeColouring()
        self._last: np.ndarray | None = None
        self.last_passes = 0
        """Sweeps the last :meth:`relax` ran."""
        self.last_converged = False
        """True if the last :meth:`relax` stopped because the wave died down."""
        self.last_links = 0
        """Link updates the last :meth:`relax` made (summed over its sweeps)."""

    def reset(self) -> None:
        """Forget the colouring and the poses of the previous call."""
        self.__init__(self.tol)

    def _dirty(self, pg: PoseGraph, p: np.ndarray, old_edges: int, kept: bool) -> np.ndarray:
        """Nodes new or moved since the previous call, and the ends of new links."""
        n = len(p)
        last = self._last
        if not kept or last is None or len(last) > n:
            return np.ones(n, bool)
        dirty = np.zeros(n, bool)
        m = len(last)
        dirty[m:] = True
        dirty[:m] = np.any(p[:m] != last, axis=1)
        dirty[pg.edges[old_edges:].ravel()] = True
        return dirty

    def relax(
        self, pg: PoseGraph, *, passes: int, correction: float = 0.5, tol: float = 0.0
    ) -> np.ndarray:
        """Relax the links reached by the change since the previous call.

        Args:
            pg: the graph (its edge list should grow by appending, as RatSLAM's does;
                any other change relaxes every link, like ``alpha``).
            passes: at most this many sweeps.
            correction: ``exp_correction`` (the rule's ``c``).
            tol: the caller's convergence tolerance; the larger of it and the
                backend's ``tol`` decides which moved nodes wake their links.

        Shape:
            returns ``(N, 3)`` float64 poses, angles in ``[-pi, pi)``.
        """
        _check(passes, correction)
        p = pg.poses.copy()
        self.last_passes, self.last_converged, self.last_links = 0, True, 0
        if passes == 0 or pg.num_edges == 0:
            self._last = p.copy()
            return p
        old_edges = len(self._colouring.edges)
        kept = self._colouring.update(pg.edges)
        dirty = self._dirty(pg, p, old_edges, kept)
        wake = max(float(tol), self.tol)
        src, dst = pg.edges[:, 0], pg.edges[:, 1]
        colour = self._colouring.colour
        meas = pg.measurements
        z = p[:, 0] + 1j * p[:, 1]
        th = p[:, 2].copy()
        c = float(correction)
        self.last_converged = False
        for _ in range(passes):
            active = np.flatnonzero(dirty[src] | dirty[dst])
            if active.size == 0:
                self.last_converged = True
                break
            self.last_passes += 1
            self.last_links += int(active.size)
            # the global colour order restricted to the active links: each class is a
            # matching, so applying it at once is applying its links one by one
            active = active[np.lexsort((active, colour[active]))]
            bounds = np.flatnonzero(np.diff(colour[active])) + 1
            touched = np.unique(pg.edges[active].ravel())
            z0, th0 = z[touched], th[touched]
            for links in np.split(active, bounds):
                f, t = src[links], dst[links]
                m = meas[links]
                err = (z[t] - z[f] - np.exp(1j * th[f]) * (m[:, 0] + 1j * m[:, 1])) * c
                z[f] += err
                z[t] -= err
                raw = th[t] - th[f] - m[:, 2]
                df = (raw - TWO_PI * np.rint(raw / TWO_PI)) * c
                th[f] += df
                th[t] -= df
            dth = th[touched] - th0
            dth -= TWO_PI * np.rint(dth / TWO_PI)
            moved = np.maximum(np.abs(z[touched] - z0), np.abs(dth)) > wake
            dirty = np.zeros(len(p), bool)
            dirty[touched[moved]] = True
        else:
            self.last_converged = not dirty.any()
        out = np.stack([z.real, z.imag, np.remainder(th + math.pi, TWO_PI) - math.pi], axis=1)
        self._last = out.copy()
        return out
