"""The pipelined mode: three worker threads joined by bounded queues.

The reader + odometry + local view, the pose cells and the experience map each run in
their own thread (queues of :data:`QUEUE_SIZE`, as in xRatSLAM). Each stage still sees
exactly the same messages in the same order as in the sequential mode, so the map is
identical; the caller's thread finishes each frame in order.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Iterable, Iterator
from typing import Any

import torch

from torchratslam.messages import Frame

__all__ = ["QUEUE_SIZE", "run_pipelined"]

QUEUE_SIZE = 10
"""Capacity of the queues between the pipelined mode's worker threads (xRatSLAM's)."""

_STOP = object()


def run_pipelined(
    frames: Iterator[Frame],
    start: int,
    view_work: Callable[[tuple[int, Frame]], tuple],
    pc_work: Callable[[tuple], tuple],
    em_work: Callable[[tuple], tuple],
    finish: Callable[[tuple], None],
) -> None:
    """Run the three stages over ``frames`` in worker threads.

    Args:
        frames: the frames, in order.
        start: the index of the first frame.
        view_work: ``(index, frame) -> item``: odometry and local view.
        pc_work: ``item -> item``: the pose cells.
        em_work: ``item -> item``: the experience map.
        finish: called in the caller's thread with each finished item, in order.

    Raises:
        BaseException: the first error of a worker (every stage stops).
    """
    q_view: queue.Queue = queue.Queue(QUEUE_SIZE)
    q_pc: queue.Queue = queue.Queue(QUEUE_SIZE)
    q_out: queue.Queue = queue.Queue(QUEUE_SIZE)
    stop = threading.Event()
    errors: list[BaseException] = []

    def put(q: queue.Queue, item: Any) -> None:
        while True:
            try:
                q.put(item, timeout=0.05)
                return
            except queue.Full:
                if stop.is_set():
                    return

    def get(q: queue.Queue) -> Any:
        while True:
            try:
                return q.get(timeout=0.05)
            except queue.Empty:
                if stop.is_set():
                    return _STOP

    # OpenMP's thread count is per thread: give the workers the caller's setting
    # (else each worker's torch ops would use every core and oversubscribe)
    n_threads = torch.get_num_threads()

    def drain(q: queue.Queue) -> Iterator[Any]:
        while (item := get(q)) is not _STOP:
            yield item

    def stage(source: Iterable[Any], out: queue.Queue, work: Callable[[Any], Any]) -> Any:
        """A worker: ``work`` on every item of ``source`` into ``out``, then _STOP;
        an error stops every stage and is re-raised by the caller."""

        def run() -> None:
            torch.set_num_threads(n_threads)
            try:
                for item in source:
                    if stop.is_set():
                        break
                    put(out, work(item))
            except BaseException as exc:
                errors.append(exc)
                stop.set()
            finally:
                put(out, _STOP)

        return run

    stages = {
        "view": stage(((start + i, f) for i, f in enumerate(frames)), q_view, view_work),
        "pose_cells": stage(drain(q_view), q_pc, pc_work),
        "experience_map": stage(drain(q_pc), q_out, em_work),
    }
    workers = [
        threading.Thread(target=run, name=f"ratslam-{name}", daemon=True)
        for name, run in stages.items()
    ]
    for w in workers:
        w.start()
    try:
        while (item := get(q_out)) is not _STOP:
            finish(item)
    except BaseException:
        stop.set()
        raise
    finally:
        for w in workers:
            w.join()
    if errors:
        raise errors[0]
