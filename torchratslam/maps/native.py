"""The native on-disk format of a map: save, load, recover an interrupted save.

Native format (version 1): a directory holding ``state.npz`` (``np.savez``, read back
with ``allow_pickle=False``) and ``state.json`` (format name, version, the shape and
dtype of every array, the flat config, the scalars). It is written atomically: into a
temporary directory beside the target, synced, then renamed over it, so a crash never
leaves a half-written map. Loading checks the version, the keys, every shape and
dtype, NaN/inf values, id ranges and (with
:func:`~torchratslam.maps.compat.check_compatible`) that the map was made with the same
pose-cell dimensions and template size as the configuration.

Example:
    >>> from torchratslam.maps.native import load_state, save_map  # doctest: +SKIP
    >>> save_map(stored, "out/run1/state")  # doctest: +SKIP
    >>> stored = load_state("out/run1")  # the run's OUT dir works too  # doctest: +SKIP
"""

from __future__ import annotations

import json
import logging
import math
import struct
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from ratslam_graph.atomic import recover_directory, write_directory_atomically
from torchratslam.errors import InputError, MapFormatError
from torchratslam.maps.compat import check_compatible
from torchratslam.maps.state import ARRAY_FIELDS, INT_FIELDS, MapState

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "HISTORY_NPZ",
    "STATE_JSON",
    "STATE_NPZ",
    "load_map",
    "load_state",
    "read_map_info",
    "recover_save",
    "resolve_native",
    "save_map",
]

log = logging.getLogger(__name__)

FORMAT_NAME = "torchratslam-map"
FORMAT_VERSION = 1
STATE_NPZ = "state.npz"
STATE_JSON = "state.json"
HISTORY_NPZ = "history.npz"


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"cannot store {type(value).__name__} in state.json")


def save_map(
    state: MapState,
    directory: str | Path,
    *,
    info: dict[str, Any] | None = None,
    extra_files: dict[str, Any] | None = None,
) -> Path:
    """Write ``state`` to ``directory`` (native format), atomically.

    The files are written into a temporary directory beside the target, synced, then
    swapped with the old one in one atomic step where the platform allows it
    (:func:`ratslam_graph.atomic.write_directory_atomically`): at every instant
    the target holds a complete map, the old or the new. An existing saved map at the
    target is replaced; an existing directory holding anything else is refused.

    Args:
        state: the map.
        directory: the target directory.
        info: JSON-able facts about the run that made the map, stored in state.json
            under ``"run"`` (e.g. ``{"partial": True, "stopped_at_frame": 120}``) and
            read back with :func:`read_map_info`; not part of the map itself.
        extra_files: more files written in the same atomic step (name -> writer of an
            open binary file); only ``history.npz`` (a run's per-frame history, which
            ``torchratslam run --resume`` reads) is allowed.

    Returns:
        The directory written.

    Raises:
        InputError: the target exists and is not a saved map (nothing is touched).
        MapFormatError: the state does not validate (nothing is written).
    """
    target = Path(directory)
    state = state.validate(source="map to save")
    if target.exists():
        if not target.is_dir():
            raise InputError(f"{target} exists and is not a directory; choose another path")
        found = {p.name for p in target.iterdir()}
        own = {STATE_NPZ, STATE_JSON, HISTORY_NPZ}
        if found - own:
            raise InputError(
                f"{target} exists and holds files other than a saved map "
                f"({', '.join(sorted(found - own)[:3])}); refusing to "
                "overwrite it: choose an empty or new directory"
            )
    extra_files = dict(extra_files or {})
    if set(extra_files) - {HISTORY_NPZ}:
        raise InputError(f"save_map: extra files may only be {HISTORY_NPZ}")
    target.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, Any] = state.arrays()
    meta = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "arrays": {k: {"shape": list(v.shape), "dtype": str(v.dtype)} for k, v in arrays.items()},
        "config": state.config,
        "ids": {k: int(getattr(state, k)) for k in INT_FIELDS},
        "scalars": state.scalars,
        "counts": state.summary(),
    }
    if info:
        meta["run"] = info

    def write_json(fh) -> None:
        fh.write(json.dumps(meta, indent=1, default=_json_default).encode())

    files = {STATE_NPZ: lambda fh: np.savez(fh, **arrays), **extra_files, STATE_JSON: write_json}
    return write_directory_atomically(target, files)


