"""What surrounds the per-frame work of :meth:`RatSLAM.run
<torchratslam.pipeline.ratslam.RatSLAM.run>`: the frames from what the caller gave
(:func:`open_frames`), the progress bar and callback (:class:`RunProgress`) and the
garbage collector parked for the run (:func:`parked_gc`).

The library shows a bar only when asked (``progress=True`` or a label) or, by default,
in an interactive notebook (an IPython kernel, :func:`in_notebook`); a script that
imports torchratslam and runs prints nothing."""

from __future__ import annotations

import gc
import itertools
from collections.abc import Callable, Iterator, Sized
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from torchratslam.errors import InputError
from torchratslam.messages import Frame
from torchratslam.pipeline.results import StepResult
from torchratslam.protocols import FrameSource

__all__ = ["RunProgress", "in_notebook", "open_frames", "parked_gc", "show_progress"]


def in_notebook() -> bool:
    """Whether this process is an IPython kernel (a Jupyter notebook), where a bar is
    shown by default."""
    import sys

    shell = sys.modules.get("IPython")
    if shell is None:
        return False
    try:
        ip = shell.get_ipython()
    except AttributeError:
        return False
    return ip is not None and "IPKernelApp" in getattr(ip, "config", {})


def show_progress(progress: bool | str | None) -> str | None:
    """The bar's label when a bar is to be shown, else None.

    Args:
        progress: True (a bar labelled ``frames``), a label (a bar with that label),
            False (none) or None (a bar only in a notebook, :func:`in_notebook`).
    """
    if progress is None:
        progress = in_notebook()
    if progress is False:
        return None
    return progress if isinstance(progress, str) and progress else "frames"


def open_frames(
    data: Any, max_frames: int | None = None
) -> tuple[Any, Iterator[Frame], int | None]:
    """What ``data`` names (itself, or the reader a data spec opens), its frames and how
    many there are (None: unknown).

    Args:
        data: a data spec (``str`` or :class:`~pathlib.Path`, opened with
            :func:`~torchratslam.readers.datasets.open_data`), a reader or simulator
            session (anything with ``frames()``), or an iterable of :class:`Frame`.
        max_frames: stop after this many frames.

    Raises:
        InputError: ``data`` is none of these, the spec names nothing readable, or
            ``max_frames`` is negative.
    """
    if isinstance(data, (str, Path)):
        from torchratslam.readers.datasets import open_data

        data = open_data(data)
    total = len(data) if isinstance(data, Sized) else None
    source = data.frames() if isinstance(data, FrameSource) else data
    try:
        it: Iterator[Frame] = iter(source)
    except TypeError:
        raise InputError(
            f"run() got a {type(data).__name__}; it expects a data spec (a str or Path "
            "that torchratslam.readers.datasets.open_data accepts, e.g. 'sim:loop'), a "
            "reader or simulator session (anything with frames()) or an iterable of Frame"
        ) from None
    if max_frames is not None:
        if max_frames < 0:
            raise InputError(f"max_frames must be >= 0, got {max_frames}")
        it = itertools.islice(it, max_frames)
        total = max_frames if total is None else min(total, max_frames)
    return data, it, total


class RunProgress:
    """Called with every :class:`StepResult` of a run, in order: counts them, calls the
    user's callback and updates a tqdm bar (labelled; frames/s, templates, experiences).

    Args:
        total: the number of frames expected (None: unknown).
        show: True or a label: show the bar (:func:`show_progress`); None: only in a
            notebook; False: none.
        callback: called with every result.

    Attributes:
        n: results seen so far.
    """

    def __init__(
        self,
        total: int | None,
        *,
        show: bool | str | None = None,
        callback: Callable[[StepResult], None] | None = None,
    ) -> None:
        self.total, self.callback, self.n = total, callback, 0
        self._bar = None
        label = show_progress(show)
        if label is not None:
            from tqdm import tqdm

            # smoothing: the ETA follows the recent rate, not the first frames' start-up
            self._bar = tqdm(
                total=total,
                desc=label,
                unit="frame",
                dynamic_ncols=True,
                mininterval=0.5,
                smoothing=0.05,
            )

    def __call__(self, r: StepResult) -> None:
        self.n += 1
        if self.callback is not None:
            self.callback(r)
        if self._bar is not None:
            self._bar.update(1)
            if self.n % 25 == 0 or self.n == self.total:
                self._bar.set_postfix(
                    templates=r.templates, experiences=r.experiences, refresh=False
                )

    def close(self) -> None:
        """Close the bar."""
        if self._bar is not None:
            self._bar.close()


@contextmanager
def parked_gc() -> Iterator[None]:
    """Park every object alive in the garbage collector's permanent generation for the
    duration (only when the collector is on and nobody else froze objects).

    Python's cyclic garbage collector: a full collection scans every object alive
    (torch, the frames, the map: 10^5-10^6 objects, tens of ms) and fires on allocation
    counts, i.e. at random frames. Parked, collections only scan what the run itself
    allocates.
    """
    freeze = gc.isenabled() and gc.get_freeze_count() == 0
    if freeze:
        gc.freeze()
    try:
        yield
    finally:
        if freeze:
            gc.unfreeze()
