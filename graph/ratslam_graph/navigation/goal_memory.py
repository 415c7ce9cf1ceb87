"""Goal memory: the temporal map spread over a copy of the pose-cell matrix (the baseline
the experience-map paper compares with, its reference [6]).

This project's reading of it (the paper describes it in one paragraph): goal memory is a
copy of the pose cells' ``(x', y')`` plane. While the robot moves, the cell holding the
packet's centre changes; each change from a cell to one of its eight neighbours (on the
torus) learns a link between the two cells with the time the packet spent in the first
(repeats averaged). A jump of the packet to a cell that is not a neighbour (a loop
closure by a familiar view) learns nothing: the goal memory inherits the pose cells'
discontinuities. A cell the packet visits at two places of the floor holds both places'
links: it inherits their collisions. A goal is a cell; the temporal map spreads from the
robot's cell over the links (Eqs. 10-11 as on the experience map), and the route is the
chain of cells back from the goal.

:func:`collisions` counts the cells of a packet path that stand for places further apart
than a given distance (the paper's Fig. 3 discussion).
"""

from __future__ import annotations

import math

import numpy as np

from ratslam_graph.errors import InputError
from ratslam_graph.navigation.temporal import TemporalMap, temporal_map

__all__ = ["GoalMemory", "collisions"]


class GoalMemory:
    """Temporal links between neighbouring cells of an ``X x Y`` pose-cell plane.

    Args:
        dims: ``(X, Y)``, the pose-cell matrix's cells along x' and y'.

    Example:
        >>> gm = GoalMemory((4, 3))
        >>> for t, x in enumerate([0.2, 1.1, 2.3]):
        ...     gm.observe((x, 0.5), float(t))
        >>> gm.route(gm.cell_of((0.2, 0.5)), gm.cell_of((2.3, 0.5)))
        [0, 1, 2]
    """

    def __init__(self, dims: tuple[int, int]) -> None:
        self.nx, self.ny = int(dims[0]), int(dims[1])
        if self.nx < 1 or self.ny < 1:
            raise InputError(f"goal memory needs positive dims, got {dims}")
        self._index: dict[tuple[int, int], int] = {}
        self._src: list[int] = []
        self._dst: list[int] = []
        self._time: list[float] = []
        self._count: list[int] = []
        self._cell = -1
        self._entered = 0.0
        self.jumps = 0
        """Changes of cell to a cell that is not a neighbour (nothing learnt)."""

    @property
    def num_cells(self) -> int:
        return self.nx * self.ny

    @property
    def num_links(self) -> int:
        return len(self._src)

    def cell_of(self, pc_xy: tuple[float, float] | np.ndarray) -> int:
        """The flat index ``x + X y`` of the cell holding ``(x', y')`` (wrapped)."""
        x = math.floor(float(pc_xy[0])) % self.nx
        y = math.floor(float(pc_xy[1])) % self.ny
        return x + self.nx * y

    def xy(self, cell: int) -> tuple[int, int]:
        """The cell's ``(x', y')`` indices."""
        return int(cell) % self.nx, int(cell) // self.nx

    def step(self, a: int, b: int) -> tuple[int, int]:
        """The shortest ``(dx, dy)`` on the torus from cell ``a`` to cell ``b``."""
        (ax, ay), (bx, by) = self.xy(a), self.xy(b)
        dx = (bx - ax + self.nx // 2) % self.nx - self.nx // 2
        dy = (by - ay + self.ny // 2) % self.ny - self.ny // 2
        return dx, dy

    def neighbours(self, a: int, b: int) -> bool:
        """Whether ``b`` is one of ``a``'s eight neighbours on the torus."""
        dx, dy = self.step(a, b)
        return a != b and abs(dx) <= 1 and abs(dy) <= 1

    def observe(self, pc_xy: tuple[float, float] | np.ndarray, t: float) -> None:
        """The packet's centre ``(x', y')`` at time ``t`` (s): a change to a neighbouring
        cell learns (or averages) the link from the cell left, timed by the stay there."""
        cell = self.cell_of(pc_xy)
        if cell == self._cell:
            return
        prev, self._cell = self._cell, cell
        stay, self._entered = t - self._entered, t
        if prev < 0:
            return
        if not self.neighbours(prev, cell):
            self.jumps += 1
            return
        k = self._index.get((prev, cell))
        if k is None:
            self._index[(prev, cell)] = len(self._src)
            self._src.append(prev)
            self._dst.append(cell)
            self._time.append(stay)
            self._count.append(1)
        else:
            self._count[k] += 1
            self._time[k] += (stay - self._time[k]) / self._count[k]

    def temporal_map(self, start: int) -> TemporalMap:
        """Times from cell ``start`` to every cell over the links (Eqs. 10-11)."""
        return temporal_map(
            self.num_cells,
            np.asarray(self._src, np.int64),
            np.asarray(self._dst, np.int64),
            np.maximum(np.asarray(self._time, np.float64), 1e-6),
            int(start),
            directed=True,
        )

    def route(self, start: int, goal: int) -> list[int] | None:
        """The cells from ``start`` to ``goal`` on the fastest chain of links (None: the
        goal cannot be reached)."""
        tm = self.temporal_map(start)
        if not np.isfinite(tm.times[goal]):
            return None
        out = [int(goal)]
        while out[-1] != start:
            out.append(int(tm.parent[out[-1]]))
        return out[::-1]

    def positions(self, cells: list[int], origin: tuple[float, float]) -> np.ndarray:
        """The cells' centres as one unwrapped path in cells, the first cell's taken as
        ``origin`` and each next one a torus step from the one before.

        Shape:
            returns (len(cells), 2).
        """
        out = np.empty((len(cells), 2))
        if not cells:
            return out
        out[0] = origin
        for i in range(1, len(cells)):
            out[i] = out[i - 1] + self.step(cells[i - 1], cells[i])
        return out


def collisions(pc_xy: np.ndarray, truth_xy: np.ndarray, separation_m: float) -> tuple[int, int]:
    """Cells of a packet path that stand for places more than ``separation_m`` apart
    (the diagonal of the box round the true places of the cell's frames).

    Args:
        pc_xy: the packet's ``(x', y')`` per frame (cells).
        truth_xy: the robot's true ``(x, y)`` per frame (m).
        separation_m: two places of one cell further apart than this make a collision.

    Returns:
        ``(cells with a collision, cells visited)``.

    Shape:
        pc_xy, truth_xy: (F, 2).
    """
    pc = np.floor(np.asarray(pc_xy, np.float64)).astype(np.int64)
    truth = np.asarray(truth_xy, np.float64)
    keys = pc[:, 0] * (1 << 20) + pc[:, 1]
    order = np.argsort(keys, kind="stable")
    ks, tr = keys[order], truth[order]
    cuts = np.flatnonzero(np.diff(ks)) + 1
    groups = np.split(np.arange(len(ks)), cuts)
    hit = 0
    for g in groups:  # one group per visited cell (at most X x Y), not per frame
        p = tr[g]
        hit += int(np.hypot(*(p.max(axis=0) - p.min(axis=0))) > separation_m)
    return hit, len(groups)
