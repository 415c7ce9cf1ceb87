"""Parameters: one frozen dataclass per module, loaded from YAML or OpenRatSLAM ``.txt``.

Keys are named exactly as in OpenRatSLAM (``shared/reference/parameters.md``); a key
that is absent takes OpenRatSLAM's default. The key space is flat, as in OpenRatSLAM's
own config files: :func:`load_config` routes each key to the module that owns it.

Every key has one default, the field of its dataclass. Two behaviour profiles
(``behaviour: openratslam``, the default, or ``torchratslam``) set the keys of
:data:`PROFILES` that a config does not set itself: OpenRatSLAM exactly (the dataclass
defaults) or the recommended choices (``docs/openratslam-fidelity.md``).

Example:
    >>> from torchratslam.config import load_config
    >>> cfg = load_config("configs/virtual_tour.yaml")
    >>> cfg.pose_cells.pc_dim_xy
    80
"""

from __future__ import annotations

import configparser
import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import yaml

from ratslam_graph.errors import unknown_name_message
from ratslam_graph.params import ExperienceMapParams, Params, param
from torchratslam.errors import ConfigError, InputError, option


def _presets_dir() -> Path:
    """The folder of the shipped presets.

    ``configs/`` in a source checkout (and an editable install); the wheel ships the same
    files as data in ``torchratslam/presets/``.
    """
    installed = Path(__file__).resolve().parent / "presets"
    if installed.is_dir():
        return installed
    return Path(__file__).resolve().parent.parent / "configs"


CONFIG_DIR = _presets_dir()

__all__ = [
    "CONFIG_DIR",
    "PROFILES",
    "RECOMMENDED",
    "ExperienceMapParams",
    "GeneralParams",
    "LocalViewParams",
    "Params",
    "PoseCellParams",
    "RatSLAMConfig",
    "VisualOdometryParams",
    "check_config_limits",
    "load_config",
    "param",
    "profile_values",
    "read_yaml_unique",
]


@dataclass(frozen=True)
class GeneralParams(Params):
    """General keys of an OpenRatSLAM config (``[general]`` section)."""

    section: ClassVar[str] = "general"

    topic_root: str = param(
        "", "ROS topic prefix: images at <root>/camera/image, odometry at <root>/odom"
    )
    local_view: str = param("ratslam", "local view module (a name in registry.LOCAL_VIEWS)")
    pose_cells: str = param("ratslam", "pose-cell module (a name in registry.POSE_CELLS)")
    experience_map: str = param("ratslam", "experience map (a name in registry.EXPERIENCE_MAPS)")
    odometry: str = param("given", "odometry source: given | visual (registry.ODOMETRY)")
    behaviour: str = param(
        "openratslam",
        "behaviour profile: openratslam (exactly OpenRatSLAM) | torchratslam (the "
        "recommended choices); sets every key of PROFILES that the config does not set itself",
        choices=("openratslam", "torchratslam"),
    )
    dtype: str = param(
        "float64",
        "precision of the pose cells, templates and view comparison: float64 (OpenRatSLAM's "
        "double, the default: its decisions exactly) | float32 (half the memory; decisions "
        "within float32's rounding of a threshold or a tie may go the other way)",
        choices=("float64", "float32"),
    )
    skip_first_odometry: bool = param(
        True,
        "no pose-cell step, no action and no experience-map odometry at frame 0, as "
        "OpenRatSLAM's nodes skip their first odometry message (prev_time == 0)",
    )
    action_angle: str = param(
        "injection",
        "relative angle an action carries to the experience map: injection (the last "
        "injection's, OpenRatSLAM's get_relative_rad) | view (this frame's view angle)",
        choices=("injection", "view"),
    )


