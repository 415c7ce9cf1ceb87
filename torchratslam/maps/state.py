"""The complete state of a RatSLAM map, its versioned on-disk format, and loading with checks.

A :class:`MapState` is a plain dataclass of numpy arrays and Python scalars holding
everything a RatSLAM structure is made of (the multisession paper, Fig. 2):

* local view cells: the templates ``(N, Y, X)`` with their means and creation frames;
* pose cells: each template's pose-cell coordinates and decay, each experience's
  pose-cell coordinates and template id, the activity ``(TH, Y, X)``;
* experience map: experience poses ``(M, 3)`` [x, y, th], creation frames and times,
  links (from, to, d, heading, facing, dt);
* current and previous template and experience ids, the frame counter, the flat config;
* ``extra``: module-specific arrays that a module's ``get_state`` holds beyond the
  above (keys ``"template:..."``, ``"exp:..."``, ``"link:..."`` are per-entity arrays
  whose first axis is N, M or L and that merges concatenate; other keys are the live
  session's own state and merges take them from the partial map);
* ``scalars``: module-specific Python scalars (merges take them from the partial map).

Native format (version 1): a directory holding ``state.npz`` (``np.savez``, read back
with ``allow_pickle=False``) and ``state.json`` (format name, version, the shape and
dtype of every array, the flat config, the scalars). It is written atomically: into a
temporary directory beside the target, synced, then renamed over it, so a crash never
leaves a half-written map. Loading checks the version, the keys, every shape and
dtype, NaN/inf values, id ranges and (with :func:`check_compatible`) that the map was
made with the same pose-cell dimensions and template size as the configuration.

Example:
    >>> from torchratslam.maps.state import load_state, save_state  # doctest: +SKIP
    >>> save_state(slam, "out/run1/state")  # doctest: +SKIP
    >>> stored = load_state("out/run1")  # the run's OUT dir works too  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import re
import struct
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from ratslam_graph.atomic import recover_directory, write_directory_atomically
from ratslam_graph.errors import InputError, MapFormatError

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "MapState",
    "check_compatible",
    "load_map",
    "load_state",
    "read_map_info",
    "recover_save",
    "save_map",
    "save_state",
]

FORMAT_NAME = "torchratslam-map"
FORMAT_VERSION = 1
STATE_NPZ = "state.npz"
STATE_JSON = "state.json"
MISSING_KEY = "missing_files"
"""Scalar key: the files a map was read without (a reference-format save lacking
``localviewcells.txt`` has zero templates in their place; see :func:`require_templates`)."""
HISTORY_NPZ = "history.npz"

# name -> (kind, ndim) ; kind "f" float, "i" integer. Shapes are cross-checked below.
ARRAY_FIELDS: dict[str, tuple[str, int]] = {
    "templates": ("f", 3),
    "template_mean": ("f", 1),
    "template_frame": ("i", 1),
    "template_pc": ("f", 2),
    "template_decay": ("f", 1),
    "exp_pose": ("f", 2),
    "exp_pc": ("f", 2),
    "exp_template": ("i", 1),
    "exp_frame": ("i", 1),
    "exp_t": ("f", 1),
    "link_from": ("i", 1),
    "link_to": ("i", 1),
    "link_d": ("f", 1),
    "link_heading": ("f", 1),
    "link_facing": ("f", 1),
    "link_dt": ("f", 1),
    "activity": ("f", 3),
}
INT_FIELDS = ("current_vt", "prev_vt", "current_exp", "prev_exp", "frame_index")
PER_ENTITY = {"template": "templates", "exp": "exp_pose", "link": "link_from"}
_KEY_RE = re.compile(r"^[A-Za-z0-9_.:\-]+$")


def _f(a: Any, dtype: Any = np.float64) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=dtype))


def _i(a: Any) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.int64))


@dataclass
class MapState:
    """Everything a RatSLAM map is made of, as numpy arrays and Python scalars.

    Ids are row indices: template ``i`` is ``templates[i]``, experience ``j`` is
    ``exp_pose[j]``. Pose-cell coordinates are in cells ``(x, y, th)``.

    Attributes:
        config: the flat config the map was made with (``RatSLAMConfig.to_flat()``).
        templates: ``(N, Y, X)`` visual templates (float32 or float64).
        template_mean: ``(N,)`` mean of each template.
        template_frame: ``(N,)`` frame at which each template was learnt (-1: unknown).
        template_pc: ``(N, 3)`` pose-cell coordinates (x, y, th cells) of each template.
        template_decay: ``(N,)`` decay of each template's injection.
        exp_pose: ``(M, 3)`` experience map poses [x m, y m, th rad].
        exp_pc: ``(M, 3)`` pose-cell coordinates of each experience.
        exp_template: ``(M,)`` template id of each experience.
        exp_frame: ``(M,)`` frame at which each experience was created (-1: unknown).
        exp_t: ``(M,)`` time (s) at which each experience was created.
        link_from, link_to: ``(L,)`` experience ids of each link.
        link_d, link_heading, link_facing: ``(L,)`` link geometry relative to the
            source experience (m, rad, rad).
        link_dt: ``(L,)`` link time (s).
        activity: ``(TH, Y, X)`` pose-cell activity, or an empty ``(0, 0, 0)`` array
            when unknown (maps imported from the reference format).
        current_vt, prev_vt, current_exp, prev_exp: current/previous ids (-1: none).
        frame_index: frames processed so far in the session that made the map.
        extra: module-specific arrays (see the module docstring).
        scalars: module-specific Python scalars (int, float, bool, str).
        name: where the map was loaded from (reports only; not saved, not compared).
    """

    config: dict[str, Any]
    templates: np.ndarray
    template_mean: np.ndarray
    template_frame: np.ndarray
    template_pc: np.ndarray
    template_decay: np.ndarray
    exp_pose: np.ndarray
    exp_pc: np.ndarray
    exp_template: np.ndarray
    exp_frame: np.ndarray
    exp_t: np.ndarray
    link_from: np.ndarray
    link_to: np.ndarray
    link_d: np.ndarray
    link_heading: np.ndarray
    link_facing: np.ndarray
    link_dt: np.ndarray
    activity: np.ndarray
    current_vt: int = -1
    prev_vt: int = -1
    current_exp: int = -1
    prev_exp: int = -1
    frame_index: int = 0
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    scalars: dict[str, Any] = field(default_factory=dict)
    name: str = field(default="", compare=False)

    # ------------------------------------------------------------------ sizes
    @property
    def n_templates(self) -> int:
        return int(self.templates.shape[0])

    @property
    def n_experiences(self) -> int:
        return int(self.exp_pose.shape[0])

    @property
    def n_links(self) -> int:
        return int(self.link_from.shape[0])

    @property
    def pc_dims(self) -> tuple[int, int, int]:
        """(pc_dim_xy, pc_dim_xy, pc_dim_th) from the config: the x, y, th ring sizes."""
        xy = int(self.config.get("pc_dim_xy", 21))
        return xy, xy, int(self.config.get("pc_dim_th", 36))

    def summary(self) -> dict[str, int]:
        """Counts for reports: templates, experiences, links."""
        return {
            "templates": self.n_templates,
            "experiences": self.n_experiences,
            "links": self.n_links,
        }

    # ------------------------------------------------------------ construction
    @classmethod
    def empty(cls, config: dict[str, Any]) -> MapState:
        """A map with no templates, experiences or links, made with ``config`` (flat)."""
        ty, tx = int(config.get("template_y_size", 1)), int(config.get("template_x_size", 1))
        return cls(
            config=dict(config),
            templates=np.zeros((0, ty, tx)),
            template_mean=np.zeros(0),
            template_frame=np.zeros(0, np.int64),
            template_pc=np.zeros((0, 3)),
            template_decay=np.zeros(0),
            exp_pose=np.zeros((0, 3)),
            exp_pc=np.zeros((0, 3)),
            exp_template=np.zeros(0, np.int64),
            exp_frame=np.zeros(0, np.int64),
            exp_t=np.zeros(0),
            link_from=np.zeros(0, np.int64),
            link_to=np.zeros(0, np.int64),
            link_d=np.zeros(0),
            link_heading=np.zeros(0),
            link_facing=np.zeros(0),
            link_dt=np.zeros(0),
            activity=np.zeros((0, 0, 0)),
        )

    def normalised(self) -> MapState:
        """A copy with canonical dtypes (int64 ids, float64 geometry, contiguous arrays)."""
        out: dict[str, Any] = {}
        for name, (kind, _) in ARRAY_FIELDS.items():
            a = np.asarray(getattr(self, name))
            if kind == "i":
                out[name] = _i(a)
            elif name in ("templates", "activity") and a.dtype in (np.float32, np.float64):
                out[name] = np.ascontiguousarray(a).copy()
            else:
                out[name] = _f(a).copy()
        return dataclasses.replace(
            self,
            config=dict(self.config),
            extra={k: np.ascontiguousarray(v).copy() for k, v in self.extra.items()},
            scalars=dict(self.scalars),
            **cast(dict[str, Any], {k: int(getattr(self, k)) for k in INT_FIELDS}),
            **out,
        )

    def copy(self) -> MapState:
        """A deep copy."""
        return self.normalised()

    def arrays(self) -> dict[str, np.ndarray]:
        """Every array field plus the extras (prefixed ``extra.``), as saved in the npz."""
        out = {name: np.asarray(getattr(self, name)) for name in ARRAY_FIELDS}
        out.update({f"extra.{k}": np.asarray(v) for k, v in self.extra.items()})
        return out

    def equals(self, other: MapState) -> bool:
        """Exact equality of every array (values, dtypes, shapes), scalar and config."""
        a, b = self.arrays(), other.arrays()
        if a.keys() != b.keys():
            return False
        for k in a:
            if a[k].dtype != b[k].dtype or a[k].shape != b[k].shape:
                return False
            if not np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f"):
                return False
        same_ints = all(getattr(self, k) == getattr(other, k) for k in INT_FIELDS)
        return same_ints and self.scalars == other.scalars and self.config == other.config

    # ------------------------------------------------------------- validation
    def validate(self, *, source: str = "map") -> MapState:
        """Check shapes, dtypes, finiteness and id ranges; return ``self``.

        Raises:
            MapFormatError: naming the first problem found and what to do.
        """

        def bad(msg: str) -> MapFormatError:
            return MapFormatError(
                f"{source}: {msg}; the map is corrupt or was not written by "
                "torchratslam (re-save it, or re-run the session)"
            )

        for name, (kind, ndim) in ARRAY_FIELDS.items():
            a = getattr(self, name)
            if not isinstance(a, np.ndarray):
                raise bad(f"field {name!r} is a {type(a).__name__}, expected a numpy array")
            if a.ndim != ndim:
                raise bad(f"array {name!r} has shape {a.shape}, expected {ndim} dimensions")
            if kind == "i" and a.dtype.kind not in "iu":
                raise bad(f"array {name!r} has dtype {a.dtype}, expected integers")
            if kind == "f" and a.dtype.kind != "f":
                raise bad(f"array {name!r} has dtype {a.dtype}, expected floats")
            if kind == "f" and a.size and not np.isfinite(a).all():
                raise bad(f"array {name!r} holds NaN or infinite values")
        n, m, el = self.n_templates, self.n_experiences, self.n_links
        expect = {
            "template_mean": (n,),
            "template_frame": (n,),
            "template_pc": (n, 3),
            "template_decay": (n,),
            "exp_pc": (m, 3),
            "exp_template": (m,),
            "exp_frame": (m,),
            "exp_t": (m,),
            "exp_pose": (m, 3),
            "link_to": (el,),
            "link_d": (el,),
            "link_heading": (el,),
            "link_facing": (el,),
            "link_dt": (el,),
        }
        for name, shape in expect.items():
            if getattr(self, name).shape != shape:
                raise bad(
                    f"array {name!r} has shape {getattr(self, name).shape}, expected "
                    f"{shape} (N={n} templates, M={m} experiences, L={el} links)"
                )
        for key, value in self.extra.items():
            if not isinstance(key, str) or not _KEY_RE.match(key):
                raise bad(f"extra key {key!r} has characters outside [A-Za-z0-9_.:-]")
            value = np.asarray(value)
            if value.dtype == object:
                raise bad(f"extra array {key!r} holds Python objects")
            prefix = key.split(":", 1)[0] if ":" in key else ""
            if prefix in PER_ENTITY:
                size = getattr(self, PER_ENTITY[prefix]).shape[0]
                if value.ndim == 0 or value.shape[0] != size:
                    raise bad(
                        f"per-{prefix} extra {key!r} has shape {value.shape}, expected "
                        f"a first axis of {size}"
                    )
        for key, value in self.scalars.items():
            if not isinstance(value, (bool, int, float, str)) or isinstance(value, np.generic):
                raise bad(f"scalar {key!r} = {value!r} is not a Python int/float/bool/str")
            if isinstance(value, float) and not math.isfinite(value):
                raise bad(f"scalar {key!r} is {value}")
        pcs = self.pc_dims
        if self.activity.size and self.activity.shape != (pcs[2], pcs[1], pcs[0]):
            raise bad(
                f"pose-cell activity has shape {self.activity.shape}, but the map's config "
                f"says (pc_dim_th, pc_dim_xy, pc_dim_xy) = {(pcs[2], pcs[1], pcs[0])}"
            )
        ty = int(self.config.get("template_y_size", int(self.templates.shape[1])))
        tx = int(self.config.get("template_x_size", int(self.templates.shape[2])))
        if self.templates.shape[1:] != (ty, tx):
            raise bad(
                f"templates have shape {self.templates.shape[1:]} (Y, X), but the map's "
                f"config says template_y_size x template_x_size = {(ty, tx)}"
            )
        if n and ((self.exp_template < -1) | (self.exp_template >= n)).any():
            raise bad(f"an experience refers to a template id outside 0..{n - 1}")
        if not n and m and (self.exp_template != -1).any():
            raise bad("experiences refer to templates but the map has none")
        for name in ("link_from", "link_to"):
            ids = getattr(self, name)
            if el and ((ids < 0) | (ids >= m)).any():
                raise bad(f"a link ({name}) refers to an experience id outside 0..{m - 1}")
        if el and (self.link_from == self.link_to).any():
            raise bad("a link joins an experience to itself")
        for name, size in (("current_vt", n), ("prev_vt", n), ("current_exp", m), ("prev_exp", m)):
            v = getattr(self, name)
            ok_type = isinstance(v, (int, np.integer)) and not isinstance(v, bool)
            if not ok_type or not -1 <= v < max(size, 0):
                raise bad(f"{name} = {v!r} is not -1 or an id in 0..{size - 1}")
        return self


def check_compatible(state: MapState, config: Any, *, what: str = "stored map") -> None:
    """Raise :class:`MapFormatError` unless ``state`` can be used with ``config``.

    Maps can only be continued or merged with the same pose-cell network size and the
    same template size: pose-cell coordinates and templates would not line up.

    Args:
        state: the map.
        config: a ``RatSLAMConfig`` or a flat dict.
        what: how to name the map in the message.
    """
    flat = config.to_flat() if hasattr(config, "to_flat") else dict(config)
    problems = []
    for key in ("pc_dim_xy", "pc_dim_th", "template_x_size", "template_y_size"):
        mine, theirs = state.config.get(key), flat.get(key)
        if mine is not None and theirs is not None and int(mine) != int(theirs):
            problems.append(f"{key} = {mine} in the map but {theirs} in the config")
    if problems:
        raise MapFormatError(
            f"{what} is incompatible with the configuration: {'; '.join(problems)}. "
            "Use the config the map was made with (saved in its state.json)."
        )


# ------------------------------------------------------------------- native I/O
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
    native = _resolve_native(p) if p.is_dir() else None
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


# ------------------------------------------------------ pipeline save / load
def _resolve_native(path: Path) -> Path | None:
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
            logging.getLogger(__name__).warning(
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
    native = _resolve_native(p) if p.is_dir() else None
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


def save_state(slam: Any, directory: str | Path) -> Path:
    """Save the complete state of a running ``RatSLAM`` (or ``MultiSessionRatSLAM``)
    to ``directory`` atomically (native format, see :func:`save_map`)."""
    return save_map(state_from_slam(slam), directory)


# ------------------------------------------------- module states <-> MapState
# The pipeline's modules each have get_state()/set_state(); these functions translate
# between their dictionaries and the canonical MapState. Keys a module holds beyond the
# canonical fields are kept in ``extra`` / ``scalars`` under the module's prefix
# (``lv.``, ``pc.``, ``em.``, ``vo.``), per-entity ones under ``template:``, ``exp:``,
# ``link:``, so a save/load round trip gives each module back exactly what it gave.

EM_ACCUM = "em.accum"
"""Extra key: the experience map's odometry accumulated since the current experience,
``[x m, y m, facing rad, time s]`` in the map frame (merges rotate it)."""
PC_BEST = "pc.best"
"""Extra key: the pose cells' last decoded packet centre ``(x, y, th)`` cells (merges move
it with the activity)."""


def _split_extras(prefix: str, d: dict[str, Any], known: set[str], out: MapState) -> None:
    for k, v in d.items():
        if k in known:
            continue
        if v is None:
            out.scalars[f"{prefix}.{k}.none"] = True
        elif isinstance(v, (bool, int, float, str)) and not isinstance(v, np.generic):
            out.scalars[f"{prefix}.{k}"] = v
        elif isinstance(v, np.generic):
            out.scalars[f"{prefix}.{k}"] = v.item()
        else:
            arr = np.asarray(v.detach().cpu().numpy() if hasattr(v, "detach") else v)
            if arr.dtype == object:
                raise MapFormatError(
                    f"module state {prefix}.{k} holds Python objects; "
                    "it cannot be saved without pickle"
                )
            out.extra[f"{prefix}.{k}"] = arr


def _collect(prefix: str, state: MapState) -> dict[str, Any]:
    """The prefix's extras and scalars back as a module-state dict (without the prefix)."""
    out: dict[str, Any] = {}
    p = prefix + "."
    for k, v in state.extra.items():
        if k.startswith(p):
            out[k[len(p) :]] = np.array(v, copy=True)
    for k, v in state.scalars.items():
        if k.startswith(p):
            if k.endswith(".none"):
                out[k[len(p) : -5]] = None
            else:
                out[k[len(p) :]] = v
    return out


