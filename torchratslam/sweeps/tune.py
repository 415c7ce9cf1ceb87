"""Automatic tuning with Optuna: search parameters within ranges to minimise a metric.

The objective of a trial is the mean of ``metric`` (``ate_m`` by default) over the
datasets and seeds, plus ``map_penalty`` times the mean number of experiences when
asked; ``max_experiences`` is a constraint (Optuna's ``constraints_func``: trials above
it are infeasible and never chosen as the best). A failed run makes its trial fail.

Trials are asked in rounds of ``workers``, evaluated by the sweep executors (local
process pool or Ray; runs of a round that differ only in pose-cell module parameters
share one batched network) and told back. The study lives in an Optuna storage (a
journal file by default, ``sqlite:///...`` too), so an interrupted study resumes and
several processes can work on one study at once (each stops when the study has
``trials`` finished trials).

Outputs in ``out``: ``best.yaml`` (the base config with the best values: a ready config
for ``torchratslam run --config``), ``history.csv`` (one row per trial: number, state,
value, parameters, metrics), ``optimization_history.png`` and
``param_importances.png`` (``optuna.visualization.matplotlib``).
"""

from __future__ import annotations

import logging
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from ratslam_graph.io import atomic_write_text
from ratslam_graph.out_checks import check_out_dir
from torchratslam.config import load_config
from torchratslam.errors import ConfigError, InputError, option
from torchratslam.sweeps.executors import Executor, make_executor
from torchratslam.sweeps.runner import METRICS
from torchratslam.sweeps.spec import RunSpec, run_id, with_seed
from torchratslam.sweeps.sweep import Progress, make_units
from torchratslam.sweeps.table import csv_text

__all__ = ["DEFAULT_SPACE", "Range", "parse_range", "tune"]

log = logging.getLogger(__name__)

DEFAULT_DATA = "sim:loop"
DEFAULT_SPACE = {
    "vt_match_threshold": "0.02:0.12",
    "pc_vt_inject_energy": "0.02:0.5:log",
    "exp_delta_pc_threshold": "1.0:6.0",
    "vt_active_decay": "0.5:3.0",
}
"""Searched when no parameters are given: the match threshold, the injection energy,
the experience threshold and the template decay."""


@dataclass(frozen=True)
class Range:
    """A searched parameter: ``low..high`` (``log`` spacing, ``integer``), or a list
    of ``choices``."""

    key: str
    low: float = 0.0
    high: float = 0.0
    log: bool = False
    integer: bool = False
    choices: tuple[Any, ...] = ()

    def suggest(self, trial: Any) -> Any:
        if self.choices:
            return trial.suggest_categorical(self.key, list(self.choices))
        if self.integer:
            return trial.suggest_int(self.key, int(self.low), int(self.high), log=self.log)
        return trial.suggest_float(self.key, self.low, self.high, log=self.log)


def parse_range(key: str, spec: Any) -> Range:
    """``"LOW:HIGH[:log][:int]"``, ``"a,b,c"`` (choices), ``[low, high]``, a list of
    choices, or ``{low, high, log, int}``.

    Raises:
        ConfigError: malformed, or low >= high, or log with low <= 0.
    """
    where = f"search range of {key!r}"
    if isinstance(spec, Mapping):
        low, high = spec.get("low"), spec.get("high")
        flags = {k for k in ("log", "int") if spec.get(k)}
    elif (
        isinstance(spec, (list, tuple))
        and len(spec) == 2
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in spec)
    ):
        low, high = spec
        flags = set()
    elif isinstance(spec, (list, tuple)):
        if not spec:
            raise ConfigError(f"{where}: no choices")
        return Range(key, choices=tuple(spec))
    elif isinstance(spec, str) and ":" in spec:
        parts = spec.split(":")
        low, high = parts[0], parts[1]
        flags = {p.strip().lower() for p in parts[2:]}
        if flags - {"log", "int"}:
            raise ConfigError(
                f"{where}: unknown flag(s) {sorted(flags - {'log', 'int'})} in {spec!r}"
            )
    elif isinstance(spec, str) and "," in spec:
        return Range(key, choices=tuple(yaml.safe_load(v.strip()) for v in spec.split(",")))
    else:
        raise ConfigError(
            f"{where}: write LOW:HIGH[:log][:int] or a,b,c, e.g. {key}=0.01:0.1, got {spec!r}"
        )
    try:
        lo, hi = float(low), float(high)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: low and high must be numbers, got {low!r}, {high!r}") from None
    if not lo < hi:
        raise ConfigError(f"{where}: low must be below high, got {lo} and {hi}")
    if "log" in flags and lo <= 0:
        raise ConfigError(f"{where}: log spacing needs low > 0, got {lo}")
    return Range(key, lo, hi, log="log" in flags, integer="int" in flags)


