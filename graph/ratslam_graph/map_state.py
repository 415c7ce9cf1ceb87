"""An experience map's state as plain arrays and scalars, and its checks on the way back.

:meth:`ratslam_graph.experience_map.ExperienceMap.get_state` and ``set_state`` call these;
savers (``ratslam_graph.state``, the pipeline's checkpoints) store the dictionary.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ratslam_graph.errors import MapFormatError

if TYPE_CHECKING:
    from ratslam_graph.experience_graph import ExperienceGraph

__all__ = ["STATE_FORMAT", "STATE_VERSION", "map_state", "read_map_state"]

STATE_FORMAT = "ratslam_graph.experience_map"
STATE_VERSION = 1

_INT_SCALARS = ("current_id", "prev_id")
_FLOAT_SCALARS = ("accum_x", "accum_y", "accum_facing", "accum_time", "relative_rad")


def map_state(
    s: ExperienceGraph, ints: np.ndarray, floats: np.ndarray, relax_cursor: int
) -> dict[str, Any]:
    """Everything needed to restore a map exactly: numpy arrays and Python scalars.

    Args:
        s: the experiences and links.
        ints: ``(current_id, prev_id)``.
        floats: ``(accum_x, accum_y, accum_facing, accum_time, relative_rad)``.
        relax_cursor: the link the next budgeted relaxation starts at.
    """
    n, e = s.n, s.e
    return {
        "format": STATE_FORMAT,
        "version": STATE_VERSION,
        "poses": s.pose[:n].copy(),
        "pc": s.pc[:n].copy(),
        "template_id": s.vt[:n].copy(),
        "frame": s.frame[:n].copy(),
        "t": s.t[:n].copy(),
        "link_ends": np.stack([s.src[:e], s.dst[:e]], axis=1),
        "link_values": s.link[:e].copy(),
        "link_counts": s.counts[:e].copy(),
        "link_behaviour": s.behaviour[:e].copy(),
        **{k: int(v) for k, v in zip(_INT_SCALARS, ints.tolist())},
        **{k: float(v) for k, v in zip(_FLOAT_SCALARS, floats.tolist())},
        "relax_cursor": int(relax_cursor),
    }


def read_map_state(state: dict[str, Any]) -> dict[str, Any]:
    """Check a :func:`map_state` dictionary; its arrays and scalars, typed.

    Raises:
        MapFormatError: see :meth:`~ratslam_graph.experience_map.ExperienceMap.set_state`.
    """
    fmt, version = state.get("format", STATE_FORMAT), state.get("version", STATE_VERSION)
    if fmt != STATE_FORMAT or version != STATE_VERSION:
        raise MapFormatError(
            f"not an experience-map state of version {STATE_VERSION} "
            f"(format={fmt!r}, version={version!r}); save it again with this version"
        )
    out: dict[str, Any]
    try:
        poses = np.array(state["poses"], dtype=np.float64).reshape(-1, 3)
        n = len(poses)
        ends = np.array(state["link_ends"], dtype=np.int64).reshape(-1, 2)
        e = len(ends)
        out = {
            "poses": poses,
            "pc": np.array(state["pc"], dtype=np.float64).reshape(n, 3),
            "template_id": np.array(state["template_id"], dtype=np.int64).reshape(n),
            "frame": np.array(state["frame"], dtype=np.int64).reshape(n),
            "t": np.array(state["t"], dtype=np.float64).reshape(n),
            "link_ends": ends,
            "link_values": np.array(state["link_values"], dtype=np.float64).reshape(e, 4),
            "link_counts": np.array(state["link_counts"], dtype=np.int64).reshape(e, 3),
            "link_behaviour": np.array(state["link_behaviour"], dtype=np.int64).reshape(e),
        }
        scalars = {k: state[k] for k in (*_INT_SCALARS, *_FLOAT_SCALARS[:-1])}
        scalars["relative_rad"] = state.get("relative_rad", 0.0)
    except (KeyError, ValueError) as exc:
        raise MapFormatError(f"experience-map state is incomplete or malformed: {exc}") from None
    if e and (ends.min() < 0 or ends.max() >= n or np.any(ends[:, 0] == ends[:, 1])):
        raise MapFormatError("experience-map state has links to missing experiences or self-links")
    try:
        out.update({k: int(scalars[k]) for k in _INT_SCALARS})
        out.update({k: float(scalars[k]) for k in _FLOAT_SCALARS})
    except (TypeError, ValueError) as exc:
        raise MapFormatError(f"experience-map state has a malformed scalar: {exc}") from None
    if not all(-1 <= out[k] < n for k in _INT_SCALARS):
        raise MapFormatError("experience-map state has a current/previous id out of range")
    s, d = ends[:, 0].tolist(), ends[:, 1].tolist()
    if len(set(zip(s, d))) != e:
        raise MapFormatError(
            "experience-map state links a pair of experiences twice; keep one link per pair"
        )
    out["relax_cursor"] = int(state.get("relax_cursor", 0))
    return out