@dataclass(frozen=True)
class PoseCellParams(Params):
    """Pose-cell network parameters (OpenRatSLAM names and defaults)."""

    section: ClassVar[str] = "pose cell"

    pc_dim_xy: int = param(21, "cells along x and y (unless pc_dim_x / pc_dim_y say)", gt=0)
    pc_dim_x: int = param(0, "cells along x (0: pc_dim_xy)", ge=0)
    pc_dim_y: int = param(0, "cells along y (0: pc_dim_xy)", ge=0)
    pc_dim_th: int = param(36, "cells along theta", gt=0)
    pc_w_e_dim: int = param(7, "excitatory kernel side (cells)", gt=0)
    pc_w_e_var: float = param(1.0, "excitatory kernel variance", gt=0.0)
    pc_w_i_dim: int = param(5, "inhibitory kernel side (cells)", gt=0)
    pc_w_i_var: float = param(2.0, "inhibitory kernel variance", gt=0.0)
    pc_global_inhib: float = param(0.00002, "global inhibition subtracted from every cell", ge=0.0)
    pc_cells_to_avg: int = param(3, "half-width of the cube decoded around the peak", ge=0)
    vt_active_decay: float = param(1.0, "decay added when the current template is re-seen", ge=0.0)
    pc_vt_inject_energy: float = param(0.15, "energy injected by a familiar template", ge=0.0)
    pc_cell_x_size: float = param(1.0, "metres per pose cell in x and y", gt=0.0)
    exp_delta_pc_threshold: float = param(
        2.0, "pose-cell distance that makes a new experience", ge=0.0
    )
    pc_vt_restore: float = param(0.05, "decay relaxation per step", ge=0.0)
    # OpenRatSLAM's exact behaviours (defaults) or the project's choices, by name.
    pc_decode: str = param(
        "openratslam",
        "packet centre decoding: openratslam (find_best: phasors at (i + 1) 2pi/n, minus one "
        "cell; a centre on a cell comes out just below it) | exact (phasors at i 2pi/n)",
        choices=("openratslam", "exact"),
    )
    vt_inject_rule: str = param(
        "openratslam",
        "which known templates inject energy: openratslam (all while fewer than 10 templates "
        "exist, then all but the 10 most recent) | last_10 (never the 10 most recent)",
        choices=("openratslam", "last_10"),
    )
    pc_axis: str = param(
        "openratslam",
        "path-integration axes: openratslam (layer k moves along (sin, cos)(k 2pi/TH) in "
        "(x, y), heading 0 is +y) | math (along (cos, sin), heading 0 is +x)",
        choices=("openratslam", "math"),
    )
    pc_wrap: str = param(
        "openratslam",
        "activity crossing the x/y wrap: openratslam (two edge cells of a layer lose what "
        "crosses, as its wrap-back loops start at 1) | preserve_mass (all of it wraps)",
        choices=("openratslam", "preserve_mass"),
    )
    pc_multi_cell: bool = param(
        False,
        "path integration over more than one cell per step (integer roll + bilinear "
        "fraction); false: OpenRatSLAM's four-neighbour weights, exact up to one cell",
    )

    pc_engine: str = param(
        "auto",
        "how one CPU network steps: numpy (on the packet's crop, fastest at B = 1) | torch "
        "(the batched methods) | auto (numpy for one CPU network). The same actions in "
        "float64; in float32 their rounding differs and can tip a near-tie the other way",
        choices=("auto", "numpy", "torch"),
    )

    @property
    def dim_x(self) -> int:
        """Cells along x: ``pc_dim_x``, or ``pc_dim_xy`` when it is 0."""
        return self.pc_dim_x or self.pc_dim_xy

    @property
    def dim_y(self) -> int:
        """Cells along y: ``pc_dim_y``, or ``pc_dim_xy`` when it is 0."""
        return self.pc_dim_y or self.pc_dim_xy

    @property
    def dims(self) -> tuple[int, int, int]:
        """``(X, Y, TH)``: the ring sizes of the network."""
        return self.dim_x, self.dim_y, self.pc_dim_th

    def __post_init__(self) -> None:
        super().__post_init__()
        default_xy = type(self).__dataclass_fields__["pc_dim_xy"].default
        if (
            self.pc_dim_x
            and self.pc_dim_y
            and self.pc_dim_xy != default_xy
            and self.pc_dim_xy not in (self.pc_dim_x, self.pc_dim_y)
        ):
            raise ConfigError(
                f"pc_dim_xy = {self.pc_dim_xy} contradicts pc_dim_x = {self.pc_dim_x} and "
                f"pc_dim_y = {self.pc_dim_y} (it would size neither axis): drop pc_dim_xy or "
                "make it one of them"
            )
        if self.pc_wrap == "openratslam" and self.pc_multi_cell:
            raise ConfigError(
                "pc_wrap='openratslam' (the reference's edge loss) is defined for one-cell "
                "steps only: set pc_multi_cell=false or pc_wrap='preserve_mass'"
            )