def _read_npz(path: Path) -> dict[str, np.ndarray]:
    """The arrays of ``path`` (an ``np.savez`` file), refusing pickles, and refusing any
    member whose header declares more data than the member holds before allocating it."""
    out: dict[str, np.ndarray] = {}
    fmt = np.lib.format
    with zipfile.ZipFile(path) as zf:
        for info in zf.infolist():
            name = info.filename
            if not name.endswith(".npy") or name[:-4] in out:
                raise ValueError(f"unexpected member {name!r}")
            with zf.open(info) as fh:
                version = fmt.read_magic(fh)
                if version == (1, 0):
                    shape, _, dtype = fmt.read_array_header_1_0(fh)
                else:
                    shape, _, dtype = fmt.read_array_header_2_0(fh)
                if dtype.hasobject:
                    raise ValueError(f"member {name!r} holds Python objects")
                need = math.prod(int(s) for s in shape) * dtype.itemsize
                if need > info.file_size:
                    raise ValueError(
                        f"member {name!r} declares shape {shape} ({need} bytes) but holds "
                        f"{info.file_size} bytes"
                    )
            with zf.open(info) as fh:
                out[name[:-4]] = fmt.read_array(fh, allow_pickle=False)
    return out


def read_map_info(directory: str | Path) -> dict[str, Any]:
    """The ``"run"`` facts saved with a native map (see :func:`save_map`'s ``info``):
    ``{}`` when there are none.

    Raises:
        InputError: no saved map at ``directory``.
        MapFormatError: state.json is not valid JSON.
    """
    p = Path(directory)
    native = resolve_native(p) if p.is_dir() else None
    if native is None:
        raise InputError(f"{p} holds no saved map ({STATE_JSON} not found)")
    try:
        meta = json.loads((native / STATE_JSON).read_text())
    except (OSError, ValueError) as exc:
        raise MapFormatError(f"{native / STATE_JSON} cannot be read ({exc})") from None
    run = meta.get("run") if isinstance(meta, dict) else None
    return dict(run) if isinstance(run, dict) else {}


def load_map(directory: str | Path) -> MapState:
    """Read and validate a native saved map directory (``state.npz`` + ``state.json``).

    Raises:
        InputError: the directory or one of its files does not exist.
        MapFormatError: wrong format or version, missing or extra keys, shapes or dtypes
            that disagree with state.json, NaN/inf, ids out of range, truncated files.
    """
    d = Path(directory)
    src = str(d)
    for name in (STATE_JSON, STATE_NPZ):
        if not (d / name).is_file():
            raise InputError(f"{d / name} not found: {src} is not a saved torchratslam map")
    try:
        meta = json.loads((d / STATE_JSON).read_text())
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise MapFormatError(
            f"{d / STATE_JSON} is not valid JSON ({exc}); the file is corrupt or truncated"
        ) from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise MapFormatError(
            f"{d / STATE_JSON}: not a {FORMAT_NAME} file (format "
            f"{meta.get('format') if isinstance(meta, dict) else None!r})"
        )
    version = meta.get("version")
    if not isinstance(version, int) or isinstance(version, bool):
        raise MapFormatError(
            f"{d / STATE_JSON}: format version {version!r} is not an integer; the file is "
            "corrupt or was edited by hand"
        )
    if version != FORMAT_VERSION:
        hint = "upgrade torchratslam" if version > FORMAT_VERSION else "re-save the map"
        raise MapFormatError(
            f"{src}: map format version {version!r} is not supported (this "
            f"torchratslam reads version {FORMAT_VERSION}); {hint}"
        )
    for key in ("arrays", "config", "ids", "scalars"):
        if not isinstance(meta.get(key), dict):
            raise MapFormatError(f"{d / STATE_JSON}: missing or malformed {key!r} section")
    declared: dict[str, Any] = meta["arrays"]
    for k, spec in declared.items():
        shape = spec.get("shape") if isinstance(spec, dict) else None
        if (
            not isinstance(spec, dict)
            or not isinstance(shape, list)
            or not all(isinstance(v, int) and not isinstance(v, bool) for v in shape)
            or not isinstance(spec.get("dtype"), str)
        ):
            raise MapFormatError(
                f"{d / STATE_JSON}: array entry {k!r} is not a mapping with a shape (a list "
                "of integers) and a dtype"
            )
    for k, v in meta["config"].items():
        if not isinstance(v, (str, int, float, bool)) and v is not None:
            raise MapFormatError(f"{d / STATE_JSON}: config key {k!r} has a {type(v).__name__}")
    for k in ("pc_dim_xy", "pc_dim_th", "template_x_size", "template_y_size"):
        v = meta["config"].get(k, 1)
        if not isinstance(v, int) or isinstance(v, bool) or v <= 0:
            raise MapFormatError(f"{d / STATE_JSON}: config {k} = {v!r} is not a positive integer")
    for k in ("pc_dim_x", "pc_dim_y"):  # 0 (or absent, an older save): pc_dim_xy
        v = meta["config"].get(k, 0)
        if not isinstance(v, int) or isinstance(v, bool) or v < 0:
            raise MapFormatError(
                f"{d / STATE_JSON}: config {k} = {v!r} is not a non-negative integer"
            )
    try:
        arrays: dict[str, Any] = _read_npz(d / STATE_NPZ)
        names = set(arrays)
        if names != set(declared):
            missing, extra = set(declared) - names, names - set(declared)
            raise MapFormatError(
                f"{src}: state.npz and state.json disagree (missing arrays: "
                f"{sorted(missing)}, undeclared: {sorted(extra)})"
            )
    except MapFormatError:
        raise
    except (
        zipfile.BadZipFile,
        zlib.error,
        struct.error,
        EOFError,
        OSError,
        ValueError,
        KeyError,
        TypeError,
        NotImplementedError,  # a member with an unknown compression method
        RuntimeError,  # an "encrypted" member
    ) as exc:
        raise MapFormatError(
            f"{d / STATE_NPZ} cannot be read ({type(exc).__name__}: {exc}); "
            "the file is corrupt or truncated"
        ) from None
    for k, a in arrays.items():
        spec = declared[k]
        if list(a.shape) != list(spec.get("shape", [])) or str(a.dtype) != spec.get("dtype"):
            raise MapFormatError(
                f"{src}: array {k!r} is {a.dtype}{list(a.shape)} but state.json "
                f"declares {spec.get('dtype')}{spec.get('shape')}"
            )
    absent = [k for k in ARRAY_FIELDS if k not in arrays]
    if absent:
        raise MapFormatError(f"{src}: required arrays missing: {', '.join(absent)}")
    ids = meta["ids"]
    for k in INT_FIELDS:
        if not isinstance(ids.get(k), int):
            raise MapFormatError(f"{d / STATE_JSON}: id {k!r} missing or not an integer")
    state = MapState(
        config=meta["config"],
        **{k: arrays[k] for k in ARRAY_FIELDS},
        **{k: ids[k] for k in INT_FIELDS},
        extra={k.removeprefix("extra."): v for k, v in arrays.items() if k.startswith("extra.")},
        scalars=meta["scalars"],
    )
    return state.validate(source=src)