def experience_map_state(state: MapState) -> dict[str, Any]:
    """The ``ratslam_graph.experience_map.ExperienceMap.set_state`` dictionary of ``state``."""
    em = _collect("em", state)
    accum = np.asarray(state.extra.get(EM_ACCUM, np.zeros(4)), np.float64)
    n_l = state.n_links
    counts = state.extra.get("link:counts", np.zeros((n_l, 3), np.int64))
    behaviour = state.extra.get("link:behaviour", np.zeros(n_l, np.int64))
    em.pop("accum", None)
    em.update(
        {
            "poses": state.exp_pose.copy(),
            "pc": state.exp_pc.copy(),
            "template_id": state.exp_template.copy(),
            "frame": state.exp_frame.copy(),
            "t": state.exp_t.copy(),
            "link_ends": np.stack([state.link_from, state.link_to], axis=1).reshape(-1, 2),
            "link_values": np.stack(
                [state.link_d, state.link_heading, state.link_facing, state.link_dt], axis=1
            ).reshape(-1, 4),
            "link_counts": np.array(counts, dtype=np.int64, copy=True),
            "link_behaviour": np.array(behaviour, dtype=np.int64, copy=True),
            "current_id": int(state.current_exp),
            "prev_id": int(state.prev_exp),
            "accum_x": float(accum[0]),
            "accum_y": float(accum[1]),
            "accum_facing": float(accum[2]),
            "accum_time": float(accum[3]),
        }
    )
    em.setdefault("relative_rad", 0.0)
    from ratslam_graph.experience_map import STATE_FORMAT, STATE_VERSION

    em.setdefault("format", STATE_FORMAT)  # maps imported from the reference format
    em.setdefault("version", STATE_VERSION)
    return em


