"""The array form of a 2D pose graph that every relaxation backend works on.

A :class:`PoseGraph` holds node poses ``(N, 3)`` ``[x, y, th]``, edges ``(E, 2)`` as row
indices ``(from, to)`` and, per edge, the measured pose of ``to`` in ``from``'s frame
``[dx, dy, dth]`` (a ``Pose2`` "between"). A RatSLAM link ``(d, heading, facing)`` is
``dx = d cos(heading)``, ``dy = d sin(heading)``, ``dth = facing``.

Also here: odometry composition (the initial estimate of a graph read from a file
without vertices, through :func:`ratslam_graph.geometry.chain_poses`) and a
union-find that anchors every connected component of a graph.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ratslam_graph.errors import InputError
from ratslam_graph.geometry import between, chain_poses, wrap_angle


class UnionFind:
    """Incremental union-find over node rows (grows on demand)."""

    def __init__(self) -> None:
        self.parent: list[int] = []

    def grow(self, n: int) -> None:
        """Make sure nodes ``0 .. n-1`` exist (new ones are singletons)."""
        self.parent.extend(range(len(self.parent), n))

    def find(self, i: int) -> int:
        parent = self.parent
        root = i
        while parent[root] != root:
            root = parent[root]
        while parent[i] != root:
            parent[i], i = root, parent[i]
        return root

    def union(self, a: int, b: int) -> bool:
        """Join the sets of ``a`` and ``b`` (the smaller root wins); True if they were apart."""
        ra, rb = self.find(a), self.find(b)
        if ra == rb:
            return False
        if rb < ra:
            ra, rb = rb, ra
        self.parent[rb] = ra
        return True

    def roots(self) -> np.ndarray:
        """Rows that are the root (lowest row) of their connected component."""
        return np.array([i for i in range(len(self.parent)) if self.find(i) == i], dtype=np.int64)


@dataclass
class PoseGraph:
    """A 2D pose graph in array form.

    Attributes:
        poses: (N, 3) float64 ``[x, y, th]`` of every node.
        edges: (E, 2) int64 row indices ``(from, to)`` into ``poses``.
        measurements: (E, 3) float64 ``[dx, dy, dth]``: measured pose of ``to`` in
            ``from``'s frame.
        ids: optional (N,) int64 external ids (file vertex ids, experience ids).
        information: optional (E, 3, 3) float64 information matrices (from files);
            ``None`` means "no noise model given" and backends use their own default.
    """

    poses: np.ndarray
    edges: np.ndarray
    measurements: np.ndarray
    ids: np.ndarray | None = None
    information: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self.poses = np.array(self.poses, dtype=np.float64, copy=True).reshape(-1, 3)
        edges = np.asarray(self.edges)
        if edges.size and not np.issubdtype(edges.dtype, np.integer):
            if not np.all(edges == np.round(edges)):
                raise InputError("PoseGraph.edges must hold integer row indices")
        self.edges = np.array(edges, dtype=np.int64, copy=True).reshape(-1, 2)
        self.measurements = np.array(self.measurements, dtype=np.float64, copy=True).reshape(-1, 3)
        n, e = len(self.poses), len(self.edges)
        if len(self.measurements) != e:
            raise InputError(
                f"PoseGraph has {e} edges but {len(self.measurements)} measurements; "
                "give one [dx, dy, dth] per edge"
            )
        if e and (self.edges.min() < 0 or self.edges.max() >= n):
            raise InputError(
                f"PoseGraph edge endpoints must be row indices in [0, {n}); "
                f"got range [{self.edges.min()}, {self.edges.max()}]"
            )
        if e and np.any(self.edges[:, 0] == self.edges[:, 1]):
            bad = int(np.flatnonzero(self.edges[:, 0] == self.edges[:, 1])[0])
            raise InputError(
                f"PoseGraph edge {bad} links node {self.edges[bad, 0]} to itself; remove it"
            )
        if not (np.all(np.isfinite(self.poses)) and np.all(np.isfinite(self.measurements))):
            raise InputError("PoseGraph poses and measurements must be finite (found NaN or inf)")
        if self.ids is not None:
            self.ids = np.array(self.ids, dtype=np.int64, copy=True).reshape(-1)
            if len(self.ids) != n:
                raise InputError(f"PoseGraph.ids has {len(self.ids)} entries for {n} poses")
        if self.information is not None:
            self.information = np.array(self.information, dtype=np.float64, copy=True)
            if self.information.shape != (e, 3, 3):
                raise InputError(
                    f"PoseGraph.information must have shape ({e}, 3, 3), "
                    f"got {self.information.shape}"
                )

    @property
    def num_poses(self) -> int:
        return len(self.poses)

    @property
    def num_edges(self) -> int:
        return len(self.edges)

    def copy(self) -> PoseGraph:
        return PoseGraph(self.poses, self.edges, self.measurements, self.ids, self.information)

    def with_poses(self, poses: np.ndarray) -> PoseGraph:
        """The same graph with other node poses.

        Shape:
            poses: (N, 3).
        """
        poses = np.asarray(poses, dtype=np.float64)
        if poses.shape != self.poses.shape:
            raise InputError(f"expected poses of shape {self.poses.shape}, got {poses.shape}")
        return PoseGraph(poses, self.edges, self.measurements, self.ids, self.information)

    def subgraph(self, num_poses: int) -> PoseGraph:
        """The first ``num_poses`` nodes and every edge between them (a prefix slice)."""
        if not 0 < num_poses <= self.num_poses:
            raise InputError(f"num_poses must be in [1, {self.num_poses}], got {num_poses}")
        keep = np.all(self.edges < num_poses, axis=1)
        return PoseGraph(
            self.poses[:num_poses],
            self.edges[keep],
            self.measurements[keep],
            None if self.ids is None else self.ids[:num_poses],
            None if self.information is None else self.information[keep],
        )

    @classmethod
    def from_links(
        cls,
        poses: np.ndarray,
        edges: np.ndarray,
        d: np.ndarray,
        heading: np.ndarray,
        facing: np.ndarray,
        ids: np.ndarray | None = None,
    ) -> PoseGraph:
        """Build from RatSLAM links (distance, heading and facing relative to the source).

        Shape:
            poses: (N, 3); edges: (E, 2); d, heading, facing: (E,).
        """
        d = np.asarray(d, dtype=np.float64)
        heading = np.asarray(heading, dtype=np.float64)
        meas = np.stack(
            [d * np.cos(heading), d * np.sin(heading), np.asarray(facing, dtype=np.float64)], -1
        )
        return cls(poses, edges, meas.reshape(-1, 3), ids)

    def links(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The measurements as RatSLAM links ``(d, heading, facing)``, each (E,)."""
        m = self.measurements
        return np.hypot(m[:, 0], m[:, 1]), np.arctan2(m[:, 1], m[:, 0]), m[:, 2].copy()

    def component_roots(self) -> np.ndarray:
        """Lowest row of every connected component (where backends put their priors)."""
        uf = UnionFind()
        uf.grow(self.num_poses)
        for a, b in self.edges.tolist():
            uf.union(a, b)
        return uf.roots()

    def relative_errors(self, poses: np.ndarray | None = None) -> np.ndarray:
        """Per-edge residual ``between(p_from, p_to) - measurement`` (angle wrapped).

        Shape:
            poses: (N, 3) or None (use ``self.poses``). Returns (E, 3).
        """
        p = self.poses if poses is None else np.asarray(poses, dtype=np.float64)
        r = between(p[self.edges[:, 0]], p[self.edges[:, 1]]) - self.measurements
        r[:, 2] = wrap_angle(r[:, 2])
        return r