def resolve_native(path: Path) -> Path | None:
    """The directory holding the native map at ``path`` (itself or its ``state/``), or
    None."""
    if (path / STATE_JSON).is_file():
        return path
    if (path / "state" / STATE_JSON).is_file():
        return path / "state"
    return None


def _complete(d: Path) -> bool:
    try:
        load_map(d)
    except (InputError, MapFormatError):
        return False
    return True


def recover_save(p: Path) -> None:
    """Put back a map an interrupted save left beside its target (``.state.new-*`` or
    ``.state.old-*``), saying so; ``p`` is the map directory or a run's OUT. The loaders
    call it first."""
    for target in (p, p / "state") if p.is_dir() else (p,):
        if target.exists() or target.name == "":
            continue
        back = recover_directory(target, _complete)
        if back is not None:
            log.warning(
                "%s was missing after an interrupted save; recovered it from %s", target, back
            )


def load_state(path: str | Path, config: Any = None) -> MapState:
    """Load a native map: a saved state directory or a run's OUT directory
    (``OUT/state/``). :func:`torchratslam.maps.io.load_state` also reads the reference
    implementation's text format.

    Args:
        path: the directory.
        config: a ``RatSLAMConfig`` (or flat dict); when given, the map's
            compatibility with it is checked.

    Raises:
        InputError: nothing loadable at ``path``.
        MapFormatError: the map is corrupt or incompatible with ``config``.
    """
    p = Path(path)
    recover_save(p)
    if not p.exists():
        raise InputError(
            f"map {str(p)!r} not found: give a saved state directory, a run's OUT "
            "directory, or a reference-format map directory"
        )
    native = resolve_native(p) if p.is_dir() else None
    if native is None:
        raise InputError(
            f"{p} holds no saved map: expected {STATE_JSON} + {STATE_NPZ} or a state/ "
            "subdirectory (a run's OUT dir); reference-format maps load with "
            "torchratslam.maps.io.load_state"
        )
    state = load_map(native)
    if config is not None:
        check_compatible(state, config, what=f"map {str(p)!r}")
    state.name = str(p)
    return state
