"""Build an office world from a :class:`~torchratslam.sim.office.plan.FloorPlan` literal.

The free space is the union of the plan's passages (each edge widened to a rectangle,
extended by half its width past both nodes) and rooms, rasterised on a grid; the walls
are the grid's free/occupied boundary, merged into straight runs and handed to
:class:`~torchratslam.sim.world.WorldBuilder` for textures. Every step is an array
operation over the grid, not a loop over its cells.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from torchratslam.errors import InputError
from torchratslam.sim.office.plan import OFFICE_FLOOR, FloorPlan
from torchratslam.sim.world import World, WorldBuilder

__all__ = ["Office", "build_office", "wall_runs"]


@dataclass(frozen=True)
class Office:
    """A built office floor.

    Attributes:
        plan: the floor plan it was built from.
        world: the walls, textured, for the renderer and the range sensor.
        names: node names; node ``i`` is ``names[i]``.
        nodes: node positions (m).
        edges: edge endpoints (node indices).
        free: the free-space grid (True = floor), row ``r`` at ``y = origin[1] + (r +
            0.5) * resolution``.
        origin: ``(x, y)`` of the grid's lower-left corner (m).
        resolution: grid cell size (m).

    Shape:
        nodes: (N, 2); edges: (K, 2); free: (rows, cols).
    """

    plan: FloorPlan
    world: World
    names: tuple[str, ...]
    nodes: np.ndarray
    edges: np.ndarray
    free: np.ndarray
    origin: tuple[float, float]
    resolution: float

    def node(self, name: str) -> int:
        """Index of the node called ``name``."""
        try:
            return self.names.index(name)
        except ValueError:
            raise InputError(f"the plan has no node {name!r}") from None

    def neighbours(self, i: int) -> np.ndarray:
        """Indices of the nodes linked to node ``i``, (k,)."""
        e = self.edges
        return np.concatenate([e[e[:, 0] == i, 1], e[e[:, 1] == i, 0]])

    def is_free(self, xy: np.ndarray) -> np.ndarray:
        """Whether each point lies on the floor (inside the walls).

        Shape:
            xy: (..., 2). Returns (...).
        """
        p = np.asarray(xy, np.float64)
        c = np.floor((p[..., 0] - self.origin[0]) / self.resolution).astype(np.int64)
        r = np.floor((p[..., 1] - self.origin[1]) / self.resolution).astype(np.int64)
        h, w = self.free.shape
        ok = (r >= 0) & (r < h) & (c >= 0) & (c < w)
        return ok & self.free[np.clip(r, 0, h - 1), np.clip(c, 0, w - 1)]


def _rasterise(
    plan: FloorPlan, res: float, margin: float
) -> tuple[np.ndarray, tuple[float, float]]:
    rects = []
    for a, b, w in plan.edges:
        (x0, y0), (x1, y1) = plan.nodes[a], plan.nodes[b]
        if x0 != x1 and y0 != y1:
            raise InputError(f"passage {a}-{b} is not axis-aligned")
        h = w / 2
        rects.append((min(x0, x1) - h, min(y0, y1) - h, max(x0, x1) + h, max(y0, y1) + h))
    for n, w, h in plan.rooms:
        x, y = plan.nodes[n]
        rects.append((x - w / 2, y - h / 2, x + w / 2, y + h / 2))
    r = np.array(rects, np.float64)
    lo = np.floor((r[:, :2].min(axis=0) - margin) / res) * res
    hi = np.ceil((r[:, 2:].max(axis=0) + margin) / res) * res
    cols, rows = np.round((hi - lo) / res).astype(int)
    xc = lo[0] + (np.arange(cols) + 0.5) * res
    yc = lo[1] + (np.arange(rows) + 0.5) * res
    inx = (xc[None, :] > r[:, 0:1]) & (xc[None, :] < r[:, 2:3])  # (R, cols)
    iny = (yc[None, :] > r[:, 1:2]) & (yc[None, :] < r[:, 3:4])  # (R, rows)
    free = np.einsum("ki,kj->ij", iny.astype(np.int32), inx.astype(np.int32)) > 0
    return free, (float(lo[0]), float(lo[1]))


def _runs(b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Runs of True along the rows of ``b``: ``(row, first, end)`` (end exclusive)."""
    rows, cols = b.shape
    padded = np.zeros((rows, cols + 2), dtype=np.int8)
    padded[:, 1:-1] = b
    d = np.diff(padded, axis=1)
    sr, sc = np.nonzero(d == 1)
    _, ec = np.nonzero(d == -1)  # the same row order: a run ends after it starts
    return sr, sc, ec


def wall_runs(free: np.ndarray, origin: tuple[float, float], res: float) -> np.ndarray:
    """The boundary between free and occupied cells as merged straight walls.

    Shape:
        free: (rows, cols). Returns (S, 4) ``[x0, y0, x1, y1]`` (m).
    """
    f = np.pad(free, 1)
    ox, oy = origin[0] - res, origin[1] - res
    horiz = f[1:, :] != f[:-1, :]  # boundary between row r and r + 1
    r, c0, c1 = _runs(horiz)
    y = oy + (r + 1) * res
    h = np.stack([ox + c0 * res, y, ox + c1 * res, y], axis=1)
    vert = (f[:, 1:] != f[:, :-1]).T  # boundary between column c and c + 1
    c, r0, r1 = _runs(vert)
    x = ox + (c + 1) * res
    v = np.stack([x, oy + r0 * res, x, oy + r1 * res], axis=1)
    return np.concatenate([h, v])


def build_office(
    plan: FloorPlan = OFFICE_FLOOR, *, seed: int = 0, resolution: float = 0.1
) -> Office:
    """Build the office: free-space grid, textured walls and the movement graph.

    Args:
        plan: the floor plan literal.
        seed: seed of the wall textures.
        resolution: grid cell size (m); plan coordinates should be multiples of it.
    """
    if resolution <= 0:
        raise InputError(f"resolution={resolution} must be > 0")
    names = tuple(plan.nodes)
    for a, b, _ in plan.edges:
        for n in (a, b):
            if n not in plan.nodes:
                raise InputError(f"edge {a}-{b} names an unknown node {n!r}")
    free, origin = _rasterise(plan, resolution, margin=0.5)
    segs = wall_runs(free, origin, resolution)
    wb = WorldBuilder(seed=seed, wall_height=plan.wall_height)
    for s in segs.tolist():
        wb.segment((s[0], s[1]), (s[2], s[3]))
    world = wb.build(name=plan.name)
    idx = {n: i for i, n in enumerate(names)}
    edges = np.array([(idx[a], idx[b]) for a, b, _ in plan.edges], np.int64).reshape(-1, 2)
    return Office(
        plan=plan,
        world=world,
        names=names,
        nodes=np.array([plan.nodes[n] for n in names], np.float64),
        edges=edges,
        free=free,
        origin=origin,
        resolution=float(resolution),
    )