def compose_odometry(
    num_poses: int,
    edges: np.ndarray,
    measurements: np.ndarray,
    start: Sequence[float] = (0.0, 0.0, 0.0),
) -> np.ndarray:
    """Initial estimate from the odometry chain ``i -> i+1`` (dead reckoning).

    Every node ``i > 0`` needs an edge ``(i-1, i)`` or ``(i, i-1)``; the first such
    edge in file order is used.

    Shape:
        edges: (E, 2); measurements: (E, 3). Returns (num_poses, 3).
    """
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    meas = np.asarray(measurements, dtype=np.float64).reshape(-1, 3)
    step = np.full((num_poses, 3), np.nan)
    have = np.zeros(num_poses, dtype=bool)  # nodes with a step (its values may be NaN)
    fwd = edges[:, 1] == edges[:, 0] + 1
    bwd = edges[:, 0] == edges[:, 1] + 1
    # inverse of a backward measurement gives the forward step
    inv = between(meas[bwd], np.zeros(3))
    for mask, vals in ((bwd, inv), (fwd, meas[fwd])):  # forward wins: written last
        idx = np.maximum(edges[mask, 0], edges[mask, 1])
        rows, first = np.unique(idx, return_index=True)  # first edge in file order
        step[rows] = vals[first]
        have[rows] = True
    if num_poses > 1 and not have[1:].all():
        missing = int(np.flatnonzero(~have[1:])[0]) + 1
        raise InputError(
            f"cannot compose odometry: no edge between nodes {missing - 1} and {missing}; "
            "give initial poses (VERTEX lines) instead"
        )
    return chain_poses(step, start)
