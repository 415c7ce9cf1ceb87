"""Run a sweep: expand it, skip finished runs when resuming, execute the rest, write
the results table after every finished unit, then the figures.

A sweep never drops results it did not make again: an out folder whose table holds a
stopped sweep (some of this sweep's runs) or another sweep's runs is refused unless
``resume`` (keep them, run the others) or ``overwrite`` (start again) is given."""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ratslam_graph.out_checks import check_out_dir
from torchratslam.errors import InputError, option
from torchratslam.sweeps.executors import Executor, make_executor
from torchratslam.sweeps.runner import batch_key
from torchratslam.sweeps.spec import RunSpec, SweepSpec, from_dict, load_sweep
from torchratslam.sweeps.table import columns, read_table, to_frame, write_table

OVERWRITE = option("--overwrite", "overwrite=True")
RESUME = option("--resume", "resume=True")

__all__ = ["Progress", "make_units", "sweep"]

log = logging.getLogger(__name__)

TABLE = "results.csv"


def make_units(runs: list[RunSpec], workers: int, batch: bool = True) -> list[list[RunSpec]]:
    """Group runs that can share a batched pose-cell network (:func:`batch_key`) into
    units, split so that every worker gets work, in the sweep's order."""
    if not batch or len(runs) < 2:
        return [[r] for r in runs]
    groups: dict[Any, list[RunSpec]] = {}
    singles: list[list[RunSpec]] = []
    for r in runs:
        key = batch_key(r)
        if key is None:
            singles.append([r])
        else:
            groups.setdefault(key, []).append(r)
    cap = max(1, math.ceil(len(runs) / max(workers, 1)))
    units = list(singles)
    for g in groups.values():
        n = math.ceil(len(g) / cap)
        size = math.ceil(len(g) / n)
        units += [g[i : i + size] for i in range(0, len(g), size)]
    return sorted(units, key=lambda u: u[0].index)


class Progress:
    """One overall bar: runs done (with ETA), running and failed; ``best`` for studies."""

    def __init__(
        self,
        total: int,
        done: int = 0,
        *,
        enabled: bool = True,
        desc: str = "sweep",
        unit: str = "run",
    ):
        self.running = 0
        self.failed = 0
        self.best: str | None = None
        self.bar = None
        if enabled:
            from tqdm import tqdm

            self.bar = tqdm(
                total=total, initial=done, unit=unit, desc=desc, dynamic_ncols=True, smoothing=0.1
            )

    def _post(self) -> None:
        if self.bar is not None:
            post: dict[str, Any] = {"running": self.running, "failed": self.failed}
            if self.best is not None:
                post["best"] = self.best
            self.bar.set_postfix(post, refresh=True)

    def start(self, n: int) -> None:
        self.running += n
        self._post()

    def finish(self, n: int, failed: int, best: str | None = None) -> None:
        self.running -= n
        self.failed += failed
        if best is not None:
            self.best = best
        if self.bar is not None:
            self.bar.update(n)
        self._post()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _check_replaceable(table: Path, runs: list[RunSpec]) -> None:
    """A table is never replaced without ``overwrite``.

    Raises:
        InputError: always: it holds this sweep finished, a stopped sweep, another
            sweep's runs, or is no table (each said, with what to do).
    """
    try:
        rows = read_table(table)
    except InputError as exc:
        raise InputError(f"{exc}; refusing to replace it: choose another out folder") from None
    wanted = {r.run_id for r in runs}
    have = {str(row.get("run_id")) for row in rows}
    if have - wanted:
        raise InputError(
            f"{table} holds {len(have - wanted)} runs of another sweep; choose another out "
            f"folder, or start again with {OVERWRITE} to replace it"
        )
    if len(have) < len(wanted):
        raise InputError(
            f"{table} holds {len(have)} of this sweep's {len(wanted)} runs (a stopped "
            f"sweep); continue it with {RESUME}, or start again with {OVERWRITE}"
        )
    raise InputError(
        f"{table} holds this sweep, finished; choose another out folder, or run it again "
        f"with {OVERWRITE}"
    )


def _spec(sweep_file: str | Path | SweepSpec | Mapping[str, Any]) -> SweepSpec:
    if isinstance(sweep_file, SweepSpec):
        return sweep_file
    if isinstance(sweep_file, Mapping):
        return from_dict(sweep_file, source="sweep()")
    return load_sweep(sweep_file)


