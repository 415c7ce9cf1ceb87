"""The complete state of a RatSLAM map as one record, and its validation.

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

The other rooms of :mod:`torchratslam.maps`: the native on-disk format
(:mod:`~torchratslam.maps.native`), the stage records a map is made of
(:mod:`~torchratslam.maps.stages`), a running pipeline's map
(:mod:`~torchratslam.maps.running`) and the checks against a configuration
(:mod:`~torchratslam.maps.compat`).

Example:
    >>> from torchratslam.maps.state import MapState
    >>> MapState.empty({"template_y_size": 2, "template_x_size": 3}).summary()
    {'templates': 0, 'experiences': 0, 'links': 0}
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from torchratslam.errors import MapFormatError

__all__ = [
    "ARRAY_FIELDS",
    "EM_ACCUM",
    "INT_FIELDS",
    "MISSING_KEY",
    "PC_BEST",
    "PER_ENTITY",
    "MapState",
    "config_pc_dims",
]

MISSING_KEY = "missing_files"
"""Scalar key: the files a map was read without (a reference-format save lacking
``localviewcells.txt`` has zero templates in their place; see
:func:`~torchratslam.maps.compat.require_templates`)."""

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
EM_ACCUM = "em.accum"
"""Extra key: the experience map's odometry accumulated since the current experience,
``[x m, y m, facing rad, time s]`` in the map frame (merges rotate it)."""
PC_BEST = "pc.best"
"""Extra key: the pose cells' last decoded packet centre ``(x, y, th)`` cells (merges move
it with the activity)."""


def _f(a: Any, dtype: Any = np.float64) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=dtype))


def _i(a: Any) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.int64))


def config_pc_dims(config: Mapping[str, Any]) -> tuple[int, int, int]:
    """The pose-cell ring sizes ``(X, Y, TH)`` a flat config gives: ``pc_dim_x`` and
    ``pc_dim_y`` where set and non-zero, else ``pc_dim_xy`` (default 21); ``pc_dim_th``
    (default 36)."""
    xy = int(config.get("pc_dim_xy", 21))
    return (
        int(config.get("pc_dim_x") or 0) or xy,
        int(config.get("pc_dim_y") or 0) or xy,
        int(config.get("pc_dim_th", 36)),
    )


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
        """(X, Y, TH) from the config: the x, y, th ring sizes (``pc_dim_x`` and
        ``pc_dim_y`` where set and non-zero, else ``pc_dim_xy``; a map saved before
        those keys existed is square)."""
        return config_pc_dims(self.config)

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
                f"says (TH, Y, X) = {(pcs[2], pcs[1], pcs[0])} (pc_dim_th, pc_dim_y or "
                "pc_dim_xy, pc_dim_x or pc_dim_xy)"
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
