"""Least-squares backends on gtsam: batch Levenberg-Marquardt ("gtsam") and iSAM2.

Factor graph: one ``BetweenFactorPose2(from, to, Pose2(dx, dy, dth))`` per edge and a
``PriorFactorPose2`` holding the lowest row of every connected component at its
current pose (a RatSLAM map has one component, a freshly merged multisession map can
have several; without a prior per component the system would be singular).

Noise model (documented choice): an edge uses the information matrix of the graph
(``PoseGraph.information``, read from g2o/TORO files, or the city10000 sigmas) when
there is one; otherwise the backend's ``sigmas`` (default ``(1, 1, 1)``: unit noise,
metres and radians weighted alike, the model that compares most directly with the
alpha rule, which corrects x, y and th with the same factor). Priors use
``prior_sigma`` (1e-4) on x, y and th. :func:`graph_error` evaluates the same edge
model (without priors, so a rigid motion of the whole map costs nothing).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import gtsam
import numpy as np

from ratslam_graph.errors import ConfigError, GraphError
from ratslam_graph.geometry import wrap_angle
from ratslam_graph.posegraph import PoseGraph, UnionFind

log = logging.getLogger(__name__)

DEFAULT_SIGMAS = (1.0, 1.0, 1.0)
DEFAULT_PRIOR_SIGMA = 1e-4


def _sigmas(sigmas: Sequence[float] | np.ndarray | None) -> np.ndarray:
    s = np.asarray(DEFAULT_SIGMAS if sigmas is None else sigmas, dtype=np.float64)
    if s.shape != (3,) or not np.all(s > 0):
        raise ConfigError(f"sigmas must be three positive numbers (x, y, th), got {sigmas!r}")
    return s


class _NoiseModels:
    """Noise model per edge: the graph's information, else one diagonal model."""

    def __init__(self, pg: PoseGraph, sigmas: Sequence[float] | np.ndarray | None) -> None:
        self.default = gtsam.noiseModel.Diagonal.Sigmas(_sigmas(sigmas))
        self.info = pg.information
        self._cache: dict[bytes, gtsam.noiseModel.Base] = {}

    def __call__(self, i: int) -> gtsam.noiseModel.Base:
        if self.info is None:
            return self.default
        m = self.info[i]
        key = m.tobytes()
        model = self._cache.get(key)
        if model is None:
            d = np.diag(m)
            if not (np.allclose(m, m.T) and np.all(np.linalg.eigvalsh(m) > 0)):
                raise GraphError(
                    f"edge {i}: information matrix {m.tolist()} is not symmetric positive "
                    "definite; fix the file or drop the information to use the default sigmas"
                )
            if np.count_nonzero(m - np.diag(d)) == 0:
                model = gtsam.noiseModel.Diagonal.Precisions(d)
            else:
                model = gtsam.noiseModel.Gaussian.Information(m)
            self._cache[key] = model
        return model


def _between_factors(pg: PoseGraph, rows: range, models: _NoiseModels) -> list:
    edges = pg.edges[rows.start : rows.stop].tolist()
    meas = pg.measurements[rows.start : rows.stop].tolist()
    return [
        gtsam.BetweenFactorPose2(a, b, gtsam.Pose2(*m), models(i))
        for i, (a, b), m in zip(rows, edges, meas)
    ]


def _values(poses: np.ndarray, rows: range | None = None) -> gtsam.Values:
    v = gtsam.Values()
    rows = range(len(poses)) if rows is None else rows
    for i, p in zip(rows, poses[rows.start : rows.stop].tolist()):
        v.insert(i, gtsam.Pose2(*p))
    return v


def _poses_from(values: gtsam.Values, n: int) -> np.ndarray:
    out = np.asarray(gtsam.utilities.extractPose2(values), dtype=np.float64).reshape(-1, 3)
    if out.shape != (n, 3):
        raise GraphError(f"gtsam returned {len(out)} poses for a graph of {n}")
    return out


def factor_graph(
    pg: PoseGraph, *, sigmas: Sequence[float] | np.ndarray | None = None, priors: bool = True
) -> gtsam.NonlinearFactorGraph:
    """The gtsam factor graph of ``pg`` (see the module doc for the noise model)."""
    g = gtsam.NonlinearFactorGraph()
    for f in _between_factors(pg, range(pg.num_edges), _NoiseModels(pg, sigmas)):
        g.add(f)
    if priors:
        prior = gtsam.noiseModel.Isotropic.Sigma(3, DEFAULT_PRIOR_SIGMA)
        for r in pg.component_roots().tolist():
            g.add(gtsam.PriorFactorPose2(r, gtsam.Pose2(*pg.poses[r]), prior))
    return g


