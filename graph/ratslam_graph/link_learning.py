"""How a transition between experiences teaches the map's links (the experience-map
paper, Section III): Eq. 9's counts and deletions, Eq. 6's averaging.

:class:`~ratslam_graph.experience_map.ExperienceMap` calls these on every transition
(``CREATE``, ``LINK``, ``SET``); a navigator calls :func:`count_transition` for a
transition it observed itself. Both switches beyond the paper are read from the map's
parameters: ``exp_link_directed`` (each driven way its own link) and
``exp_link_overlap_m`` (Eq. 9 does not fail a link that predicted another
representation of the place reached).

Example:
    >>> from ratslam_graph.experience_graph import ExperienceGraph
    >>> from ratslam_graph.params import ExperienceMapParams
    >>> g = ExperienceGraph()
    >>> for x in (0.0, 1.0, 1.0):
    ...     _ = g.add_experience(x, 0.0, 0.0)
    >>> g.add_link(0, 1, 1.0, 0.0, 0.0, 1.0, behaviour=2)
    True
    >>> p = ExperienceMapParams(exp_link_confidence_threshold=0.5)
    >>> count_transition(g, p, 0, 2, 2)  # 0 -> 1 now 1 success in 2 trials
    >>> g.links()["trials"].tolist()
    [2]
    >>> count_transition(g, ExperienceMapParams(exp_link_overlap_m=0.5), 0, 2, 2)
    >>> g.links()["trials"].tolist()  # 2 is where 1 is: no trial
    [2]
"""

from __future__ import annotations

import math

import numpy as np

from ratslam_graph.experience_graph import ExperienceGraph
from ratslam_graph.features import average_transition, link_confidence
from ratslam_graph.geometry import inverse, wrap_angle
from ratslam_graph.params import ExperienceMapParams

__all__ = ["average_into", "count_transition"]


def count_transition(
    store: ExperienceGraph, params: ExperienceMapParams, src: int, dst: int, behaviour: int
) -> None:
    """Count the transition ``src -> dst`` for Eq. 9 and delete links whose confidence
    fell too low.

    Every link leaving ``src`` with the same behaviour had a trial; the one to ``dst``
    succeeded, the others failed. The link between the pair (either direction;
    ``exp_link_directed``: ``src -> dst``) counts a traversal. Links leaving ``src``
    whose confidence falls below ``exp_link_confidence_threshold`` (0: never) are
    removed. With ``exp_link_overlap_m`` > 0 a link to another representation of
    ``dst``'s place (within that distance of it in the map, facing within 45 degrees of
    its way) has no trial: the robot arrived where it predicted.
    """
    s, threshold, overlap_m = store, params.exp_link_confidence_threshold, params.exp_link_overlap_m
    k_pair = s.link_index(src, dst, directed=params.exp_link_directed)
    # the links leaving src (a node's few out-links, not the map's links)
    beh, dsts, counts = s.behaviour, s.dst, s.counts
    rows = [k for k in s.out_links(src) if beh[k] == behaviour]
    if overlap_m > 0.0 and rows:
        there = s.pose[dsts[rows]] - s.pose[dst]
        same = (np.hypot(there[:, 0], there[:, 1]) <= overlap_m) & (
            np.abs(wrap_angle(there[:, 2])) <= np.pi / 4
        )
        rows = [k for k, o in zip(rows, same.tolist()) if dsts[k] == dst or not o]
    for k in rows:
        counts[k, 2] += 1
        if dsts[k] == dst:
            counts[k, 1] += 1
    if k_pair >= 0:
        counts[k_pair, 0] += 1
        s.edge_dirty[k_pair] = 1
    s.edge_dirty[rows] = 1
    if threshold > 0.0 and rows:
        sel = np.array(rows, dtype=np.int64)
        conf = link_confidence(counts[sel, 1], counts[sel, 2])
        for v in dsts[sel[conf < threshold]].tolist():
            s.remove_link(src, int(v))


def average_into(
    store: ExperienceGraph,
    k: int,
    src: int,
    measured: tuple[float, float, float],
    dt: float,
) -> None:
    """Average a transition measured from ``src`` into link ``k`` (Eq. 6).

    Args:
        store: the map's experiences and links.
        k: the link's row (from ``src`` or, the other way, to it).
        src: the experience the transition left.
        measured: ``(d, heading, facing)`` relative to ``src``'s orientation.
        dt: the transition's time (s); the link's becomes the mean of both.
    """
    d, heading, facing = measured
    meas = np.array([d * math.cos(heading), d * math.sin(heading), facing])
    if int(store.src[k]) != src:  # the link runs the other way: express it from its source
        meas = inverse(meas, include_pi=True)
    new = average_transition(store.meas[k], meas)
    t = 0.5 * (float(store.link[k, 3]) + dt)
    store.set_link(k, math.hypot(new[0], new[1]), math.atan2(new[1], new[0]), float(new[2]), t)