_EM_KNOWN = {
    "poses",
    "pc",
    "template_id",
    "frame",
    "t",
    "link_ends",
    "link_values",
    "link_counts",
    "link_behaviour",
    "current_id",
    "prev_id",
    "accum_x",
    "accum_y",
    "accum_facing",
    "accum_time",
}


def apply_experience_map(state: MapState, config: Any, *, passes: int | None = None) -> MapState:
    """Relax ``state``'s experience map once with the configured backend
    (``exp_backend``, ``exp_loops`` passes unless ``passes`` is given); returns a copy
    with the new poses."""
    from ratslam_graph.experience_map import ExperienceMap

    params = config.experience_map
    if passes is not None:
        params = params.replace(exp_loops=int(passes))
    em = ExperienceMap(params)
    em.set_state(experience_map_state(state))
    em.iterate()
    out = state.copy()
    out.exp_pose = np.asarray(em.poses, np.float64).copy()
    return out


def require_templates(state: MapState, *, what: str = "map") -> None:
    """Raise :class:`MapFormatError` when ``state`` was read without its templates (a
    reference-format save lacking ``localviewcells.txt``): it can be plotted and compared,
    but not merged or continued."""
    missing = state.scalars.get(MISSING_KEY)
    if missing:
        raise MapFormatError(
            f"{what} ({state.name or 'in memory'}) has no templates: {missing} is missing "
            "from its directory; merging or continuing a map needs its templates (plots, "
            "ICP and ATE work without them)"
        )


