"""Relaxing the experience map: functions on the map's arrays.

:meth:`ratslam_graph.experience_map.ExperienceMap.iterate` picks one of three paths:

* ``exp_backend="alpha"`` with ``exp_relax_order="openratslam"`` (the defaults):
  :func:`sweep_in_place`, OpenRatSLAM's ``iterate()`` compiled, in place on the map's own
  arrays, the links in its order (:func:`reference_order`, kept current link after link
  by :class:`ReferenceOrder`), its arithmetic. A pass that changes nothing ends the
  relaxation and later calls are skipped until poses or links change (exact: the result
  is bit-identical to running every pass). With ``exp_relax_budget`` a relaxation makes
  at most that many link updates, going on round the links where the previous one
  stopped.
* a backend with ``relax_inplace`` (``exp_backend="alpha_local"``): the map's own arrays,
  relaxed only where the map changed since its last call.
* any other backend: :func:`relax_with_backend` relaxes the map's
  :class:`~ratslam_graph.posegraph.PoseGraph` and writes the poses back. With
  ``exp_relax_order="colour"`` a relaxation whose first pass moves nothing by more than
  the map's ``relax_tol`` (relative to its extent) stops there (the map is at the sweep's
  fixed point to rounding), and later calls are skipped until poses or links change.
  This is a deliberate deviation from always running ``exp_loops`` passes: the map
  differs from the always-run one by rounding noise only (tested to 1e-9); set
  ``relax_tol = 0`` to disable it.

Nothing here loops over links in Python.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ratslam_graph.errors import GraphError
from ratslam_graph.geometry import wrap_angle
from ratslam_graph.posegraph import PoseGraph
from ratslam_graph.protocols import RelaxationBackend

if TYPE_CHECKING:
    from ratslam_graph.params import ExperienceMapParams

__all__ = [
    "MapArrays",
    "ReferenceOrder",
    "log_not_converged",
    "make_map_backend",
    "reference_links",
    "reference_order",
    "relax_local",
    "relax_map",
    "relax_with_backend",
    "sweep_in_place",
]

log = logging.getLogger(__name__)

ReferenceLinks = tuple[np.ndarray, np.ndarray, np.ndarray]
"""Link sources, targets and ``(d, heading, facing)`` in OpenRatSLAM's order."""


class MapArrays(Protocol):
    """What :func:`relax_map` needs of a map's store
    (:class:`~ratslam_graph.experience_graph.ExperienceGraph`)."""

    n: int
    e: int
    pose: np.ndarray
    src: np.ndarray
    dst: np.ndarray
    link: np.ndarray

    def reference_links(self) -> ReferenceLinks: ...

    def posegraph(self, order: str = ...) -> PoseGraph: ...

    def poses_changed(self) -> None: ...


def make_map_backend(name: str, relax_order: str) -> RelaxationBackend:
    """The backend ``exp_backend`` names; the alpha rule visits links in ``relax_order``
    (``exp_relax_order``).

    Raises:
        ConfigError: unknown backend or order.
    """
    from ratslam_graph.backends import make_backend

    if name == "alpha":
        return make_backend(name, schedule=relax_order)
    return make_backend(name)


def reference_order(src: np.ndarray) -> np.ndarray:
    """OpenRatSLAM's relaxation order: by source experience, then link creation.

    Shape:
        src: (E,). Returns (E,) int64 indices into the links.
    """
    return np.argsort(src, kind="stable")


def reference_links(
    src: np.ndarray, dst: np.ndarray, link: np.ndarray, order: np.ndarray
) -> ReferenceLinks:
    """Link ends and ``(d, heading, facing)`` in ``order``, contiguous for the sweep.

    Shape:
        src, dst: (E,); link: (E, >=3) ``[d, heading, facing, ...]``; order: (E,).
        Returns (E,), (E,), (E, 3).
    """
    return (
        np.ascontiguousarray(src[order]),
        np.ascontiguousarray(dst[order]),
        np.ascontiguousarray(link[:, :3][order]),
    )