@dataclass(frozen=True)
class LocalViewParams(Params):
    """Local view cell (visual template) parameters."""

    section: ClassVar[str] = "local view"

    vt_min_patch_normalisation_std: float = param(0.0, "minimum std in patch normalisation", ge=0.0)
    vt_patch_normalise: int = param(0, "patch normalisation radius in pixels (0: off)", ge=0)
    vt_normalisation: float = param(0.0, "global normalisation target mean (0: off)", ge=0.0)
    vt_shift_match: int = param(25, "max column shift in normal mode", ge=0)
    vt_step_match: int = param(5, "column step between compared offsets", gt=0)
    vt_panoramic: bool = param(False, "images are 360-degree panoramas (circular matching)")
    vt_match_threshold: float = param(0.03, "MAD above which a new template is learnt", ge=0.0)
    # OpenRatSLAM's own defaults (1 x 1 with vt_shift_match 25) cannot be matched in
    # normal mode; 60 x 10 is the template of its shipped St Lucia and New College
    # configs (all three of its configs use 60 columns), so the defaults run.
    template_x_size: int = param(60, "template width (columns; OpenRatSLAM: 1)", gt=0)
    template_y_size: int = param(10, "template height (rows; OpenRatSLAM: 1)", gt=0)
    image_crop_x_min: int = param(0, "crop: first column", ge=0)
    image_crop_x_max: int = param(-1, "crop: end column (exclusive; -1: image width)", ge=-1)
    image_crop_y_min: int = param(0, "crop: first row", ge=0)
    image_crop_y_max: int = param(-1, "crop: end row (exclusive; -1: image height)", ge=-1)


@dataclass(frozen=True)
class VisualOdometryParams(Params):
    """Visual odometry from intensity profiles (OpenRatSLAM names; -1 means image edge)."""

    section: ClassVar[str] = "visual odometry"

    vtrans_image_x_min: int = param(0, "translation crop: first column", ge=0)
    vtrans_image_x_max: int = param(-1, "translation crop: end column (-1: width)", ge=-1)
    vtrans_image_y_min: int = param(0, "translation crop: first row", ge=0)
    vtrans_image_y_max: int = param(-1, "translation crop: end row (-1: height)", ge=-1)
    vrot_image_x_min: int = param(0, "rotation crop: first column", ge=0)
    vrot_image_x_max: int = param(-1, "rotation crop: end column (-1: width)", ge=-1)
    vrot_image_y_min: int = param(0, "rotation crop: first row", ge=0)
    vrot_image_y_max: int = param(-1, "rotation crop: end row (-1: height)", ge=-1)
    camera_fov_deg: float = param(50.0, "horizontal field of view (degrees)", gt=0.0, le=360.0)
    camera_hz: float = param(10.0, "frame rate (Hz)", gt=0.0)
    vtrans_scaling: float = param(100.0, "profile difference to metres scale", gt=0.0)
    vtrans_max: float = param(20.0, "cap on the translational speed estimate", ge=0.0)


#: The recommended profile, ``behaviour: torchratslam``: OpenRatSLAM plus the choices
#: measured to be as good or better on all but one simulated set
#: (docs/openratslam-fidelity.md, "When to use which", has the numbers and the exception).
#: Each key is set to a value other than its default; the ``openratslam`` profile sets the
#: same keys to their defaults (:data:`PROFILES`).
RECOMMENDED: dict[str, Any] = {
    "pc_decode": "exact",
    "pc_axis": "math",
    "pc_wrap": "preserve_mass",
    "pc_multi_cell": True,
    "skip_first_odometry": False,
    "exp_first_at_origin": True,
    "exp_link_time": "per_link",
}