def conform(state: MapState, config: Any, *, what: str = "stored map") -> MapState:
    """``state`` made usable with ``config``: a reference-format map read without a
    config (templates ``(N, 1, S)``, no pose-cell sizes) gets its templates reshaped to
    the config's ``template_y_size x template_x_size`` and the config's pose-cell sizes;
    then compatibility is checked (:func:`check_compatible`).

    Raises:
        MapFormatError: the map cannot be used with ``config``.
    """
    require_templates(state, what=what)
    flat = config.to_flat() if hasattr(config, "to_flat") else dict(config)
    ty, tx = int(flat.get("template_y_size", 1)), int(flat.get("template_x_size", 1))
    if (
        state.scalars.get("imported_from") == "reference"
        and state.templates.shape[1:] != (ty, tx)
        and state.templates.shape[1] * state.templates.shape[2] == ty * tx
        and state.templates.shape[1] == 1
    ):
        state = state.copy()
        state.templates = state.templates.reshape(-1, ty, tx)
        state.config = {
            **flat,
            **{
                k: v
                for k, v in state.config.items()
                if k not in ("template_x_size", "template_y_size")
            },
        }
    missing = [k for k in ("pc_dim_xy", "pc_dim_th") if k not in state.config]
    if state.scalars.get("imported_from") == "reference" and missing:
        state = state.copy()
        state.config.update({k: flat.get(k) for k in missing})
    check_compatible(state, config, what=what)
    return state


