"""Where :class:`~torchratslam.pose_cells.stage.PoseCells` keeps its scalars for the
compiled frame (:mod:`~torchratslam.pose_cells._frame`), the kernels' statuses, and the
helpers that keep the arrays (:class:`Slot`, :func:`grown`, :func:`link_chains`).

``ist`` (int64, :data:`I_SIZE`): the current experience, the current and previous
template, the numbers of templates and experiences, the two "arrived since the last
decision" flags, then the configuration (:data:`I_RULE`: ``vt_inject_rule ==
"openratslam"``).

``fst`` (float64, :data:`F_SIZE`): the centre ``(x, y, th)`` from :data:`BEST`, the last
injection's theta offset (cells), this view's relative angle, then the configuration:
``pc_vt_inject_energy``, ``vt_active_decay``, ``pc_vt_restore``,
``exp_delta_pc_threshold``, ``pc_cell_x_size`` and the dims ``X, Y, TH`` as floats.
"""

from __future__ import annotations

from typing import Any, Generic, TypeVar

import numpy as np

_T = TypeVar("_T")

CUR_EXP, CUR_VT, PREV_VT, N_T, N_E, ODO_UPD, VT_UPD = 0, 1, 2, 3, 4, 5, 6
I_RULE = 8
I_SIZE = 9

BEST, VT_DELTA, REL_RAD = 0, 3, 4
F_ENERGY, F_ACTIVE, F_RESTORE, F_THRESHOLD, F_CELL, F_DIMS = 8, 9, 10, 11, 12, 13
F_SIZE = 16

RECENT = 10
"""Templates among the last this many learnt do not inject energy."""

# the kernels' statuses (0: done)
GROW = 1  # done; a template or experience buffer is full (grow it before the next frame)
BAD_ID = 2  # a template id out of range (nothing changed)
BAD_CELL = 3  # a template cell that is not finite (int() would raise)
BAD_ENERGY = 4  # an injection that is not finite
BAD_ODOMETRY = 5  # odometry that is not finite (the view was applied)
ALL_ZERO = 6  # the activity is all zero (the view was applied)
DIED = 7  # the activity died out (the view was applied, nothing written)


class Slot(Generic[_T]):
    """An attribute kept in one cell of a state array (``ist`` or ``fst``) that the
    compiled frame reads and writes."""

    def __init__(self, array: str, index: int, kind: type[_T]) -> None:
        self.array, self.index, self.kind = array, index, kind

    def __get__(self, obj: Any, owner: Any = None) -> _T:
        if obj is None:
            return self  # type: ignore[return-value]
        return self.kind(obj.__dict__[self.array][self.index])  # type: ignore[call-arg]

    def __set__(self, obj: Any, value: _T) -> None:
        obj.__dict__[self.array][self.index] = value


def grown(a: np.ndarray, n: int, fill: float) -> np.ndarray:
    """``a`` with a free row past its first ``n`` (doubling: every row kept, new rows
    ``fill``)."""
    if n < len(a):
        return a
    out = np.full((max(16, 2 * n), *a.shape[1:]), fill, dtype=a.dtype)
    out[: len(a)] = a
    return out


def link_chains(e_template: np.ndarray, t_chain: np.ndarray, e_next: np.ndarray) -> None:
    """Chain each template's experiences in creation order: ``t_chain[t] = (first,
    last)``, ``e_next[e]`` the next (``-1``: none); the chains start empty."""
    for i, t in enumerate(e_template.tolist()):  # restore only, not a hot path
        if t >= 0:
            if t_chain[t, 1] >= 0:
                e_next[t_chain[t, 1]] = i
            else:
                t_chain[t, 0] = i
            t_chain[t, 1] = i
