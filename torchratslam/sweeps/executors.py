"""Where the runs execute: in this process, a local process pool, or a Ray cluster.

Every executor takes *units* (lists of runs that share one batched pose-cell network;
most units hold one run) and yields ``(unit, rows)`` as units finish, in any order.
Each worker runs torch with one thread (``TORCHRATSLAM_THREADS``, default 1): a
sweep's parallelism is across runs.
"""

from __future__ import annotations

import logging
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from torchratslam.errors import ConfigError, RatSLAMError, option
from torchratslam.sweeps.runner import run_group_safely
from torchratslam.sweeps.spec import RunSpec

__all__ = ["Executor", "LocalExecutor", "RayExecutor", "SerialExecutor", "make_executor"]

log = logging.getLogger(__name__)

Unit = list[RunSpec]
Result = tuple[Unit, list[dict[str, Any]]]


def _threads() -> int:
    try:
        return max(1, int(os.environ.get("TORCHRATSLAM_THREADS", "1")))
    except ValueError:
        return 1


def _worker_init(threads: int) -> None:
    import torch

    torch.set_num_threads(threads)
    logging.disable(logging.WARNING)  # a worker reports through its results, not its log


def _run_unit(unit: Unit, threads: int = 1) -> list[dict[str, Any]]:
    import torch

    if torch.get_num_threads() != threads:
        torch.set_num_threads(threads)
    return run_group_safely(unit)


class Executor:
    """Base class: ``workers`` units run at a time."""

    workers: int = 1
    name: str = "serial"

    def map(self, units: Sequence[Unit], on_start: Callable[[Unit], None]) -> Iterator[Result]:
        raise NotImplementedError

    def close(self) -> None:
        """Release the executor's resources."""


class SerialExecutor(Executor):
    """Every unit in this process, one after the other."""

    def map(self, units: Sequence[Unit], on_start: Callable[[Unit], None]) -> Iterator[Result]:
        for unit in units:
            on_start(unit)
            yield unit, _run_unit(unit, _threads())


class LocalExecutor(Executor):
    """A pool of ``workers`` processes on this machine (default: every core)."""

    name = "local"

    def __init__(self, workers: int | None = None) -> None:
        self.workers = int(workers or os.cpu_count() or 1)
        if self.workers < 1:
            raise ConfigError(f"workers must be >= 1, got {workers}")
        self._pool: Any = None

    def _get_pool(self) -> Any:
        if self._pool is None:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor

            method = "forkserver" if sys.platform.startswith("linux") else "spawn"
            ctx = mp.get_context(method)
            if method == "forkserver":  # workers fork from a server that imported these
                ctx.set_forkserver_preload(["torch", "torchratslam.sweeps.executors"])
            self._pool = ProcessPoolExecutor(
                max_workers=self.workers,
                mp_context=ctx,
                initializer=_worker_init,
                initargs=(_threads(),),
            )
        return self._pool

    def map(self, units: Sequence[Unit], on_start: Callable[[Unit], None]) -> Iterator[Result]:
        from concurrent.futures import FIRST_COMPLETED, wait
        from concurrent.futures.process import BrokenProcessPool

        pool = self._get_pool()
        threads = _threads()
        pending = list(units)
        running: dict[Any, Unit] = {}
        try:
            while pending or running:
                while pending and len(running) < self.workers:
                    unit = pending.pop(0)
                    running[pool.submit(_run_unit, unit, threads)] = unit
                    on_start(unit)
                done, _ = wait(list(running), return_when=FIRST_COMPLETED)
                for fut in done:
                    unit = running.pop(fut)
                    try:
                        rows = fut.result()
                    except BrokenProcessPool:
                        self._pool = None
                        raise RatSLAMError(
                            "a sweep worker process died (out of memory or killed); the "
                            "finished runs are in the table: run again with "
                            f"{option('--resume', 'resume=True')}, perhaps with fewer "
                            f"{option('--workers', 'workers')}"
                        ) from None
                    yield unit, rows
        finally:
            for fut in running:
                fut.cancel()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


class RayExecutor(Executor):
    """Ray tasks, one CPU each: on the cluster at ``address`` (``"auto"``: the one this
    machine belongs to), or on Ray's own local cluster when ``address`` is None."""

    name = "ray"

    def __init__(self, address: str | None = None, workers: int | None = None) -> None:
        try:
            import ray
        except ImportError:
            raise ConfigError(
                "Ray is not installed; pip install 'torchratslam[ray]' (or drop "
                f"{option('--ray', 'ray=True')})"
            ) from None
        self._ray = ray
        self._started = False
        if not ray.is_initialized():
            # the thread count travels with each task (no runtime_env: it slows the start)
            kwargs: dict[str, Any] = {"log_to_driver": False, "logging_level": logging.ERROR}
            if address is None:
                kwargs.update(
                    num_cpus=workers or os.cpu_count() or 1,
                    include_dashboard=False,
                    object_store_memory=100 * 1024 * 1024,
                )
            else:
                kwargs["address"] = address
            ray.init(**kwargs)
            self._started = True
        self.workers = int(workers or ray.cluster_resources().get("CPU", 1))
        self._task = ray.remote(num_cpus=1, max_retries=0)(_run_unit)

    def map(self, units: Sequence[Unit], on_start: Callable[[Unit], None]) -> Iterator[Result]:
        ray = self._ray
        threads = _threads()
        pending = list(units)
        running: dict[Any, Unit] = {}
        while pending or running:
            while pending and len(running) < self.workers:
                unit = pending.pop(0)
                running[self._task.remote(unit, threads)] = unit
                on_start(unit)
            done, _ = ray.wait(list(running), num_returns=1)
            for ref in done:
                unit = running.pop(ref)
                yield unit, ray.get(ref)

    def close(self) -> None:
        if self._started:
            self._ray.shutdown()
            self._started = False


def make_executor(
    *, workers: int | None = None, ray: bool = False, ray_address: str | None = None
) -> Executor:
    """The executor for a sweep: Ray when ``ray`` or ``ray_address`` is given, else a
    local pool (in this process when ``workers == 1``)."""
    if ray or ray_address:
        return RayExecutor(ray_address, workers)
    if workers is not None and int(workers) == 1:
        return SerialExecutor()
    return LocalExecutor(workers)