def _optuna() -> Any:
    try:
        import optuna
    except ImportError:
        raise ConfigError(
            "tuning needs Optuna; pip install 'torchratslam[tune]' (or pip install optuna)"
        ) from None
    return optuna


def _storage(optuna: Any, storage: str | None, out: Path | None) -> Any:
    if storage is None:
        if out is None:
            return None  # in memory
        storage = str(out / "study.journal")
    if "://" in storage:
        return storage  # an RDB URL, e.g. sqlite:///study.db
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    Path(storage).parent.mkdir(parents=True, exist_ok=True)
    return JournalStorage(JournalFileBackend(str(storage)))


def _objective(rows: Sequence[dict[str, Any]], metric: str, map_penalty: float) -> float:
    vals = [float(r.get(metric, math.nan)) for r in rows]
    value = sum(vals) / len(vals)
    if map_penalty:
        exps = [float(r.get("experiences", math.nan)) for r in rows]
        value += map_penalty * sum(exps) / len(exps)
    return value


def _sampler(optuna: Any, seed: int, constrained: dict[str, Any]) -> Any:
    with warnings.catch_warnings():  # Optuna 5 prefers Trial.set_constraint; both work
        warnings.simplefilter("ignore", FutureWarning)
        return optuna.samplers.TPESampler(seed=seed, **constrained)


def _constraint(trial: Any) -> Sequence[float]:
    return trial.user_attrs.get("constraint", (0.0,))


def _set_constraint(trial: Any, value: float) -> None:
    """Record ``value`` (<= 0: feasible) where the sampler reads it."""
    trial.set_user_attr("constraint", (value,))