class GraphErrorEvaluator:
    """``graph.error`` of one graph's edges (no priors) for many pose sets."""

    def __init__(
        self, pg: PoseGraph, *, sigmas: Sequence[float] | np.ndarray | None = None
    ) -> None:
        self.num_poses = pg.num_poses
        self.graph = factor_graph(pg, sigmas=sigmas, priors=False)

    def __call__(self, poses: np.ndarray) -> float:
        """Shape: poses (N, 3)."""
        poses = np.asarray(poses, dtype=np.float64)
        if poses.shape != (self.num_poses, 3):
            raise GraphError(f"expected poses of shape ({self.num_poses}, 3), got {poses.shape}")
        return float(self.graph.error(_values(poses)))


def graph_error(
    pg: PoseGraph,
    poses: np.ndarray | None = None,
    *,
    sigmas: Sequence[float] | np.ndarray | None = None,
) -> float:
    """gtsam's ``graph.error`` (0.5 sum of squared whitened residuals) of the edges.

    Shape:
        poses: (N, 3) or None (``pg.poses``).
    """
    return GraphErrorEvaluator(pg, sigmas=sigmas)(pg.poses if poses is None else poses)


class GtsamBackend:
    """Batch Levenberg-Marquardt from the current poses (``passes`` is ignored).

    Args:
        sigmas: default edge sigmas (x, y, th) when the graph has no information.
        max_iterations: LM iteration limit.
        relative_error_tol: LM stopping tolerance on the relative error decrease.
    """

    name = "gtsam"
    incremental = False

    def __init__(
        self,
        sigmas: Sequence[float] | np.ndarray | None = None,
        max_iterations: int = 100,
        relative_error_tol: float = 1e-10,
    ) -> None:
        self.sigmas = _sigmas(sigmas)
        self.params = gtsam.LevenbergMarquardtParams()
        self.params.setMaxIterations(int(max_iterations))
        self.params.setRelativeErrorTol(float(relative_error_tol))
        self.params.setAbsoluteErrorTol(0.0)
        self.iterations = 0

    def reset(self) -> None:
        """Nothing to forget (stateless)."""

    def relax(self, pg: PoseGraph, *, passes: int = 0, correction: float = 0.5) -> np.ndarray:
        """Optimise ``pg`` with LM; ``passes`` and ``correction`` are ignored.

        Returns:
            (N, 3) float64 optimised poses.
        """
        if pg.num_edges == 0:
            return pg.poses.copy()
        g = factor_graph(pg, sigmas=self.sigmas)
        opt = gtsam.LevenbergMarquardtOptimizer(g, _values(pg.poses), self.params)
        try:
            result = opt.optimize()
        except RuntimeError as exc:
            raise GraphError(f"gtsam LM failed: {exc}") from None
        self.iterations = opt.iterations()
        if self.iterations >= self.params.getMaxIterations():
            log.warning(
                "gtsam LM stopped at its limit of %d iterations before converging "
                "(error %.6g); raise max_iterations",
                self.iterations,
                opt.error(),
            )
        return _poses_from(result, pg.num_poses)