class ReferenceOrder:
    """The links in OpenRatSLAM's order (:func:`reference_order`), kept current link
    after link in buffers with spare room: a new link is inserted after every link of a
    source ``<= src`` (creation order within a source) by moving the tail one row, no
    sort and no Python loop over links.

    Args:
        src, dst: the links' ends (creation order).
        link: the links' ``[d, heading, facing, ...]``.

    Shape:
        src, dst: (E,); link: (E, >=3).
    """

    def __init__(self, src: np.ndarray, dst: np.ndarray, link: np.ndarray) -> None:
        order = reference_order(src)
        ref = reference_links(src, dst, link, order)
        self.n = len(order)
        self._bufs: list[np.ndarray] = [order, *ref]

    @property
    def order(self) -> np.ndarray:
        """Indices of the links (creation rows) in OpenRatSLAM's order.

        Shape:
            (E,) int64.
        """
        return self._bufs[0][: self.n]

    @property
    def links(self) -> ReferenceLinks:
        """Sources, targets and ``(d, heading, facing)`` in that order: views, valid until
        the next :meth:`insert`.

        Shape:
            (E,), (E,), (E, 3).
        """
        n = self.n
        return self._bufs[1][:n], self._bufs[2][:n], self._bufs[3][:n]

    def insert(self, k: int, src: int, dst: int, link: np.ndarray) -> None:
        """Insert link ``k`` (the newest) with ends ``src``, ``dst`` and ``link[:3]``
        (one compiled call: a binary search and the tail moved one row).

        Shape:
            link: (>=3,).
        """
        self.reserve()
        from ratslam_graph.backends._sweep import insert_link

        order, srcs, dsts, values = self._bufs
        insert_link(order, srcs, dsts, values, self.n, k, src, dst, link)
        self.n += 1

    def reserve(self) -> None:
        """Make room for one more link in the buffers (doubling)."""
        n = self.n
        if n == len(self._bufs[0]):
            cap = max(16, 2 * n)
            grown = []
            for a in self._bufs:
                b = np.zeros((cap, *a.shape[1:]), dtype=a.dtype)
                b[:n] = a[:n]
                grown.append(b)
            self._bufs = grown

    @property
    def buffers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The buffers (order, sources, targets, values), ``n`` rows in use, for the
        compiled frame (:mod:`ratslam_graph.frame_step`), which inserts in place."""
        order, srcs, dsts, values = self._bufs
        return order, srcs, dsts, values


def sweep_in_place(
    pose: np.ndarray,
    ref: ReferenceLinks,
    *,
    loops: int,
    correction: float,
    budget: int,
    cursor: int,
) -> tuple[int, bool]:
    """OpenRatSLAM's relaxation, compiled, in place on ``pose``.

    Args:
        pose: the map's poses ``[x, y, th]`` (float64, C-contiguous); updated in place.
        ref: the links in OpenRatSLAM's order (:func:`reference_links`).
        loops: passes (``exp_loops``).
        correction: ``exp_correction``.
        budget: ``exp_relax_budget``: 0, or the most link updates when ``loops`` passes
            would make more; they go on round the links from ``cursor``.
        cursor: the link the previous bounded relaxation stopped at.

    Returns:
        (the link the next relaxation starts at, True if the map is at its fixed point:
        a whole pass changed nothing).

    Shape:
        pose: (N, 3).
    """
    from ratslam_graph.backends._sweep import sweep, sweep_window

    src, dst, link = ref
    if budget and loops * len(src) > budget:
        cursor, moved = sweep_window(pose, src, dst, link, cursor, budget, float(correction))
        return cursor, not moved and budget >= len(src)
    ran = sweep(pose, src, dst, link, loops, float(correction))
    return 0, ran < loops


def relax_local(
    backend: Any,
    pose: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    link: np.ndarray,
    *,
    loops: int,
    correction: float,
    budget: int,
) -> bool:
    """Relax with a backend's ``relax_inplace`` on the map's own arrays (``alpha_local``:
    only where the map changed since its last call, so no O(N) work here).

    Returns:
        True if the backend says it reached a fixed point (``last_converged``).

    Shape:
        pose: (N, 3), updated in place; src, dst: (E,); link: (E, 4).
    """
    backend.relax_inplace(pose, src, dst, link, passes=loops, correction=correction, budget=budget)
    return bool(getattr(backend, "last_converged", False))


def relax_with_backend(
    backend: RelaxationBackend,
    pose: np.ndarray,
    pg: PoseGraph,
    *,
    loops: int,
    correction: float,
    relax_tol: float,
    name: str,
) -> bool:
    """Relax ``pg`` with ``backend`` and write the poses into ``pose`` (angles wrapped).

    Args:
        backend: the relaxation backend.
        pose: the map's poses, the rows of ``pg``; updated in place.
        pg: the map as a pose graph.
        loops: passes (``exp_loops``).
        correction: ``exp_correction``.
        relax_tol: relative early-stop tolerance, for backends that take ``tol``.
        name: the backend's name, for messages.

    Returns:
        True if the backend says it reached a fixed point (``last_converged``).

    Raises:
        GraphError: the backend returned poses of the wrong shape or non-finite ones.

    Shape:
        pose: (N, 3).
    """
    n = len(pose)
    kw: dict[str, float] = {"correction": correction}
    if getattr(backend, "accepts_tol", False):
        extent = float(np.abs(pose[:, :2]).max())
        kw["tol"] = relax_tol * max(1.0, extent)
    new = np.asarray(backend.relax(pg, passes=loops, **kw), dtype=np.float64)
    if new.shape != (n, 3) or not np.all(np.isfinite(new)):
        raise GraphError(
            f"backend {name!r} returned poses of shape {new.shape} "
            f"(expected ({n}, 3), finite); check the backend"
        )
    pose[:, :2] = new[:, :2]
    pose[:, 2] = wrap_angle(new[:, 2], include_pi=True)
    return bool(getattr(backend, "last_converged", False))


def log_not_converged(loops: int, backend: str, n: int) -> None:
    """Say (at DEBUG) that a relaxation's passes did not reach a fixed point."""
    if log.isEnabledFor(logging.DEBUG):
        log.debug(
            "relaxation: %d passes of %r did not reach a fixed point (%d experiences)",
            loops,
            backend,
            n,
        )