_PC_KNOWN = {
    "activity",
    "template_pc",
    "template_decay",
    "exp_pc",
    "exp_template",
    "current_exp",
    "current_vt",
    "prev_vt",
    "best",
}
_LV_KNOWN = {"templates", "means", "frames", "current_id", "previous_id", "template_shape"}


def _np(v: Any) -> np.ndarray:
    return np.asarray(v.detach().cpu().numpy() if hasattr(v, "detach") else v)


def state_from_slam(slam: Any) -> MapState:
    """The complete state of a running ``RatSLAM`` (or ``MultiSessionRatSLAM``) as a
    :class:`MapState` (from each module's ``get_state()``).

    Raises:
        MapFormatError: a module has no ``get_state`` / ``set_state``
            (:class:`torchratslam.protocols.Stateful`).
    """
    from torchratslam.pipeline import RatSLAM
    from torchratslam.protocols import Stateful

    slam = slam if isinstance(slam, RatSLAM) else slam.slam  # a multisession wrapper
    stages = {"local view": slam.local_view, "pose cells": slam.pose_cells}
    for label, module in {**stages, "experience map": slam.experience_map}.items():
        if not isinstance(module, Stateful):
            raise MapFormatError(
                f"the {label} ({type(module).__name__}) has no get_state()/set_state(), "
                "so its map cannot be saved"
            )
    lv = slam.local_view.get_state()
    pc = slam.pose_cells.get_state()
    em = slam.experience_map.get_state()
    templates = _np(lv["templates"])
    n = templates.shape[0]
    means = _np(lv.get("means", templates.reshape(n, -1).mean(1) if n else np.zeros(0)))
    ends = _np(em["link_ends"]).reshape(-1, 2)
    vals = _np(em["link_values"]).reshape(-1, 4)
    exp_pc = _np(pc["exp_pc"]).astype(np.float64).reshape(-1, 3)
    em_pc = _np(em["pc"]).astype(np.float64).reshape(-1, 3)
    state = MapState(
        config=slam.config.to_flat(),
        templates=np.ascontiguousarray(templates),
        template_mean=means.astype(np.float64),
        template_frame=_np(lv.get("frames", np.full(n, -1))).astype(np.int64),
        template_pc=_np(pc["template_pc"]).astype(np.float64).reshape(-1, 3),
        template_decay=_np(pc["template_decay"]).astype(np.float64),
        exp_pose=_np(em["poses"]).astype(np.float64).reshape(-1, 3),
        exp_pc=exp_pc,
        exp_template=_np(em["template_id"]).astype(np.int64),
        exp_frame=_np(em["frame"]).astype(np.int64),
        exp_t=_np(em["t"]).astype(np.float64),
        link_from=ends[:, 0].astype(np.int64),
        link_to=ends[:, 1].astype(np.int64),
        link_d=vals[:, 0].copy(),
        link_heading=vals[:, 1].copy(),
        link_facing=vals[:, 2].copy(),
        link_dt=vals[:, 3].copy(),
        activity=np.ascontiguousarray(_np(pc["activity"])),
        current_vt=int(pc.get("current_vt", lv.get("current_id", -1))),
        prev_vt=int(pc.get("prev_vt", lv.get("previous_id", -1))),
        current_exp=int(em["current_id"]),
        prev_exp=int(em["prev_id"]),
        frame_index=int(slam.frame_index),
    )
    state.extra[EM_ACCUM] = np.array(
        [em["accum_x"], em["accum_y"], em["accum_facing"], em["accum_time"]], np.float64
    )
    state.extra["link:counts"] = _np(em["link_counts"]).astype(np.int64).reshape(-1, 3)
    state.extra["link:behaviour"] = _np(em["link_behaviour"]).astype(np.int64).reshape(-1)
    if "best" in pc:
        state.extra[PC_BEST] = _np(pc["best"]).astype(np.float64).reshape(3)
    if not np.array_equal(em_pc, exp_pc):
        state.extra["exp:em_pc"] = em_pc
    if not np.array_equal(_np(pc["exp_template"]).astype(np.int64), state.exp_template):
        state.extra["exp:pc_template"] = _np(pc["exp_template"]).astype(np.int64)
    if int(pc.get("current_exp", state.current_exp)) != state.current_exp:
        state.scalars["pc.current_exp"] = int(pc["current_exp"])
    _split_extras("lv", lv, _LV_KNOWN, state)
    _split_extras("pc", pc, _PC_KNOWN, state)
    _split_extras("em", em, _EM_KNOWN, state)
    if isinstance(slam.odometry, Stateful):
        _split_extras("vo", slam.odometry.get_state(), set(), state)
    state.scalars["slam.last_t"] = float(slam._last_t)
    return state.validate(source="running map")


