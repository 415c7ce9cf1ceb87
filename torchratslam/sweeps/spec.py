"""Sweep files: what to vary, on which data, with which seeds and backends.

A sweep file is YAML::

    base: virtual_tour            # a shipped preset name or a config path (relative
                                  # to the sweep file); default: OpenRatSLAM's defaults
    set:                          # fixed overrides of the base config (optional)
      exp_loops: 20
    mode: grid                    # grid (every combination, default) or list (zipped)
    parameters:                   # flat config keys and their values
      vt_match_threshold: [0.02, 0.03, 0.05]
      pc_vt_inject_energy: {start: 0.05, stop: 0.2, num: 4}   # linspace, inclusive
      exp_delta_pc_threshold: {values: [1.0, 2.0]}
    datasets:                     # strings or {data:, max_frames:}
      - sim:loop?laps=1
      - {data: sim:virtual_tour/session1, max_frames: 200}
    max_frames: 300               # default for datasets without their own (optional)
    seeds: [0, 1]                 # simulator seeds (sim:NAME?seed=S); default [0]
    backends: [alpha, gtsam]      # exp_backend values; default: the config's
    batch: true                   # share a batched pose-cell network (default true)

One *run* is one combination of parameter values x dataset x seed x backend. Runs are
numbered in a fixed order (datasets, then seeds, then backends, then parameter values,
last parameter fastest) and named by a short hash of their settings, so the same file
always gives the same runs with the same ids.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from torchratslam.config import RatSLAMConfig, load_config
from torchratslam.errors import ConfigError, InputError

__all__ = ["Dataset", "RunSpec", "SweepSpec", "expand", "load_sweep", "parse_values"]

KNOWN_KEYS = frozenset(
    {
        "base",
        "set",
        "mode",
        "parameters",
        "datasets",
        "max_frames",
        "seeds",
        "backends",
        "batch",
        "description",
    }
)
BACKENDS = ("alpha", "alpha_reference", "gtsam", "isam2")


@dataclass(frozen=True)
class Dataset:
    """A dataset of a sweep: a spec for :func:`torchratslam.readers.open_data` and a
    frame limit (None: every frame)."""

    data: str
    max_frames: int | None = None


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep.

    Attributes:
        index: position in the sweep's fixed order.
        run_id: short stable hash of the settings (the resume key).
        base: config preset name or path.
        overrides: flat config keys set for this run (fixed ``set`` and swept values).
        params: the swept keys and their values only (the table's parameter columns).
        data: dataset spec actually opened (with ``?seed=`` for simulator data).
        dataset: dataset spec as written in the sweep file.
        max_frames: frame limit.
        seed: the seed.
        backend: ``exp_backend`` (None: the config's).
    """

    index: int
    run_id: str
    base: str | None
    overrides: dict[str, Any]
    params: dict[str, Any]
    data: str
    dataset: str
    max_frames: int | None
    seed: int
    backend: str | None

    def config(self) -> RatSLAMConfig:
        """The run's validated config."""
        over = dict(self.overrides)
        if self.backend is not None:
            over["exp_backend"] = self.backend
        return load_config(self.base, **over)


@dataclass(frozen=True)
class SweepSpec:
    """A parsed sweep file (see the module docstring)."""

    base: str | None = None
    fixed: dict[str, Any] = field(default_factory=dict)
    parameters: dict[str, list[Any]] = field(default_factory=dict)
    mode: str = "grid"
    datasets: tuple[Dataset, ...] = (Dataset("sim:loop?laps=1", 300),)
    seeds: tuple[int, ...] = (0,)
    backends: tuple[str | None, ...] = (None,)
    batch: bool = True
    source: str = "sweep"

    def runs(self) -> list[RunSpec]:
        """Every run, in the sweep's fixed order."""
        return expand(self)


