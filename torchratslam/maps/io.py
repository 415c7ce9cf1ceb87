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

from torchratslam.errors import InputError, MapFormatError, RatSLAMError, option
from torchratslam.maps import native
from torchratslam.maps.compat import check_compatible
from torchratslam.maps.reference_format import (
    EXP_EXTRAS,
    TAIL,
    compare_texts,
    is_reference_map,
    read_reference,
    read_texts,
    reference_texts,
    write_reference,
)
from torchratslam.maps.state import INT_FIELDS, MISSING_KEY, MapState

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


def _first_difference(x: np.ndarray, y: np.ndarray) -> str:
    """``" (first at [3]: 0.5 -> 0.499)"`` for two arrays of one shape, or their shapes."""
    if x.shape != y.shape:
        return f" (shape {x.shape} -> {y.shape})"
    if x.size == 0:
        return ""
    idx = tuple(int(i) for i in np.argwhere(x != y)[0]) if (x != y).any() else ()
    if not idx:
        return f" (dtype {x.dtype} -> {y.dtype})"
    return f" (first at {list(idx)}: {x[idx]!r} -> {y[idx]!r})"


def _array_changes(
    a: dict[str, np.ndarray], b: dict[str, np.ndarray], *, dtypes: bool = True
) -> list[str]:
    out = []
    for name in sorted(set(a) | set(b)):
        x, y = a.get(name), b.get(name)
        if x is None or y is None:
            out.append(f"{name} ({'dropped' if y is None else 'added'})")
        elif x.shape != y.shape or (dtypes and x.dtype != y.dtype) or not np.array_equal(x, y):
            out.append(name + _first_difference(np.asarray(x), np.asarray(y)))
    return out


def _value_changes(a: dict[str, Any], b: dict[str, Any], what: str = "") -> list[str]:
    prefix = f"{what} " if what else ""
    return [
        f"{prefix}{k} ({a.get(k)!r} -> {b.get(k)!r})"
        for k in sorted(set(a) | set(b))
        if a.get(k) != b.get(k)
    ]


def _differences(a: MapState, b: MapState, *, reference: bool) -> list[str]:
    """Every value of ``a`` that ``b`` does not hold the same (for the reference
    format: every value that format holds), each with its first difference."""
    if not reference:
        out = _array_changes(a.arrays(), b.arrays())
        out += _value_changes(
            {k: getattr(a, k) for k in INT_FIELDS}, {k: getattr(b, k) for k in INT_FIELDS}
        )
        out += _value_changes(a.scalars, b.scalars, "scalar")
        return out + _value_changes(a.config, b.config, "config")
    n_a, n_b = a.n_templates, b.n_templates
    held = {k: np.asarray(getattr(a, k)) for k in _HELD}
    back = {k: np.asarray(getattr(b, k)) for k in _HELD}
    # the format stores a template's values, not its (Y, X) split, and writes float64
    for arrays, n in ((held, n_a), (back, n_b)):
        t = arrays["templates"]
        arrays["templates"] = t.reshape(n, int(np.prod(t.shape[1:]))).astype(np.float64)
    held.update({f"extra {k}": np.asarray(v) for k, v in a.extra.items() if k in _REF_EXTRAS})
    back.update({f"extra {k}": np.asarray(v) for k, v in b.extra.items() if k in _REF_EXTRAS})
    out = _array_changes(held, back, dtypes=False)
    out += _value_changes({k: getattr(a, k) for k in _IDS}, {k: getattr(b, k) for k in _IDS})
    kept = (MISSING_KEY, TAIL)
    ref_a = {k: v for k, v in a.scalars.items() if k.startswith(kept)}
    ref_b = {k: v for k, v in b.scalars.items() if k.startswith(kept)}
    return out + _value_changes(ref_a, ref_b, "scalar")


def _shown(exc: BaseException, work: Path, dst: Path) -> str:
    """The message of ``exc`` naming ``dst`` where it names the temporary ``work``."""
    return str(exc).replace(str(work), str(dst))


def _listed(items: list[str], limit: int = 5) -> str:
    more = f"; and {len(items) - limit} more" if len(items) > limit else ""
    return "; ".join(items[:limit]) + more


def convert_map(
    source: str | Path, target: str | Path, *, to: str, config: Any = None
) -> dict[str, Any]:
    """Convert a saved map between the native and the reference format, and check that
    nothing the target format can hold is lost.

    The map is written into a temporary directory beside ``target``, read back and
    compared field by field, and only then moved to ``target`` (which must not exist, or
    be empty). A reference-format source is also compared, field by field, with the
    files the result gives in that format: a template's experience list or an
    experience's link list that the source held stale (their merge leaves some) comes
    back derived from the map's ids, and is listed under ``changed``; any other value
    that differs is an error.

    Args:
        source: any map :func:`load_state` reads.
        target: the directory to create.
        to: ``"native"`` or ``"reference"``.
        config: a ``RatSLAMConfig`` or flat dict (shapes a reference map's templates).

    Returns:
        ``source``, ``source_format``, ``target``, ``format``, the counts,
        ``templates_missing`` (the file the source's templates were missing with, or
        None), ``dropped``
        (what the target format cannot hold; empty for native), ``changed`` (each
        value written differently from the source, with both values) and ``checked``
        (the fields compared after reading back).

    Raises:
        InputError: ``to`` is unknown, ``target`` exists and is not an empty directory,
            or cannot be written.
        MapFormatError: a value the target format holds did not survive the round trip
            (naming each, with its values); nothing is written.
    """
    import shutil
    import tempfile

    if to not in ("native", "reference"):
        raise InputError(f"{option('--to', 'to')} must be 'native' or 'reference', got {to!r}")
    src, dst = Path(source), Path(target)
    rs, rd = src.resolve(), dst.resolve()
    if rd == rs or rs in rd.parents or rd in rs.parents:
        raise InputError(
            f"{dst} is (or lies in, or holds) the map {src} being converted; convert never "
            "rewrites its input: choose another target"
        )
    if dst.exists() and (not dst.is_dir() or any(dst.iterdir())):
        raise InputError(f"{dst} exists and is not empty; convert writes a new directory")
    state = load_state(src, config)
    source_format = map_format(src)
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{dst.name}.convert-", dir=dst.parent))
    work = tmp / "map"
    try:
        if to == "reference":
            write_reference(state, work)
            cfg = state.config if state.config else config
            back = read_reference(work, cfg, shown_as=dst)
            written = read_texts(work)
        else:
            native.save_map(state, work)
            back = native.load_map(work)
            written = reference_texts(back)
        bad = _differences(state, back, reference=to == "reference")
        changed: list[str] = []
        if source_format == "reference":
            for change in compare_texts(read_texts(src), written):
                (changed if change.derived else bad).append(change.text)
        if bad:
            raise MapFormatError(
                f"converting {src} to the {to} format would change {_listed(bad)}; "
                "nothing was written"
            )
        if dst.exists():
            dst.rmdir()  # empty, checked above
        work.rename(dst)
    except OSError as exc:
        raise InputError(
            f"{dst}: cannot be written ({exc.strerror or _shown(exc, work, dst)})"
        ) from None
    except RatSLAMError as exc:
        raise type(exc)(_shown(exc, work, dst)) from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {
        "source": str(src),
        "source_format": source_format,
        "target": str(dst),
        "format": to,
        **state.summary(),
        "templates_missing": state.scalars.get(MISSING_KEY) or None,
        "dropped": reference_losses(state) if to == "reference" else [],
        "changed": changed,
        "checked": list(_HELD + _IDS) + sorted(_REF_EXTRAS) if to == "reference" else ["all"],
    }