def relax_map(
    s: MapArrays,
    params: ExperienceMapParams,
    backend: RelaxationBackend,
    *,
    cursor: int,
    relax_tol: float,
) -> tuple[int, bool]:
    """Relax a map's arrays in place by the path its settings pick (this module's
    docstring), ``exp_loops`` passes; the poses are written back and marked changed.

    Args:
        s: the experiences and links (at least two experiences and a link).
        params: ``exp_loops``, ``exp_correction``, ``exp_backend``, ``exp_relax_budget``.
        backend: the relaxation backend.
        cursor: the link a budgeted OpenRatSLAM sweep starts at.
        relax_tol: relative early-stop tolerance, for backends that take ``tol``.

    Returns:
        The next cursor and whether a fixed point was reached.
    """
    loops, correction = params.exp_loops, params.exp_correction
    alpha = params.exp_backend.startswith("alpha")
    relax_inplace = getattr(backend, "relax_inplace", None)
    if alpha and getattr(backend, "schedule", None) == "openratslam":
        # the map's own arrays: float64, C-contiguous, int64 ends
        budget = params.exp_relax_budget
        cursor, fixed = sweep_in_place(
            s.pose,
            s.reference_links(),
            loops=loops,
            correction=correction,
            budget=budget,
            cursor=cursor,
        )
        if not (fixed or (bool(budget) and loops * s.e > budget)):
            log_not_converged(loops, params.exp_backend, s.n)
    elif callable(relax_inplace):  # alpha_local: relaxed only where the map changed
        fixed = relax_local(
            backend,
            s.pose[: s.n],
            s.src[: s.e],
            s.dst[: s.e],
            s.link[: s.e],
            loops=loops,
            correction=correction,
            budget=params.exp_relax_budget,
        )
    else:
        fixed = relax_with_backend(
            backend,
            s.pose[: s.n],
            s.posegraph(),
            loops=loops,
            correction=correction,
            relax_tol=relax_tol,
            name=params.exp_backend,
        )
        if not fixed and alpha:
            log_not_converged(loops, params.exp_backend, s.n)
    s.poses_changed()
    return cursor, fixed