def apply_state(state: MapState, slam: Any, *, exp_ids: np.ndarray | None = None) -> None:
    """Load ``state`` into a running ``RatSLAM`` (or ``MultiSessionRatSLAM``) through each
    module's ``set_state``, so that it continues exactly as the saved run would have.

    Args:
        state: the map (checked against the slam's config first).
        slam: the pipeline.
        exp_ids: after a merge, the old -> new experience id map of the running map, used
            to re-point the per-frame history (``trajectory()``) into the merged map.

    Raises:
        MapFormatError: the map is incompatible with the slam's config.
    """
    from torchratslam.pipeline import RatSLAM
    from torchratslam.protocols import Stateful

    slam = slam if isinstance(slam, RatSLAM) else slam.slam  # a multisession wrapper
    state = conform(state, slam.config)
    lv = _collect("lv", state)
    lv.update(
        {
            "templates": np.ascontiguousarray(state.templates),
            "means": state.template_mean.copy(),
            "frames": state.template_frame.copy(),
            "current_id": int(state.current_vt),
            "previous_id": int(state.prev_vt),
            "template_shape": np.asarray(state.templates.shape[1:], np.int64),
        }
    )
    if not {"kind", "version"} <= lv.keys():  # not saved (an imported map): the module's own
        own = slam.local_view.get_state()
        lv.setdefault("kind", own.get("kind", "ratslam"))
        lv.setdefault("version", own.get("version", 1))
    lv.setdefault("frame_counter", int(state.frame_index))
    pc = _collect("pc", state)
    pc.update(
        {
            "activity": state.activity.copy(),
            "template_pc": state.template_pc.copy(),
            "template_decay": state.template_decay.copy(),
            "exp_pc": state.exp_pc.copy(),
            "exp_template": np.array(
                state.extra.get("exp:pc_template", state.exp_template), dtype=np.int64, copy=True
            ),
            "current_exp": int(state.scalars.get("pc.current_exp", state.current_exp)),
            "current_vt": int(state.current_vt),
            "prev_vt": int(state.prev_vt),
        }
    )
    pc["current_exp"] = int(state.scalars.get("pc.current_exp", state.current_exp))
    if PC_BEST in state.extra:
        pc["best"] = np.array(state.extra[PC_BEST], np.float64, copy=True)
    em = experience_map_state(state)
    if "exp:em_pc" in state.extra:
        em["pc"] = np.array(state.extra["exp:em_pc"], np.float64, copy=True)
    slam.local_view.set_state(lv)
    slam.pose_cells.set_state(pc)
    slam.experience_map.set_state(em)
    vo = _collect("vo", state)
    if isinstance(slam.odometry, Stateful) and vo:
        slam.odometry.set_state(vo)
    slam.frame_index = int(state.frame_index)
    slam._last_t = float(state.scalars.get("slam.last_t", 0.0))
    if exp_ids is not None:
        slam.remap_experiences(np.asarray(exp_ids, np.int64))
