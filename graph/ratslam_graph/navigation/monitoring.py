"""Transition monitoring and link adaptation (experience-map paper, Section III D).

Every transition between experiences is recorded with the movement behaviour executed
on it. The links leaving the source with that behaviour predicted where the robot would
arrive: the one to the experience it reached counts a success, every one of them counts
a trial, and a link's confidence is ``c_ij = n_ij / n_i,beta_ij`` (Eq. 9,
:func:`ratslam_graph.features.link_confidence`). A link whose confidence falls below the
threshold is deleted; when the robot later makes the transition again the link is
learnt anew (a relearnt link starts over with one success in one trial).

The table is a frozen set of arrays (the map's ``links()`` fields) and
:func:`record_transition` returns a new table: no Python loop over links.

Example:
    >>> from ratslam_graph.navigation.monitoring import LinkTable, record_transition
    >>> t = LinkTable.empty()
    >>> t, r = record_transition(t, 0, 1, behaviour=2, dt=1.5, threshold=0.5)
    >>> r.learnt, t.src.tolist(), t.dst.tolist()
    (True, [0], [1])
    >>> t, r = record_transition(t, 0, 7, behaviour=2, dt=1.0, threshold=0.6)
    >>> r.as_predicted, r.deleted, t.confidence.tolist()
    (False, ((0, 1),), [1.0])
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ratslam_graph.errors import InputError
from ratslam_graph.features import link_confidence

__all__ = ["LinkTable", "TransitionRecord", "record_transition"]

_I = np.int64


@dataclass(frozen=True)
class LinkTable:
    """Links with their Eq. 9 counts.

    Attributes:
        src, dst: link endpoints (a link ``src -> dst`` predicts that behaviour
            ``behaviour`` leaving ``src`` arrives at ``dst``).
        behaviour: the movement behaviour ``beta_ij`` the link was learnt with.
        dt: transition time (s) of the link's latest traversal.
        successes: ``n_ij``; trials: ``n_i,beta_ij``.
        deleted: ``(D, 2)`` pairs whose links were deleted (and not yet relearnt).

    Shape:
        src, dst, behaviour, dt, successes, trials: (E,); deleted: (D, 2).
    """

    src: np.ndarray
    dst: np.ndarray
    behaviour: np.ndarray
    dt: np.ndarray
    successes: np.ndarray
    trials: np.ndarray
    deleted: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=_I))

    @classmethod
    def empty(cls) -> LinkTable:
        """A table without links."""
        z = np.zeros(0, dtype=_I)
        return cls(z, z, z, np.zeros(0), z, z)

    @classmethod
    def from_links(cls, links: dict[str, Any]) -> LinkTable:
        """A table from an experience map's ``links()`` arrays (``src, dst, behaviour,
        dt, successes, trials``)."""
        return cls(
            src=np.asarray(links["src"], dtype=_I),
            dst=np.asarray(links["dst"], dtype=_I),
            behaviour=np.asarray(links["behaviour"], dtype=_I),
            dt=np.asarray(links["dt"], dtype=np.float64),
            successes=np.asarray(links["successes"], dtype=_I),
            trials=np.asarray(links["trials"], dtype=_I),
        )

    def __len__(self) -> int:
        return len(self.src)

    @property
    def confidence(self) -> np.ndarray:
        """Eq. 9 confidence of every link, (E,)."""
        return link_confidence(self.successes, self.trials)


@dataclass(frozen=True)
class TransitionRecord:
    """One monitored transition.

    Attributes:
        src, dst: the experiences left and reached.
        behaviour: the behaviour executed on the transition.
        predicted: where the links leaving ``src`` with that behaviour predicted arrival.
        as_predicted: whether ``dst`` is among ``predicted`` (False when nothing was
            predicted: the transition was new).
        learnt: a link ``src -> dst`` was added (new or relearnt).
        relearnt: that link had been deleted before.
        deleted: links ``(src, dst)`` deleted because their confidence fell below the
            threshold.
    """

    src: int
    dst: int
    behaviour: int
    predicted: tuple[int, ...]
    as_predicted: bool
    learnt: bool
    relearnt: bool
    deleted: tuple[tuple[int, int], ...]


def _pair_in(pairs: np.ndarray, a: int, b: int) -> np.ndarray:
    return (pairs[:, 0] == a) & (pairs[:, 1] == b)


def record_transition(
    table: LinkTable,
    src: int,
    dst: int,
    *,
    behaviour: int,
    dt: float,
    threshold: float,
) -> tuple[LinkTable, TransitionRecord]:
    """Record the transition ``src -> dst`` made with ``behaviour`` (Section III D).

    1. Every link leaving ``src`` with ``behaviour`` counts a trial; the one to ``dst``
       counts a success (Eq. 9's ``n_i,beta`` and ``n_ij``), and takes ``dt``.
    2. Links of that group whose confidence fell below ``threshold`` are deleted.
    3. Without a link between the pair (either direction), ``src -> dst`` is learnt with
       one success in one trial (relearnt when it had been deleted).

    Args:
        table: the links.
        src, dst: the experiences left and reached (distinct).
        behaviour: the behaviour executed.
        dt: the transition's duration (s).
        threshold: links with confidence below this are deleted (0 deletes none).

    Returns:
        The updated table and the transition's record.
    """
    if src == dst:
        raise InputError(f"a transition needs two experiences, got {src} -> {dst}")
    if not 0.0 <= threshold <= 1.0:
        raise InputError(f"confidence threshold {threshold} must be in [0, 1]")
    group = (table.src == src) & (table.behaviour == behaviour)
    hit = group & (table.dst == dst)
    predicted = tuple(int(v) for v in np.unique(table.dst[group]))
    successes = table.successes + hit
    trials = table.trials + group
    conf = link_confidence(successes, trials)
    doomed = group & (conf < threshold)
    keep = ~doomed
    deleted = tuple((int(src), int(v)) for v in table.dst[doomed])
    gone = np.concatenate([table.deleted, np.array(deleted, dtype=_I).reshape(-1, 2)])
    t = LinkTable(
        src=table.src[keep],
        dst=table.dst[keep],
        behaviour=table.behaviour[keep],
        dt=np.where(hit, float(dt), table.dt)[keep],
        successes=successes[keep],
        trials=trials[keep],
        deleted=gone,
    )
    linked = ((t.src == src) & (t.dst == dst)) | ((t.src == dst) & (t.dst == src))
    learnt = not bool(linked.any())
    relearnt = False
    if learnt:
        was = _pair_in(gone, src, dst) | _pair_in(gone, dst, src)
        relearnt = bool(was.any())
        t = LinkTable(
            src=np.append(t.src, _I(src)),
            dst=np.append(t.dst, _I(dst)),
            behaviour=np.append(t.behaviour, _I(behaviour)),
            dt=np.append(t.dt, float(dt)),
            successes=np.append(t.successes, _I(1)),
            trials=np.append(t.trials, _I(1)),
            deleted=gone[~was],
        )
    record = TransitionRecord(
        src=int(src),
        dst=int(dst),
        behaviour=int(behaviour),
        predicted=predicted,
        as_predicted=dst in predicted,
        learnt=learnt,
        relearnt=relearnt,
        deleted=deleted,
    )
    return t, record
