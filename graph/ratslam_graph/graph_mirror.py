"""The networkx view of an experience graph, brought up to date when it is read.

:class:`~ratslam_graph.experience_graph.ExperienceGraph` keeps experiences and links in
numpy arrays; :class:`GraphMirror` holds the :class:`networkx.DiGraph` that mirrors them
and what changed since it was last read (new experiences and links, attributes gone
stale, poses moved), so a run that never reads the graph never pays for it. New
experiences and links are rows past those it holds (the arrays only grow at the end, and
a removed link's rows shift after the graph took every link), so nothing is recorded
when they are made.

Example:
    >>> from ratslam_graph.experience_graph import ExperienceGraph
    >>> g = ExperienceGraph()
    >>> g.add_experience(0.0, 0.0, 0.0), g.add_experience(1.0, 0.0, 0.0)
    (0, 1)
    >>> g.add_link(0, 1, 1.0, 0.0, 0.0, 2.0)
    True
    >>> sorted(g.graph.edges), g.graph.nodes[1]["x"]
    ([(0, 1)], 1.0)
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ratslam_graph.features import link_confidence

if TYPE_CHECKING:
    import networkx as nx

__all__ = ["GraphMirror", "MirroredArrays"]


class MirroredArrays(Protocol):
    """The arrays a :class:`GraphMirror` mirrors
    (:class:`~ratslam_graph.experience_graph.ExperienceGraph`'s)."""

    n: int
    e: int
    pose: np.ndarray
    pc: np.ndarray
    vt: np.ndarray
    frame: np.ndarray
    t: np.ndarray
    src: np.ndarray
    dst: np.ndarray
    link: np.ndarray
    counts: np.ndarray
    behaviour: np.ndarray
    edge_dirty: np.ndarray


def _node_attrs(s: MirroredArrays, i: int) -> dict[str, Any]:
    """The graph attributes of experience ``i``."""
    x, y, th = s.pose[i].tolist()
    return {
        "x": x,
        "y": y,
        "th": th,
        "pc": tuple(s.pc[i].tolist()),
        "template_id": int(s.vt[i]),
        "frame": int(s.frame[i]),
        "t": float(s.t[i]),
    }


def _edge_attrs(s: MirroredArrays, k: int) -> dict[str, Any]:
    """The graph attributes of link ``k``."""
    d, heading, facing, dt = s.link[k].tolist()
    trav, succ, trials = s.counts[k].tolist()
    return {
        "d": d,
        "heading": heading,
        "facing": facing,
        "dt": dt,
        "traversals": trav,
        "successes": succ,
        "trials": trials,
        "behaviour": int(s.behaviour[k]),
        "confidence": float(link_confidence(succ, trials)),
    }


class GraphMirror:
    """A :class:`networkx.DiGraph` mirroring an experience graph's arrays, lazily.

    The owner's rows past :attr:`nodes` and :attr:`edges` are new; it says what else
    changed (:attr:`poses_dirty`, and its own ``edge_dirty`` array for link attributes);
    :meth:`read` applies it. networkx is imported, and the graph made, when the graph is
    first needed: a run that never reads it never loads networkx.

    Attributes:
        nodes, edges: the experiences and links (rows ``[:nodes]``, ``[:edges]``) the
            graph holds.
        poses_dirty: every experience's ``x, y, th`` is stale.
    """

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """An empty graph, nothing pending."""
        self._made: nx.DiGraph | None = None
        self.nodes = 0
        self.edges = 0
        self.poses_dirty = False

    @property
    def _g(self) -> nx.DiGraph:
        """The graph (made empty when first needed)."""
        if self._made is None:
            import networkx as nx

            self._made = nx.DiGraph()
        return self._made

    def read(self, s: MirroredArrays) -> nx.DiGraph:
        """The graph, brought up to date with ``s``'s arrays."""
        self._sync_structure(s)
        if s.edge_dirty[: s.e].any():
            self.flush_edges(s)
        if self.poses_dirty:
            import networkx as nx

            p = s.pose[: s.n].tolist()
            nx.set_node_attributes(
                self._g, {i: {"x": x, "y": y, "th": th} for i, (x, y, th) in enumerate(p)}
            )
            self.poses_dirty = False
        return self._g

    def _sync_structure(self, s: MirroredArrays) -> None:
        """Add the experiences (with their attributes) and links (their attributes follow
        from ``edge_dirty``) made since the graph was last read."""
        g = self._g
        n, e = s.n, s.e
        if self.nodes < n:
            g.add_nodes_from((i, _node_attrs(s, i)) for i in range(self.nodes, n))
            self.nodes = n
        if self.edges < e:
            src, dst = s.src[self.edges : e].tolist(), s.dst[self.edges : e].tolist()
            g.add_edges_from(zip(src, dst))
            self.edges = e

    def flush_edges(self, s: MirroredArrays) -> None:
        """Add the pending links and refresh every stale link's attributes (before link
        rows shift: the graph then holds every link with its current values)."""
        self._sync_structure(s)
        dirty = s.edge_dirty[: s.e]
        edges = self._g.edges
        for k in np.flatnonzero(dirty).tolist():
            edges[int(s.src[k]), int(s.dst[k])].update(_edge_attrs(s, k))
        dirty[:] = 0

    def remove_edge(self, src: int, dst: int) -> None:
        """Drop the link ``src -> dst`` (call :meth:`flush_edges` first; the owner's later
        link rows shift down one)."""
        self._g.remove_edge(int(src), int(dst))
        self.edges -= 1

    def load(self, s: MirroredArrays) -> None:
        """The whole graph of ``s``, built at once (after a load)."""
        self.clear()
        self._g.add_nodes_from((i, _node_attrs(s, i)) for i in range(s.n))
        src, dst = s.src[: s.e].tolist(), s.dst[: s.e].tolist()
        self._g.add_edges_from((src[k], dst[k], _edge_attrs(s, k)) for k in range(s.e))
        self.nodes, self.edges = s.n, s.e