def tune(
    data: str | Sequence[str] = DEFAULT_DATA,
    params: Mapping[str, Any] | None = None,
    *,
    config: str | None = "virtual_tour",
    fixed: Mapping[str, Any] | None = None,
    metric: str = "ate_m",
    trials: int = 20,
    max_frames: int | None = None,
    seeds: Sequence[int] = (0,),
    map_penalty: float = 0.0,
    max_experiences: int | None = None,
    out: str | Path | None = None,
    storage: str | None = None,
    study_name: str = "torchratslam",
    resume: bool = False,
    baseline: bool = True,
    sampler_seed: int = 0,
    workers: int | None = None,
    ray: bool = False,
    ray_address: str | None = None,
    progress: bool = False,
    executor: Executor | None = None,
) -> dict[str, Any]:
    """Search ``params`` within their ranges to minimise ``metric`` (module docstring).

    Args:
        data: one dataset spec or several (default ``sim:loop``, the loop tour).
        params: key -> range (:func:`parse_range`); default :data:`DEFAULT_SPACE`.
        config: the base config (preset name or path).
        fixed: keys set in every trial.
        metric: a metric column of the results table, minimised.
        trials: finished trials the study should have.
        max_frames: frame limit per dataset.
        seeds: simulator seeds; the objective averages over them.
        map_penalty: added per experience (metric units per experience).
        max_experiences: constraint on the mean number of experiences.
        out: output folder (default storage, best.yaml, history.csv, plots).
        storage: an Optuna storage URL or a journal file path (default
            ``out/study.journal``; in memory when ``out`` is None).
        study_name: the study's name in the storage.
        resume: continue a study that already has trials (else that is an error).
        baseline: make trial 0 the base config's own values (when inside the ranges),
            so the study reports how much it improved on it.
        sampler_seed: seed of the TPE sampler (with ``resume``, the sampler is seeded
            from this, the trial count and the process id, so that processes sharing a
            study explore different values).
        workers, ray, ray_address, executor: where trials run (as :func:`sweep`).
        progress: show the progress bar with the best value so far.

    Returns:
        ``{"best_value", "best_params", "best_trial", "best_config" (flat dict),
        "baseline_value" (trial 0's when ``baseline``), "trials" (count), "history"
        (rows), "study"}``.

    Raises:
        ConfigError: Optuna missing, bad ranges, unknown keys or metric.
        InputError: an existing study without ``resume``.
    """
    datasets = [data] if isinstance(data, str) else list(data)
    if not datasets:
        raise ConfigError("tune: give at least one dataset, e.g. sim:loop")
    if metric not in METRICS or metric in ("batch", "ate_frames"):
        valid = ", ".join(m for m in METRICS if m not in ("batch", "ate_frames"))
        raise ConfigError(f"tune: unknown metric {metric!r} (valid: {valid})")
    if trials < 1:
        raise ConfigError(f"tune: trials must be >= 1, got {trials}")
    if out is not None:  # new, empty, or a study's own (its storage says resume or not)
        check_out_dir(out, what="tuning study", marks=("study.journal", "history.csv"))
    space = [parse_range(k, v) for k, v in (params or DEFAULT_SPACE).items()]
    fixed = dict(fixed or {})
    base = load_config(config, **fixed)
    for r in space:  # unknown keys and out-of-range bounds fail before any run
        probe = r.choices or ((int(r.low), int(r.high)) if r.integer else (r.low, r.high))
        for v in probe:
            try:
                base.replace(**{r.key: v})
            except ConfigError as exc:
                raise ConfigError(f"tune: {r.key}={v!r}: {exc}") from None
    optuna = _optuna()  # after the arguments: bad input is reported first
    out_dir = Path(out) if out is not None else None
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    constrained = {} if max_experiences is None else {"constraints_func": _constraint}
    sampler = _sampler(optuna, sampler_seed, constrained)
    study = optuna.create_study(
        study_name=study_name,
        storage=_storage(optuna, storage, out_dir),
        sampler=sampler,
        direction="minimize",
        load_if_exists=True,
    )
    finished_states = (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.FAIL)
    n_done = sum(1 for t in study.trials if t.state in finished_states)
    if n_done and not resume:
        raise InputError(
            f"study {study_name!r} already has {n_done} trials in its storage; pass "
            f"{option('--resume', 'resume=True')} to continue it, or choose another out / "
            "study name"
        )
    if resume:  # resuming or joining: a seed of its own, or processes sharing the
        # study would suggest the same values (a new study keeps `sampler_seed`)
        import os

        study.sampler = _sampler(
            optuna, hash((sampler_seed, len(study.trials), os.getpid())) % 2**31, constrained
        )
    # trials left RUNNING by a killed process stay so; the study just asks new ones
    if baseline and not study.trials:  # trial 0: the base config itself, for comparison
        flat = base.to_flat()
        start = {r.key: flat[r.key] for r in space}
        if all(_inside(r, v) for r, v in zip(space, start.values())):
            study.enqueue_trial(start, user_attrs={"baseline": True})
    own_executor = executor is None
    if executor is None:
        import os

        n = workers or min(os.cpu_count() or 1, trials)
        executor = make_executor(workers=n, ray=ray, ray_address=ray_address)
    bar = Progress(trials, min(n_done, trials), enabled=progress, desc="tune", unit="trial")
    try:
        while True:
            n_done = sum(1 for t in study.trials if t.state in finished_states)
            left = trials - n_done
            if left <= 0:
                break
            batch = [study.ask() for _ in range(min(executor.workers, left))]
            runs: dict[int, list[RunSpec]] = {}
            index = 0
            for trial in batch:
                values = {r.key: r.suggest(trial) for r in space}
                overrides = {**fixed, **values}
                runs[trial.number] = []
                for ds in datasets:
                    for seed in seeds:
                        settings = {
                            "base": config,
                            "overrides": overrides,
                            "data": ds,
                            "max_frames": max_frames,
                            "seed": seed,
                        }
                        runs[trial.number].append(
                            RunSpec(
                                index,
                                run_id(settings),
                                config,
                                overrides,
                                values,
                                with_seed(ds, seed),
                                ds,
                                max_frames,
                                seed,
                                None,
                            )
                        )
                        index += 1
            all_runs = [r for rs in runs.values() for r in rs]
            rows: dict[str, dict[str, Any]] = {}
            units = make_units(all_runs, executor.workers)
            bar.start(len(batch))
            for _unit, unit_rows in executor.map(units, lambda u: None):
                for row in unit_rows:
                    rows[str(row["run_id"])] = row
            for trial in batch:
                trows = [rows[r.run_id] for r in runs[trial.number]]
                failed = [r for r in trows if r.get("status") != "ok"]
                for key in TRIAL_MEANS:
                    vals = [float(r.get(key, math.nan)) for r in trows]
                    trial.set_user_attr(key, sum(vals) / len(vals))
                # the ATEs' frames: every run's frames with ground truth, summed
                trial.set_user_attr("ate_frames", sum(int(r.get("ate_frames", 0)) for r in trows))
                value = math.nan if failed else _objective(trows, metric, map_penalty)
                if failed or not math.isfinite(value):
                    msg = failed[0].get("error", "") if failed else f"{metric} is not finite"
                    trial.set_user_attr("error", str(msg))
                    study.tell(trial, state=optuna.trial.TrialState.FAIL)
                    bar.finish(1, 1)
                    continue
                if max_experiences is not None:
                    exps = trial.user_attrs["experiences"]
                    _set_constraint(trial, float(exps - max_experiences))
                study.tell(trial, value)
                best = _best(study, optuna)
                bar.finish(1, 0, None if best is None else f"{best.value:.4g}")
    finally:
        bar.close()
        if own_executor:
            executor.close()
    best = _best(study, optuna)
    history = _history(study, space)
    result: dict[str, Any] = {
        "best_value": None if best is None else best.value,
        "best_params": {} if best is None else dict(best.params),
        "best_trial": None if best is None else best.number,
        "trials": len(history),
        "baseline_value": _baseline_value(study, optuna),
        "history": history,
        "study": study,
    }
    best_flat = None
    if best is not None:
        best_flat = base.replace(**best.params).to_flat()
    result["best_config"] = best_flat
    if out_dir is not None:
        cols = [
            "number",
            "state",
            "value",
            *[r.key for r in space],
            *TRIAL_MEANS,
            "ate_frames",
            "baseline",
            "error",
        ]
        atomic_write_text(out_dir / "history.csv", csv_text(history, cols))
        if best_flat is not None:
            atomic_write_text(
                out_dir / "best.yaml", _best_yaml(best_flat, best, config, metric, datasets)
            )
        _plots(study, out_dir, optuna, metric)
    return result


