"""Loading a map in any supported format: one entry point for every command.

* a native saved map (``state.json`` + ``state.npz``) or a run's OUT directory
  (``OUT/state/``): :func:`torchratslam.maps.native.load_state`;
* a save of the multisession paper's implementation (``experiences.txt`` and friends):
  :func:`torchratslam.maps.reference_format.read_reference`.

This module sits above both (``native`` never imports ``reference_format``).

Example:
    >>> from torchratslam.maps.io import load_state, map_format  # doctest: +SKIP
    >>> map_format("their_map/")  # doctest: +SKIP
    'reference'
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from torchratslam.errors import InputError, MapFormatError
from torchratslam.maps import native
from torchratslam.maps.compat import check_compatible
from torchratslam.maps.reference_format import (
    EXP_EXTRAS,
    TAIL,
    is_reference_map,
    read_reference,
    write_reference,
)
from torchratslam.maps.state import MISSING_KEY, MapState

__all__ = ["convert_map", "load_state", "map_format", "reference_losses"]


def map_format(path: str | Path) -> str | None:
    """``"native"`` (a saved map or a run's OUT dir), ``"reference"`` (the authors'
    text format) or None (nothing loadable at ``path``)."""
    p = Path(path)
    if not p.is_dir():
        return None
    if (p / native.STATE_JSON).is_file() or (p / "state" / native.STATE_JSON).is_file():
        return "native"
    if is_reference_map(p):
        return "reference"
    return None


def load_state(path: str | Path, config: Any = None) -> MapState:
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
    native.recover_save(p)  # a native map an interrupted save left beside its place
    kind = map_format(p)
    if kind == "native":
        return native.load_state(p, config)
    if kind is None:
        if not p.exists():
            raise InputError(
                f"map {str(p)!r} not found: give a saved state directory, a run's OUT "
                "directory, or a reference-format map directory"
            )
        raise InputError(
            f"{p} holds no saved map: expected {native.STATE_JSON} + {native.STATE_NPZ}, a "
            "state/ subdirectory (a run's OUT dir), or the reference format's "
            "experiences.txt and posecellexperiences.txt"
        )
    state = read_reference(p, config)
    if config is not None:
        check_compatible(state, config, what=f"map {str(p)!r}")
    state.name = str(p)
    return state


# ------------------------------------------------------------------ conversion
_HELD = (  # MapState fields the reference format holds
    "templates",
    "template_mean",
    "template_pc",
    "template_decay",
    "exp_pose",
    "exp_pc",
    "exp_template",
    "link_from",
    "link_to",
    "link_d",
    "link_heading",
    "link_facing",
    "link_dt",
)
_IDS = ("current_vt", "prev_vt", "current_exp", "prev_exp")
_REF_EXTRAS = {"ref.goal_list", "exp:pc_template", *(k for k, _ in EXP_EXTRAS)}
_REF_SCALARS = ("imported_from", MISSING_KEY, TAIL)


def reference_losses(state: MapState) -> list[str]:
    """What of ``state`` the reference format cannot hold (empty: nothing is lost)."""
    out = []
    if state.activity.size:
        out.append(f"pose-cell activity {state.activity.shape}")
    for name, none in (("template_frame", -1), ("exp_frame", -1), ("exp_t", 0)):
        a = getattr(state, name)
        if a.size and (a != none).any():
            out.append(f"{name} ({a.size} values)")
    if state.frame_index:
        out.append(f"frame_index = {state.frame_index}")
    if state.templates.dtype != np.float64:
        out.append(f"templates dtype {state.templates.dtype} (written as float64, values exact)")
    cfg = sorted(set(state.config) - {"template_x_size", "template_y_size"})
    if cfg:
        out.append(f"config ({len(cfg)} keys; give --config when reading it back)")
    if state.scalars.get("imported_from") != "reference" and state.templates.shape[1] > 1:
        out.append(f"template shape {state.templates.shape[1:]} (only their size is stored)")
    extra = sorted(set(state.extra) - _REF_EXTRAS)
    if extra:
        out.append(f"module extras {', '.join(extra)}")
    scalars = sorted(k for k in state.scalars if not k.startswith(_REF_SCALARS))
    if scalars:
        out.append(f"module scalars {', '.join(scalars)}")
    return out


def _differences(a: MapState, b: MapState, *, reference: bool) -> list[str]:
    if not reference:
        return [] if a.equals(b) else ["the native map read back differs from the source"]
    out = []
    for name in _HELD:
        x, y = np.asarray(getattr(a, name)), np.asarray(getattr(b, name))
        if x.size != y.size or not np.array_equal(x.reshape(-1), y.reshape(-1)):
            out.append(name)
    for name in _IDS:
        i, j = getattr(a, name), getattr(b, name)
        if i != j:
            out.append(f"{name} ({i} -> {j})")
    for key in sorted(_REF_EXTRAS):
        ea, eb = a.extra.get(key), b.extra.get(key)
        if ea is None or eb is None:
            if (ea is None) != (eb is None):
                out.append(f"extra {key}")
        elif not np.array_equal(ea, eb):
            out.append(f"extra {key}")
    return out


def convert_map(
    source: str | Path, target: str | Path, *, to: str, config: Any = None
) -> dict[str, Any]:
    """Convert a saved map between the native and the reference format, and check that
    nothing the target format can hold is lost.

    The map is written into a temporary directory beside ``target``, read back and
    compared, and only then moved to ``target`` (which must not exist, or be empty).

    Args:
        source: any map :func:`load_state` reads.
        target: the directory to create.
        to: ``"native"`` or ``"reference"``.
        config: a ``RatSLAMConfig`` or flat dict (shapes a reference map's templates).

    Returns:
        ``source``, ``source_format``, ``target``, ``format``, the counts, ``dropped``
        (what the target format cannot hold; empty for native) and ``checked`` (the
        fields compared after reading back).

    Raises:
        InputError: ``to`` is unknown, ``target`` exists and is not an empty directory.
        MapFormatError: a value the target format holds did not survive the round trip.
    """
    import shutil
    import tempfile

    if to not in ("native", "reference"):
        raise InputError(f"--to must be 'native' or 'reference', got {to!r}")
    src, dst = Path(source), Path(target)
    if dst.exists() and (not dst.is_dir() or any(dst.iterdir())):
        raise InputError(f"{dst} exists and is not empty; convert writes a new directory")
    state = load_state(src, config)
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{dst.name}.convert-", dir=dst.parent))
    try:
        work = tmp / "map"
        if to == "reference":
            write_reference(state, work)
            back = read_reference(work, state.config if state.config else config)
        else:
            native.save_map(state, work)
            back = native.load_map(work)
        bad = _differences(state, back, reference=to == "reference")
        if bad:
            raise MapFormatError(
                f"converting {src} to the {to} format would change {', '.join(bad)}; "
                "nothing was written"
            )
        if dst.exists():
            dst.rmdir()  # empty, checked above
        work.rename(dst)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {
        "source": str(src),
        "source_format": map_format(src),
        "target": str(dst),
        "format": to,
        **state.summary(),
        "dropped": reference_losses(state) if to == "reference" else [],
        "checked": list(_HELD + _IDS) + sorted(_REF_EXTRAS) if to == "reference" else ["all"],
    }