# Keys that only drive OpenRatSLAM's on-screen drawing; accepted and ignored anywhere.
DISPLAY_KEYS = frozenset(
    {
        "enable",
        "vt_window_width",
        "vt_window_height",
        "exp_map_size",
        "posecell_vis",
        "media_path",
        "image_file",
        "pc_window_width",
        "pc_window_height",
    }
)
# Top-level YAML keys that are metadata, not parameters.
META_KEYS = frozenset({"description", "source"})


@dataclass(frozen=True)
class RatSLAMConfig:
    """All module parameters of one RatSLAM run.

    Attributes map one-to-one to modules; build with :func:`load_config` or
    :meth:`from_flat`.
    """

    general: GeneralParams = field(default_factory=GeneralParams)
    pose_cells: PoseCellParams = field(default_factory=PoseCellParams)
    local_view: LocalViewParams = field(default_factory=LocalViewParams)
    experience_map: ExperienceMapParams = field(default_factory=ExperienceMapParams)
    visual_odometry: VisualOdometryParams = field(default_factory=VisualOdometryParams)

    def __post_init__(self) -> None:
        self.check()

    def check(self) -> None:
        """Cross-field checks (each key alone is checked by its section).

        Raises:
            ConfigError: two keys that cannot go together, both named with their values.
        """
        lv = self.local_view
        if not lv.vt_panoramic and lv.template_x_size <= 2 * lv.vt_shift_match:
            raise ConfigError(
                f"template_x_size = {lv.template_x_size} must exceed 2 * vt_shift_match = "
                f"{2 * lv.vt_shift_match} when vt_panoramic is off (the compared width is "
                "template_x_size - 2 * vt_shift_match); lower vt_shift_match or widen "
                "the template"
            )
        vo = self.visual_odometry
        crops: list[tuple[Params, str]] = [(lv, "image_crop_x"), (lv, "image_crop_y")]
        crops += [(vo, f"{p}_image_{a}") for p in ("vtrans", "vrot") for a in "xy"]
        for section, stem in crops:
            lo, hi = getattr(section, f"{stem}_min"), getattr(section, f"{stem}_max")
            if hi != -1 and hi <= lo:
                raise ConfigError(
                    f"{stem}_max = {hi} must exceed {stem}_min = {lo} (or be -1 for the image edge)"
                )

    @classmethod
    def sections(cls) -> dict[str, type[Params]]:
        hints = {f.name: f.default_factory for f in dataclasses.fields(cls)}
        return hints  # type: ignore[return-value]

    @classmethod
    def key_owner(cls) -> dict[str, str]:
        """Map every flat parameter key to the attribute (section) that owns it."""
        owner: dict[str, str] = {}
        for attr, klass in cls.sections().items():
            for key in klass.keys():
                owner[key] = attr
        return owner

    @classmethod
    def from_flat(cls, values: Mapping[str, Any], *, source: str = "config") -> RatSLAMConfig:
        """Build from a flat ``{key: value}`` mapping, routing keys to modules.

        Raises:
            ConfigError: an unknown key (named, with the nearest valid key), a wrong type
                or an out-of-range value (named with the value).
        """
        owner = cls.key_owner()
        grouped: dict[str, dict[str, Any]] = {attr: {} for attr in cls.sections()}
        behaviour = values.get("behaviour", GeneralParams.behaviour)
        values = {**profile_values(behaviour, source), **values}
        for key, value in values.items():
            if key in META_KEYS or key in DISPLAY_KEYS:
                continue
            if key not in owner:
                raise ConfigError(f"{source}: " + unknown_name_message("parameter", key, owner))
            grouped[owner[key]][key] = value
        try:
            built: dict[str, Any] = {
                attr: klass(**grouped[attr]) for attr, klass in cls.sections().items()
            }
            return cls(**built)
        except ConfigError as exc:
            raise ConfigError(f"{source}: {exc}") from None

    def to_flat(self) -> dict[str, Any]:
        """The flat ``{key: value}`` form (what :meth:`from_flat` reads)."""
        out: dict[str, Any] = {}
        for attr in self.sections():
            out.update(getattr(self, attr).to_dict())
        return out

    def replace(self, **changes: Any) -> RatSLAMConfig:
        """A copy with some flat keys changed (validated like a loaded file).

        Changing ``behaviour`` sets the new profile's keys too, except those given in
        ``changes`` and those whose current value differs from the old profile's (keys
        the config set itself; a key set to the old profile's own value follows the new
        profile). Setting both ``pc_dim_x`` and ``pc_dim_y`` (and not ``pc_dim_xy``)
        returns ``pc_dim_xy`` to its default, which then sizes neither axis.
        """
        flat = self.to_flat()
        if changes.get("pc_dim_x") and changes.get("pc_dim_y") and "pc_dim_xy" not in changes:
            flat.pop("pc_dim_xy")  # both axes are sized now: the old square size goes
        if "behaviour" in changes:
            old = profile_values(flat["behaviour"], "replace()")
            flat = {k: v for k, v in flat.items() if k not in old or v != old[k]}
        return self.from_flat({**flat, **changes}, source="replace()")