TRIAL_MEANS = ("experiences", "templates", "links", "ate_m", "dead_reckoning_ate_m", "wall_s")
"""What a trial records of its runs (datasets x seeds): their means. Beside them
``ate_frames``, the frames with ground truth the runs' ATEs are over, summed."""


def _inside(r: Range, v: Any) -> bool:
    if r.choices:
        return v in r.choices
    return isinstance(v, (int, float)) and r.low <= float(v) <= r.high


def _baseline_value(study: Any, optuna: Any) -> float | None:
    for t in study.trials:
        if t.user_attrs.get("baseline") and t.state == optuna.trial.TrialState.COMPLETE:
            return float(t.value)
    return None


def _best(study: Any, optuna: Any) -> Any:
    """The best complete trial that satisfies the constraint."""
    done = [
        t
        for t in study.trials
        if t.state == optuna.trial.TrialState.COMPLETE
        and all(c <= 0 for c in t.user_attrs.get("constraint", (0.0,)))
    ]
    return min(done, key=lambda t: (t.value, t.number)) if done else None


def _history(study: Any, space: Sequence[Range]) -> list[dict[str, Any]]:
    rows = []
    for t in study.trials:
        row: dict[str, Any] = {
            "number": t.number,
            "state": t.state.name.lower(),
            "value": math.nan if t.value is None else float(t.value),
        }
        for r in space:
            row[r.key] = t.params.get(r.key, "")
        for k in TRIAL_MEANS:
            row[k] = t.user_attrs.get(k, math.nan)
        row["ate_frames"] = t.user_attrs.get("ate_frames", 0)
        row["baseline"] = bool(t.user_attrs.get("baseline", False))
        row["error"] = t.user_attrs.get("error", "")
        rows.append(row)
    return rows


def _best_yaml(
    flat: dict[str, Any], best: Any, config: str | None, metric: str, datasets: Sequence[str]
) -> str:
    values = ", ".join(
        f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={v}" for k, v in best.params.items()
    )
    head = {
        "description": f"tuned from {config or 'defaults'} by torchratslam tune: "
        f"{metric}={best.value:.6g} on {', '.join(datasets)} (trial {best.number}: {values})",
        "source": "torchratslam tune",
    }
    return yaml.safe_dump({**head, **flat}, sort_keys=False)


def _plots(study: Any, out: Path, optuna: Any, metric: str) -> None:
    import matplotlib

    matplotlib.use("Agg", force=False)
    from optuna.visualization import matplotlib as ovm

    from torchratslam.viz.plots import save_figure

    complete = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    if not complete:
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # optuna marks its matplotlib backend experimental
        ax = ovm.plot_optimization_history(study)
        from torchratslam.viz.sweeps import METRIC_LABELS

        ax.set_ylabel(f"objective: {METRIC_LABELS.get(metric, metric)}")
        vals = [t.value for t in complete if t.value is not None and t.value > 0]
        if vals and len(vals) == len(complete) and max(vals) > 20 * min(vals):
            ax.set_yscale("log")  # one bad trial would flatten the rest
        save_figure(ax.figure, out / "optimization_history.png")
        if len(complete) >= 2 and len(complete[0].params) >= 2:
            try:
                ax = ovm.plot_param_importances(study)
                ax.set_xlabel("importance for the objective (fANOVA, fraction)")
                save_figure(ax.figure, out / "param_importances.png")
            except (RuntimeError, ValueError, ZeroDivisionError) as exc:
                log.warning("no parameter-importance plot (%s)", exc)
