"""Loading a map in any supported format: one entry point for every command.

* a native saved map (``state.json`` + ``state.npz``) or a run's OUT directory
  (``OUT/state/``): :func:`torchratslam.maps.state.load_state`;
* a save of the multisession paper's implementation (``experiences.txt`` and friends):
  :func:`torchratslam.maps.reference_format.read_reference`.

This module sits above both (``state`` never imports ``reference_format``).

Example:
    >>> from torchratslam.maps.io import load_state, map_format  # doctest: +SKIP
    >>> map_format("their_map/")  # doctest: +SKIP
    'reference'
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from torchratslam.graph.errors import InputError
from torchratslam.maps import state as _state
from torchratslam.maps.reference_format import is_reference_map, read_reference

__all__ = ["load_state", "map_format"]


def map_format(path: str | Path) -> str | None:
    """``"native"`` (a saved map or a run's OUT dir), ``"reference"`` (the authors'
    text format) or None (nothing loadable at ``path``)."""
    p = Path(path)
    if not p.is_dir():
        return None
    if (p / _state.STATE_JSON).is_file() or (p / "state" / _state.STATE_JSON).is_file():
        return "native"
    if is_reference_map(p):
        return "reference"
    return None


def load_state(path: str | Path, config: Any = None) -> _state.MapState:
    """Load a map from a native saved map, a run's OUT directory, or a reference-format
    save directory.

    Args:
        path: the directory.
        config: a ``RatSLAMConfig`` (or flat dict). Shapes the templates of a
            reference-format map (that format stores only their total size); when given,
            the map's compatibility with it is checked.

    Raises:
        InputError: nothing loadable at ``path``.
        MapFormatError: the map is corrupt or incompatible with ``config``.
    """
    p = Path(path)
    kind = map_format(p)
    if kind == "native":
        return _state.load_state(p, config)
    if kind is None:
        if not p.exists():
            raise InputError(
                f"map {str(p)!r} not found: give a saved state directory, a run's OUT "
                "directory, or a reference-format map directory"
            )
        raise InputError(
            f"{p} holds no saved map: expected {_state.STATE_JSON} + {_state.STATE_NPZ}, a "
            "state/ subdirectory (a run's OUT dir), or the reference format's "
            "experiences.txt and posecellexperiences.txt"
        )
    state = read_reference(p, config)
    if config is not None:
        _state.check_compatible(state, config, what=f"map {str(p)!r}")
    state.name = str(p)
    return state