def _defaults() -> dict[str, Any]:
    """Every key's default: the field of the dataclass that owns it."""
    return {
        f.name: f.default
        for klass in RatSLAMConfig.sections().values()
        for f in dataclasses.fields(klass)
    }


#: The behaviour profiles: ``openratslam`` (the default, OpenRatSLAM exactly: the keys of
#: :data:`RECOMMENDED` at their dataclass defaults) and ``torchratslam`` (recommended).
PROFILES: dict[str, dict[str, Any]] = {
    "openratslam": {key: _defaults()[key] for key in RECOMMENDED},
    "torchratslam": dict(RECOMMENDED),
}


def profile_values(name: Any, source: str = "config") -> dict[str, Any]:
    """The keys a behaviour profile sets (a copy of ``PROFILES[name]``).

    Raises:
        ConfigError: an unknown profile name (with the nearest valid one) or a value that
            is not a name.
    """
    if not isinstance(name, str):
        raise ConfigError(
            f"{source}: behaviour must be a profile name ({' or '.join(PROFILES)}), "
            f"got {type(name).__name__} {name!r:.60}"
        )
    if name not in PROFILES:
        raise ConfigError(
            f"{source}: " + unknown_name_message("behaviour profile", str(name), PROFILES)
        )
    return dict(PROFILES[name])


def _read_text(path: Path) -> str:
    try:
        return path.read_text()
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not a text file ({exc})") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({exc.strerror or exc})") from None


class _DuplicateKey(yaml.YAMLError):
    """A mapping names one key twice (the message says which, on which lines)."""