def parse_values(key: str, spec: Any, source: str = "sweep") -> list[Any]:
    """Values of one swept parameter: a list, ``{values: [...]}``, a scalar, or
    ``{start, stop, num}`` (inclusive linspace; ``log: true`` for geometric spacing;
    integers stay integers when start and stop are integers and the steps are whole).

    Raises:
        ConfigError: an empty or malformed value specification.
    """
    where = f"{source}: parameter {key!r}"
    if isinstance(spec, Mapping):
        if "values" in spec:
            return parse_values(key, spec["values"], source)
        missing = {"start", "stop", "num"} - set(spec)
        if missing:
            raise ConfigError(
                f"{where}: give a list, {{values: [...]}} or {{start, stop, num}} "
                f"(missing {', '.join(sorted(missing))})"
            )
        try:
            start, stop, num = float(spec["start"]), float(spec["stop"]), int(spec["num"])
        except (TypeError, ValueError):
            raise ConfigError(f"{where}: start, stop must be numbers and num an integer") from None
        if num < 1:
            raise ConfigError(f"{where}: num must be >= 1, got {num}")
        if num > MAX_RUNS:
            raise ConfigError(f"{where}: num = {num} values is more than a sweep runs ({MAX_RUNS})")
        log = bool(spec.get("log", False))
        if log and (start <= 0 or stop <= 0):
            raise ConfigError(f"{where}: log spacing needs start and stop > 0")
        if num == 1:
            vals = [start]
        elif log:
            ratio = (stop / start) ** (1.0 / (num - 1))
            vals = [start * ratio**i for i in range(num - 1)] + [stop]
        else:
            step = (stop - start) / (num - 1)
            vals = [start + step * i for i in range(num - 1)] + [stop]
        ints = isinstance(spec["start"], int) and isinstance(spec["stop"], int)
        if ints and all(float(v).is_integer() for v in vals):
            return [int(v) for v in vals]
        return [round(v, 12) for v in vals]
    if isinstance(spec, (list, tuple)):
        if not spec:
            raise ConfigError(f"{where}: the list of values is empty")
        return list(spec)
    if spec is None:
        raise ConfigError(f"{where}: no values given")
    return [spec]


def _datasets(raw: Any, default_frames: int | None, source: str) -> tuple[Dataset, ...]:
    if raw is None:
        return (Dataset("sim:loop?laps=1", default_frames or 300),)
    items = raw if isinstance(raw, list) else [raw]
    out = []
    for item in items:
        if isinstance(item, str):
            out.append(Dataset(item, default_frames))
        elif isinstance(item, Mapping) and "data" in item:
            mf = item.get("max_frames", default_frames)
            out.append(Dataset(str(item["data"]), None if mf is None else _frames(mf, source)))
        else:
            raise ConfigError(
                f"{source}: datasets: expected 'sim:NAME' strings or {{data:, max_frames:}} "
                f"entries, got {item!r}"
            )
    if not out:
        raise ConfigError(f"{source}: datasets is empty; name at least one, e.g. sim:loop")
    return tuple(out)