class ISAM2Backend:
    """Incremental smoothing (iSAM2): new nodes and edges are added as they appear.

    A call with a graph that extends the previous one (same first edges, same
    measurements and endpoints, more nodes and/or edges appended) only adds the new
    factors and initial values (new nodes start at ``pg.poses``) and runs one iSAM2
    update, plus ``extra_updates`` more; a call with an unchanged graph runs one more
    update (another relinearisation step). The first call, and any other change (edited
    or deleted links, reordered nodes, as after a map merge or link averaging), rebuilds
    from ``pg.poses``: a batch LM solve whose optimum becomes iSAM2's linearisation point.
    The default ``relinearize_threshold`` (0.01, as gtsam's City10000 example) keeps
    online updates cheap and ends within ~3e-5 (relative) of LM's error on city10000
    slices; 0.001 reaches LM to 1e-6 at about twice the cost per pose.
    When two components with their own priors get linked, it rebuilds too, so a map
    never keeps a stale prior.

    Args:
        sigmas: default edge sigmas (x, y, th) when the graph has no information.
        relinearize_threshold: iSAM2 relinearisation threshold (per variable).
        relinearize_skip: relinearise every this many updates.
        extra_updates: additional ``update()`` calls per relax.
    """

    name = "isam2"
    incremental = True

    def __init__(
        self,
        sigmas: Sequence[float] | np.ndarray | None = None,
        relinearize_threshold: float = 0.01,
        relinearize_skip: int = 1,
        extra_updates: int = 0,
    ) -> None:
        self.sigmas = _sigmas(sigmas)
        self.relinearize_threshold = float(relinearize_threshold)
        self.relinearize_skip = int(relinearize_skip)
        self.extra_updates = int(extra_updates)
        self._lm = GtsamBackend(self.sigmas).params
        self.rebuilds = 0
        self.reset()

    def reset(self) -> None:
        """Forget everything; the next call rebuilds."""
        self._isam: gtsam.ISAM2 | None = None
        self._edges = np.zeros((0, 2), np.int64)
        self._meas = np.zeros((0, 3))
        self._info: np.ndarray | None = None
        self._n = 0
        self._uf = UnionFind()

    def _new_isam(self) -> gtsam.ISAM2:
        p = gtsam.ISAM2Params()
        p.setRelinearizeThreshold(self.relinearize_threshold)
        p.relinearizeSkip = self.relinearize_skip
        return gtsam.ISAM2(p)

    def _extends(self, pg: PoseGraph) -> bool:
        e = len(self._edges)
        if self._isam is None or pg.num_poses < self._n or pg.num_edges < e:
            return False
        if not (
            np.array_equal(pg.edges[:e], self._edges)
            and np.array_equal(pg.measurements[:e], self._meas)
        ):
            return False
        if (self._info is None) != (pg.information is None):
            return False
        info = pg.information
        return self._info is None or (info is not None and np.array_equal(info[:e], self._info))

    def relax(self, pg: PoseGraph, *, passes: int = 0, correction: float = 0.5) -> np.ndarray:
        """Bring the iSAM2 estimate up to date with ``pg``; ``passes`` is ignored.

        Returns:
            (N, 3) float64 current best estimate.
        """
        if pg.num_poses == 0:
            return pg.poses.copy()
        first_new = len(self._edges)
        incremental = self._extends(pg)
        if incremental:
            uf = self._uf
            uf.grow(pg.num_poses)
            for a, b in pg.edges[first_new:].tolist():
                ra, rb = uf.find(a), uf.find(b)
                if ra != rb and ra < self._n and rb < self._n:
                    incremental = False  # joins two old components, each with a prior
                    break
                uf.union(ra, rb)
        if incremental:
            new_edges = range(first_new, pg.num_edges)
            # new nodes not connected to older ones start components of their own
            prior_rows = [r for r in range(self._n, pg.num_poses) if self._uf.find(r) == r]
        else:
            if self._isam is not None:
                log.debug("iSAM2: the graph changed other than by appending; rebuilding")
            self.rebuilds += 1
            self.reset()
            self._isam = self._new_isam()
            self._uf.grow(pg.num_poses)
            for a, b in pg.edges.tolist():
                self._uf.union(a, b)
            new_edges = range(pg.num_edges)
            prior_rows = self._uf.roots().tolist()
        graph = gtsam.NonlinearFactorGraph()
        for f in _between_factors(pg, new_edges, _NoiseModels(pg, self.sigmas)):
            graph.add(f)
        prior = gtsam.noiseModel.Isotropic.Sigma(3, DEFAULT_PRIOR_SIGMA)
        for r in prior_rows:
            graph.add(gtsam.PriorFactorPose2(r, gtsam.Pose2(*pg.poses[r]), prior))
        values = _values(pg.poses, range(self._n, pg.num_poses))
        isam = self._isam
        assert isam is not None  # made above unless the graph extends the last one
        try:
            if not incremental and pg.num_edges:
                # a (re)build starts from scratch: solve it in batch and hand iSAM2 the
                # optimum as linearisation point, so it starts exactly where LM ends
                values = gtsam.LevenbergMarquardtOptimizer(graph, values, self._lm).optimize()
            isam.update(graph, values)
            for _ in range(self.extra_updates):
                isam.update()
            out = _poses_from(isam.calculateEstimate(), pg.num_poses)
        except RuntimeError as exc:
            self.reset()
            raise GraphError(f"iSAM2 update failed: {exc}") from None
        self._edges = pg.edges.copy()
        self._meas = pg.measurements.copy()
        self._info = None if pg.information is None else pg.information.copy()
        self._n = pg.num_poses
        out[:, 2] = wrap_angle(out[:, 2])
        return out