class _UniqueKeyLoader(yaml.SafeLoader):
    """YAML's safe loader, refusing a mapping that names one key twice (plain YAML
    keeps the last value silently)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                first = seen.setdefault(key, key_node.start_mark.line + 1)
            except TypeError:
                continue  # an unhashable key: construct_mapping below names it
            if first != key_node.start_mark.line + 1:
                raise _DuplicateKey(
                    f"key {key!r:.60} appears twice (lines {first} and "
                    f"{key_node.start_mark.line + 1}); keep one"
                )
        return super().construct_mapping(node, deep=deep)


def read_yaml_unique(path: str | Path) -> Any:
    """The YAML file at ``path`` read with a safe loader that refuses a key given twice
    (plain YAML keeps the last value silently); None for an empty file.

    Raises:
        ConfigError: a duplicate key (naming both lines), not valid YAML, not text.
        InputError: the file cannot be read.
    """
    p = Path(path)
    try:
        return yaml.load(_read_text(p), Loader=_UniqueKeyLoader)  # a SafeLoader
    except _DuplicateKey as exc:
        raise ConfigError(f"{p}: {exc}") from None
    except (yaml.YAMLError, RecursionError) as exc:
        one_line = " ".join(str(exc).split())
        raise ConfigError(f"{p}: not valid YAML ({one_line})") from None


def _read_yaml(path: Path) -> dict[str, Any]:
    data = read_yaml_unique(path)
    if data is None:
        raise ConfigError(
            f"{path}: holds no parameters (an empty file); write the keys to change, or "
            "'{}' for OpenRatSLAM's defaults"
        )
    if not isinstance(data, dict):
        raise ConfigError(
            f"{path}: expected a mapping of parameter keys, got {type(data).__name__}"
        )
    for key in data:
        if not isinstance(key, str):
            raise ConfigError(
                f"{path}: key {key!r} ({type(key).__name__}) is not a parameter name; keys "
                "are names such as pc_dim_xy"
            )
    return data


def _read_openratslam_txt(path: Path) -> dict[str, Any]:
    """Read an OpenRatSLAM ini-style config: ``[general]``, ``[ratslam]``,
    ``[visual_odometry]``, ``[draw]``; ``;`` and ``#`` comments; other sections ignored."""
    parser = configparser.ConfigParser(
        inline_comment_prefixes=(";", "#"),
        comment_prefixes=(";", "#"),
        strict=True,  # a key or section given twice is refused, as OpenRatSLAM's reader does
        interpolation=None,
    )
    parser.optionxform = str  # type: ignore[assignment,method-assign]  # keep key case
    try:
        parser.read_string(_read_text(path))
    except configparser.DuplicateOptionError as exc:
        raise ConfigError(
            f"{path}: key {exc.option!r} appears twice in [{exc.section}] (line {exc.lineno}); "
            "keep one"
        ) from None
    except configparser.DuplicateSectionError as exc:
        raise ConfigError(
            f"{path}: section [{exc.section}] appears twice (line {exc.lineno}); keep one"
        ) from None
    except configparser.Error as exc:
        one_line = " ".join(str(exc).split())
        raise ConfigError(f"{path}: not a valid OpenRatSLAM config ({one_line})") from None
    flat: dict[str, Any] = {}
    where: dict[str, str] = {}
    for section in ("general", "ratslam", "visual_odometry"):
        if parser.has_section(section):
            for key, value in parser.items(section):
                if key in flat:
                    raise ConfigError(
                        f"{path}: key {key!r} appears in both [{where[key]}] and "
                        f"[{section}]; keep one"
                    )
                flat[key], where[key] = value.strip().strip('"'), section
    if not flat:
        raise ConfigError(
            f"{path}: holds no parameters (no keys under [general], [ratslam] or "
            "[visual_odometry]); write the keys to change"
        )
    return flat


def load_config(
    path: str | Path | Mapping[str, Any] | None = None, **overrides: Any
) -> RatSLAMConfig:
    """Load a configuration.

    Args:
        path: a YAML file (``.yaml``/``.yml``), an OpenRatSLAM ``.txt`` config, the name
            of a shipped preset (``configs/`` in the repository, ``torchratslam/presets/``
            when installed) without extension (e.g. ``"virtual_tour"``), a dict of flat
            keys (as in a YAML file, e.g. ``{"pc_dim_xy": 15}``), or None for
            OpenRatSLAM's defaults.
        **overrides: flat keys that replace values from the file.

    Returns:
        The validated :class:`RatSLAMConfig`.

    Raises:
        InputError: the file does not exist.
        ConfigError: unknown key, wrong type or out-of-range value, or two keys that
            cannot go together (:meth:`RatSLAMConfig.check`).
    """
    if path is None:
        return RatSLAMConfig.from_flat(overrides, source="overrides")
    if isinstance(path, Mapping):
        bad = next((k for k in path if not isinstance(k, str)), None)
        if bad is not None:
            raise ConfigError(
                f"config dict: key {bad!r} ({type(bad).__name__}) is not a parameter name; "
                "keys are names such as pc_dim_xy"
            )
        return RatSLAMConfig.from_flat({**path, **overrides}, source="config dict")
    if not isinstance(path, (str, Path)):
        raise ConfigError(
            f"load_config takes a file path, a preset name, a dict of flat keys or None; "
            f"got {type(path).__name__}"
        )
    p = Path(path)
    if not p.exists() and not p.suffix and (CONFIG_DIR / f"{p.name}.yaml").exists():
        p = CONFIG_DIR / f"{p.name}.yaml"
    if not p.exists():
        shipped = sorted(q.stem for q in CONFIG_DIR.glob("*.yaml"))
        raise InputError(
            f"config file {str(path)!r} not found (shipped configs: {', '.join(shipped)})"
        )
    if p.is_dir():
        raise InputError(f"config {str(path)!r} is a directory; give a .yaml or .txt file")
    flat = _read_yaml(p) if p.suffix.lower() in (".yaml", ".yml") else _read_openratslam_txt(p)
    try:
        return RatSLAMConfig.from_flat({**flat, **overrides}, source=str(p))
    except ConfigError:
        if not overrides:
            raise
    # something is wrong: name the file when the file alone is wrong, else the overrides
    RatSLAMConfig.from_flat(flat, source=str(p))
    return RatSLAMConfig.from_flat({**flat, **overrides}, source=option("--set", "overrides"))


