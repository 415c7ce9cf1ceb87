"""The networkx view of an experience graph, brought up to date when it is read.

:class:`~ratslam_graph.experience_graph.ExperienceGraph` keeps experiences and links in
numpy arrays; :class:`GraphMirror` holds the :class:`networkx.DiGraph` that mirrors them
and what changed since it was last read (new experiences and links, attributes gone
stale, poses moved), so a run that never reads the graph never pays for it.

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

    The owner says what changed (:attr:`pending_edges`, :attr:`dirty_nodes`,
    :attr:`poses_dirty`, and its own ``edge_dirty`` array for link attributes);
    :meth:`read` applies it. networkx is imported, and the graph made, when the graph is
    first needed: a run that never reads it never loads networkx.

    Attributes:
        pending_edges: links made since the last read, in order ``(src, dst)``.
        dirty_nodes: experiences whose attributes are stale.
        poses_dirty: every experience's ``x, y, th`` is stale.
    """

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """An empty graph, nothing pending."""
        self._made: nx.DiGraph | None = None
        self.pending_edges: list[tuple[int, int]] = []
        self.dirty_nodes: set[int] = set()
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
        self._sync_structure(s.n)
        if self.dirty_nodes:
            nodes = self._g.nodes
            for i in sorted(self.dirty_nodes):
                nodes[i].update(_node_attrs(s, i))
            self.dirty_nodes.clear()
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

    def _sync_structure(self, n: int) -> None:
        """Add the experiences and links made since the graph was last read (their
        attributes follow from the dirty sets)."""
        g = self._g
        if len(g) < n:
            g.add_nodes_from(range(len(g), n))
        if self.pending_edges:
            g.add_edges_from(self.pending_edges)
            self.pending_edges.clear()

    def flush_edges(self, s: MirroredArrays) -> None:
        """Add the pending links and refresh every stale link's attributes (before link
        rows shift: the graph then holds every link with its current values)."""
        self._sync_structure(s.n)
        dirty = s.edge_dirty[: s.e]
        edges = self._g.edges
        for k in np.flatnonzero(dirty).tolist():
            edges[int(s.src[k]), int(s.dst[k])].update(_edge_attrs(s, k))
        dirty[:] = 0

    def remove_edge(self, src: int, dst: int) -> None:
        """Drop the link ``src -> dst`` (call :meth:`flush_edges` first)."""
        self._g.remove_edge(int(src), int(dst))

    def load(self, s: MirroredArrays) -> None:
        """The whole graph of ``s``, built at once (after a load)."""
        self.clear()
        self._g.add_nodes_from((i, _node_attrs(s, i)) for i in range(s.n))
        src, dst = s.src[: s.e].tolist(), s.dst[: s.e].tolist()
        self._g.add_edges_from((src[k], dst[k], _edge_attrs(s, k)) for k in range(s.e))