def _frames(value: Any, source: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ConfigError(f"{source}: max_frames must be a positive integer, got {value!r}")
    return int(value)


def from_dict(
    raw: Mapping[str, Any], *, source: str = "sweep", root: Path | None = None
) -> SweepSpec:
    """Build a :class:`SweepSpec` from the mapping of a sweep file.

    Args:
        raw: the file's mapping.
        source: name used in error messages.
        root: folder that relative ``base`` paths are resolved against.

    Raises:
        ConfigError: unknown keys, bad values, unknown config keys or backends.
    """
    if not isinstance(raw, Mapping):
        raise ConfigError(f"{source}: expected a mapping (base, parameters, datasets, ...)")
    unknown = sorted(set(raw) - KNOWN_KEYS)
    if unknown:
        raise ConfigError(
            f"{source}: unknown key(s) {', '.join(unknown)} "
            f"(valid: {', '.join(sorted(KNOWN_KEYS))})"
        )
    base = raw.get("base")
    if base is not None:
        base = str(base)
        if root is not None and (root / base).exists():
            base = str((root / base).resolve())
    fixed = dict(raw.get("set") or {})
    params_raw = raw.get("parameters") or {}
    if not isinstance(params_raw, Mapping):
        raise ConfigError(f"{source}: parameters must map config keys to values")
    parameters = {str(k): parse_values(str(k), v, source) for k, v in params_raw.items()}
    mode = str(raw.get("mode", "grid"))
    if mode not in ("grid", "list"):
        raise ConfigError(f"{source}: mode must be 'grid' or 'list', got {mode!r}")
    if mode == "list" and len({len(v) for v in parameters.values()}) > 1:
        sizes = ", ".join(f"{k}: {len(v)}" for k, v in parameters.items())
        raise ConfigError(f"{source}: mode 'list' needs equally long value lists ({sizes})")
    mf = raw.get("max_frames")
    default_frames = None if mf is None else _frames(mf, source)
    datasets = _datasets(raw.get("datasets"), default_frames, source)
    seeds_raw = raw.get("seeds", [0])
    seeds_list = seeds_raw if isinstance(seeds_raw, list) else [seeds_raw]
    if not seeds_list or any(isinstance(s, bool) or not isinstance(s, int) for s in seeds_list):
        raise ConfigError(f"{source}: seeds must be a list of integers, got {seeds_raw!r}")
    backends_raw = raw.get("backends")
    if backends_raw is None:
        backends: tuple[str | None, ...] = (None,)
    else:
        blist = backends_raw if isinstance(backends_raw, list) else [backends_raw]
        bad = [b for b in blist if b not in BACKENDS]
        if bad or not blist:
            raise ConfigError(
                f"{source}: unknown backend(s) {bad or blist} (valid: {', '.join(BACKENDS)})"
            )
        backends = tuple(str(b) for b in blist)
    _check_size(parameters, mode, len(datasets) * len(seeds_list) * len(backends), source)
    spec = SweepSpec(
        base=base,
        fixed=fixed,
        parameters=parameters,
        mode=mode,
        datasets=datasets,
        seeds=tuple(int(s) for s in seeds_list),
        backends=backends,
        batch=bool(raw.get("batch", True)),
        source=source,
    )
    _validate(spec)
    return spec


# A sweep of more runs than this is refused at once (before any config is read).
MAX_RUNS = 100_000


def _check_size(parameters: dict[str, Any], mode: str, per_combination: int, source: str) -> None:
    """Refuse a sweep of more than MAX_RUNS runs, counted without expanding it."""
    sizes = [len(v) for v in parameters.values()]
    combos = (min(sizes) if mode == "list" else math.prod(sizes)) if sizes else 1
    total = combos * per_combination
    if total > MAX_RUNS:
        raise ConfigError(
            f"{source}: {total:.3g} runs ({' x '.join(map(str, sizes))} values"
            f"{f' x {per_combination} datasets/seeds/backends' if per_combination > 1 else ''}"
            f"); a sweep runs at most {MAX_RUNS}: use fewer values"
        )


def _validate(spec: SweepSpec) -> None:
    """Check every swept key and value against the config (before any run starts)."""
    owner = RatSLAMConfig.key_owner()
    for key in [*spec.fixed, *spec.parameters]:
        if key not in owner:
            from ratslam_graph.errors import unknown_name_message

            raise ConfigError(f"{spec.source}: " + unknown_name_message("parameter", key, owner))
    base = load_config(spec.base, **spec.fixed)
    for key, values in spec.parameters.items():
        for v in values:
            try:
                base.replace(**{key: v})
            except ConfigError as exc:
                raise ConfigError(f"{spec.source}: parameter {key!r} value {v!r}: {exc}") from None


def load_sweep(path: str | Path) -> SweepSpec:
    """Read and validate a sweep file.

    Raises:
        InputError: the file does not exist.
        ConfigError: not valid YAML or not a valid sweep (see :func:`from_dict`).
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"sweep file {str(path)!r} not found")
    from torchratslam.config import read_yaml_unique

    raw = read_yaml_unique(p)  # a key given twice is refused, as in a config
    if raw is None:
        raise ConfigError(
            f"{p}: holds no sweep (an empty file); give at least base, datasets and parameters"
        )
    return from_dict(raw, source=str(p), root=p.parent)


def with_seed(data: str, seed: int) -> str:
    """The dataset spec with the seed applied (``sim:`` specs only; others unchanged)."""
    if not data.startswith("sim:") or "seed=" in data:
        return data
    return f"{data}{'&' if '?' in data else '?'}seed={int(seed)}"


def run_id(settings: Mapping[str, Any]) -> str:
    """A short stable hash of a run's settings (JSON with sorted keys)."""
    text = json.dumps(settings, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def _combinations(spec: SweepSpec) -> list[dict[str, Any]]:
    keys = list(spec.parameters)
    if not keys:
        return [{}]
    if spec.mode == "list":
        return [dict(zip(keys, vals)) for vals in zip(*spec.parameters.values())]
    return [dict(zip(keys, vals)) for vals in itertools.product(*spec.parameters.values())]


def expand(spec: SweepSpec) -> list[RunSpec]:
    """Every run of a sweep, in its fixed order (see the module docstring)."""
    runs: list[RunSpec] = []
    for ds in spec.datasets:
        for seed in spec.seeds:
            for backend in spec.backends:
                for combo in _combinations(spec):
                    overrides = {**spec.fixed, **combo}
                    settings = {
                        "base": spec.base,
                        "overrides": overrides,
                        "data": ds.data,
                        "max_frames": ds.max_frames,
                        "seed": seed,
                        "backend": backend,
                    }
                    runs.append(
                        RunSpec(
                            index=len(runs),
                            run_id=run_id(settings),
                            base=spec.base,
                            overrides=overrides,
                            params=dict(combo),
                            data=with_seed(ds.data, seed),
                            dataset=ds.data,
                            max_frames=ds.max_frames,
                            seed=seed,
                            backend=backend,
                        )
                    )
    return runs