def to_openratslam_txt(config: RatSLAMConfig, *, comment: str = "") -> str:
    """The config as an OpenRatSLAM ini-style ``.txt`` file (what its nodes read).

    ``[general]`` holds ``topic_root``, ``[visual_odometry]`` the visual-odometry keys and
    ``[ratslam]`` every other key (OpenRatSLAM ignores the keys it does not know, and
    :func:`load_config` reads every one back, so the round trip is exact). Booleans are
    written as 0/1 and integral floats without a fraction (OpenRatSLAM reads some keys
    as ints).

    Args:
        config: the configuration.
        comment: an optional first comment line (``;`` is prefixed).

    Returns:
        The file's text.
    """
    sections: dict[str, list[str]] = {"general": [], "ratslam": [], "visual_odometry": []}
    for attr in config.sections():
        target = attr if attr in ("general", "visual_odometry") else "ratslam"
        for key, value in getattr(config, attr).to_dict().items():
            if isinstance(value, bool) or (isinstance(value, float) and value.is_integer()):
                value = int(value)  # C++ reads "2" as an int or a double, "2.0" only as a double
            sections[target].append(f"{key}={value}")
    lines = [f"; {comment}"] if comment else []
    for name, entries in sections.items():
        lines += [f"[{name}]", *entries, ""]
    return "\n".join(lines)


def check_config_limits(config: RatSLAMConfig, *, memory_bytes: int | None = None) -> None:
    """Checks against the machine, made before any work (the checks across fields run
    when the config is made):

    * the pose-cell network (``X * Y * pc_dim_th`` cells, a few float copies)
      and one template (``template_x_size * template_y_size``) fit in ``memory_bytes``
      (default: the machine's physical memory).

    Raises:
        ConfigError: naming the keys, their values and the limit.
    """
    flat = config.to_flat()
    if memory_bytes is None:
        memory_bytes = _physical_memory()
    n_x, n_y, th = config.pose_cells.dims
    need = n_x * n_y * th * 8 * 4  # activity + excitation/inhibition buffers, float64 worst
    if memory_bytes and need > memory_bytes:
        size = f"pc_dim_xy = {n_x}" if n_x == n_y else f"pc_dim_x = {n_x}, pc_dim_y = {n_y}"
        keys = "pc_dim_xy" if n_x == n_y else "pc_dim_x / pc_dim_y"
        raise ConfigError(
            f"{size}, pc_dim_th = {th}: the pose-cell network needs about "
            f"{_size(need)}, more than this machine's {_size(memory_bytes)}; lower {keys}"
        )
    tx, ty = int(flat["template_x_size"]), int(flat["template_y_size"])
    one = tx * ty * 8 * 4  # one template and the working copies of a comparison
    if memory_bytes and one > memory_bytes:
        raise ConfigError(
            f"template_x_size = {tx}, template_y_size = {ty}: one template needs about "
            f"{_size(one)}, more than this machine's {_size(memory_bytes)}; lower them"
        )


def _size(n: float) -> str:
    n = float(n) if n < 1e300 else float("inf")
    for unit in ("B", "KB", "MB", "GB", "TB", "PB"):
        if n < 1000 or unit == "PB":
            return f"{n:.3g} {unit}"
        n /= 1000
    return f"{n:.3g} PB"  # pragma: no cover


def _physical_memory() -> int:
    import os

    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 0