def sweep(
    sweep_file: str | Path | SweepSpec | Mapping[str, Any],
    out: str | Path | None = None,
    *,
    workers: int | None = None,
    ray: bool = False,
    ray_address: str | None = None,
    resume: bool = False,
    retry_failed: bool = False,
    batch: bool | None = None,
    figures: bool = True,
    progress: bool = False,
    executor: Executor | None = None,
    overwrite: bool = False,
) -> Any:
    """Run every combination of a sweep and return the results table.

    Args:
        sweep_file: a sweep YAML path, its mapping, or a :class:`SweepSpec`
            (format in :mod:`torchratslam.sweeps.spec`).
        out: output folder: ``results.csv`` (and ``results.parquet`` with pyarrow),
            written after every finished run, and ``figures/``; None writes nothing.
        workers: processes (local) or concurrent tasks (Ray); default every core.
            ``workers=1`` runs in this process.
        ray: run on Ray's local cluster. ray_address: run on this Ray cluster.
        resume: keep the finished runs of ``out/results.csv`` and run only the others.
        retry_failed: with ``resume``, run the failed runs again too.
        batch: share a batched pose-cell network where possible (default: the file's
            ``batch``, true unless set).
        figures: draw the figures into ``out/figures``.
        progress: show the progress bar (one bar, labelled ``sweep``).
        executor: a ready executor (overrides workers / ray).
        overwrite: start again in an ``out`` whose table holds a stopped sweep or
            another sweep's runs (replacing ``results.csv``, nothing else).

    Returns:
        A pandas DataFrame when pandas is installed, else a list of dicts: one row per
        run in the sweep's order, columns of :func:`torchratslam.sweeps.table.columns`.

    Raises:
        InputError, ConfigError: a bad sweep file, ``resume`` with an unreadable table,
            or (without ``resume`` or ``overwrite``) a table in ``out`` holding a stopped
            sweep or another sweep's runs.
    """
    if out is not None:  # new, empty, or a sweep's own (whose table is judged below)
        check_out_dir(out, what="sweep", marks=(TABLE, "results.parquet"))
    spec = _spec(sweep_file)
    runs = spec.runs()
    cols = columns(list(spec.parameters))
    out_dir = Path(out) if out is not None else None
    table = out_dir / TABLE if out_dir is not None else None
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
    rows: dict[str, dict[str, Any]] = {}
    if resume and table is not None and table.exists():
        wanted = {r.run_id: r for r in runs}
        finished = read_table(table)
        others = {str(row.get("run_id")) for row in finished} - set(wanted)
        if others:
            raise InputError(
                f"{table} holds {len(others)} runs of another sweep, which resuming this "
                "one would drop; choose another out folder, or start again with "
                f"{OVERWRITE} to replace it"
            )
        for row in finished:
            rid = str(row.get("run_id"))
            if rid in wanted and (row.get("status") == "ok" or not retry_failed):
                row["index"] = wanted[rid].index
                rows[rid] = row
        log.info("resuming: %d of %d runs already finished", len(rows), len(runs))
    elif table is not None and table.exists() and not overwrite:
        _check_replaceable(table, runs)
    todo = [r for r in runs if r.run_id not in rows]
    own_executor = executor is None
    if executor is None:
        workers_n = workers
        if workers_n is None and not (ray or ray_address):
            import os

            workers_n = min(os.cpu_count() or 1, max(len(todo), 1))
        executor = make_executor(workers=workers_n, ray=ray, ray_address=ray_address)
    use_batch = spec.batch if batch is None else bool(batch)
    units = make_units(todo, executor.workers, use_batch)
    bar = Progress(len(runs), len(rows), enabled=progress)
    bar.failed = sum(1 for r in rows.values() if r.get("status") != "ok")
    t0 = time.perf_counter()
    try:
        for unit, unit_rows in executor.map(units, lambda u: bar.start(len(u))):
            for row in unit_rows:
                rows[str(row["run_id"])] = row
            failed = sum(1 for r in unit_rows if r.get("status") != "ok")
            bar.finish(len(unit), failed)
            if table is not None:
                write_table(table, list(rows.values()), cols, parquet=False)
    finally:
        bar.close()
        if own_executor:
            executor.close()
    log.info("sweep: %d runs in %.1f s", len(todo), time.perf_counter() - t0)
    if table is not None:
        write_table(table, list(rows.values()), cols)
    if out_dir is not None and figures:
        from torchratslam.viz.sweeps import plot_sweep

        plot_sweep(list(rows.values()), list(spec.parameters), out_dir / "figures")
    return to_frame(list(rows.values()), cols)
