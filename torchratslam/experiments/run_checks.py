"""The checks of a dataset run made before its first frame: the counts, the device, that
every option applies to the data, and that OUT can take the outputs.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ratslam_graph.atomic import Manifest
from torchratslam.errors import InputError, option
from torchratslam.experiments.run_options import RunOptions
from torchratslam.experiments.run_outputs import OUTPUT_FILES, TUM_FILES, UNMERGED_DIR
from torchratslam.experiments.run_state import LOADED_DIR, RUN_RECORD, STATE_DIR

__all__ = [
    "check_applicable",
    "check_counts",
    "check_device",
    "check_inputs_apart",
    "check_out",
]


def check_counts(threads: int, max_frames: int | None, checkpoint_every: int | None) -> None:
    """The counts must be positive (``checkpoint_every`` 0: no checkpoints).

    Raises:
        InputError: a count below one.
    """
    if threads < 1:
        raise InputError(f"{option('--threads', 'threads')} must be >= 1, got {threads}")
    if max_frames is not None and max_frames <= 0:
        raise InputError(
            f"{option('--max-frames', 'max_frames')} must be a positive number of frames, "
            f"got {max_frames}"
        )
    if checkpoint_every is not None and checkpoint_every < 0:
        raise InputError(
            f"{option('--checkpoint-every', 'checkpoint_every')} must be >= 1 frame (0: no "
            f"checkpoints), got {checkpoint_every}"
        )


def check_device(spec: str | None) -> Any:
    """The torch device ``spec``, checked against this torch build and machine (None:
    the default).

    Raises:
        InputError: not a device, or not usable here.
    """
    if spec is None:
        return None
    import torch

    try:
        dev = torch.device(spec)
    except (RuntimeError, ValueError, TypeError):
        raise InputError(
            f"--device {spec!r} is not a torch device; use cpu, cuda, cuda:N or mps"
        ) from None
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            why = "has no CUDA" if torch.version.cuda is None else "sees no GPU"
            raise InputError(
                f"--device {spec}: this torch ({torch.__version__}) {why}; use --device cpu"
            )
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise InputError(
                f"--device {spec}: only {torch.cuda.device_count()} CUDA device(s) are visible"
            )
    elif dev.type == "mps":
        if not torch.backends.mps.is_available():
            raise InputError(f"--device {spec}: MPS is not available here; use --device cpu")
    elif dev.type != "cpu":
        raise InputError(f"--device {spec}: {dev.type} devices are not supported; use cpu or cuda")
    return dev


def _data_kind(spec: str) -> str:
    """The kind of data: sim, bag (ROS 1 or 2, a file or a bag directory), directory, video."""
    from torchratslam.readers.bags import is_bag

    if spec.startswith("sim:"):
        return "sim"
    p = Path(spec)
    if is_bag(p):
        return "bag"
    return "directory" if p.is_dir() else "video"


def check_applicable(opts: RunOptions) -> None:
    """Every option given must apply to the data: an option that would be ignored is an
    error, not a silent no-op."""
    kind = _data_kind(str(opts.data))
    wrong = {
        "sim": (
            "odometry",
            "groundtruth",
            "image_topic",
            "odom_topic",
            "max_speed",
            "max_turn_rate",
        ),
        "directory": ("image_topic", "odom_topic"),
        "video": ("image_topic", "odom_topic"),
        "bag": ("odometry", "groundtruth", "max_speed", "max_turn_rate"),
    }[kind]
    given = [f"--{k.replace('_', '-')}" for k in wrong if getattr(opts, k)]
    if given:
        raise InputError(
            f"{' and '.join(given)} do{'es' if len(given) == 1 else ''} not apply to "
            f"{kind} data ({opts.data}); remove {'it' if len(given) == 1 else 'them'}"
        )


def check_inputs_apart(out: Path, opts: RunOptions) -> None:
    """OUT must not be, hold or lie in the run's inputs (the data directory, a ``--load``
    map, the odometry or ground-truth file): a run never rewrites its inputs. A new
    folder directly inside a data directory is allowed (it touches none of the data).

    Raises:
        InputError: naming the option.
    """
    target = out.resolve()
    named: list[tuple[str, str, Any]] = [
        ("--data", "data", None if str(opts.data).startswith("sim:") else opts.data),
        ("--odometry", "odometry", opts.odometry),
        ("--groundtruth", "groundtruth", opts.groundtruth),
        *(("--load", "load", p) for p in opts.load),
    ]
    for flag, arg, value in named:
        if not value or not Path(str(value)).exists():
            continue
        src = Path(str(value)).resolve()
        if flag == "--data" and target.parent == src and not target.exists():
            continue  # a new folder beside the data's frames/ and CSVs rewrites none of them
        if target == src or src in target.parents or target in src.parents:
            raise InputError(
                f"{option('--out', 'out')} {out} is (or lies in, or holds) the input given as "
                f"{option(flag, arg)} {value}; a run never rewrites its inputs: choose "
                f"another {option('--out', 'out')}"
            )


OTHER_COMMANDS = {
    "report.json": "a multisession run or a reproduced experiment",
    "running.json": "a multisession run",
    "seeds.json": "a multisession seed table",
    "results.csv": "a sweep",
    "study.journal": "a tuning study",
    "state.npz": "an MBARAM run",
    "index.json": "reproduced experiments",
    "frames": "a dataset",
}
"""What another command leaves in its OUT: a run never writes among it (a user's own
loose files are kept beside a run's, as before)."""


def check_out(out: Path, *, resume: bool) -> None:
    """OUT must be a writable directory (or creatable), with no file where a directory
    goes and no file of ours' names that torchratslam did not write."""
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a directory; choose another path")
    if out.exists():
        state = out / STATE_DIR
        if state.exists() and not state.is_dir():
            raise InputError(
                f"{state} exists and is not a directory (the map goes there); move it away"
            )
        for name in OUTPUT_FILES:
            if (out / name).is_dir():
                raise InputError(f"{out / name} is a directory (a file goes there); move it away")
        other = next((n for n in OTHER_COMMANDS if (out / n).exists()), None)
        if other is not None and not resume:
            raise InputError(
                f"{option('--out', 'out')} {out} holds {OTHER_COMMANDS[other]} ({other}); a "
                f"run does not write among another command's outputs: choose another "
                f"{option('--out', 'out')}"
            )
        own = Manifest(out).entries()
        names = (*OUTPUT_FILES, *TUM_FILES, STATE_DIR, RUN_RECORD, UNMERGED_DIR, LOADED_DIR)
        theirs = [n for n in names if (out / n).exists()]
        theirs = [n for n in theirs if n not in own]
        if theirs and not resume:
            raise InputError(
                f"{out} holds {', '.join(theirs)} that torchratslam did not write (or wrote "
                "before it kept a manifest); refusing to replace them: choose another --out "
                "or move them away"
            )
        probe = out
    else:
        probe = next((q for q in out.parents if q.exists()), Path("."))
        if not probe.is_dir():
            raise InputError(f"--out {out}: {probe} is not a directory")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise InputError(f"--out {out}: {probe} is not writable; choose another --out")
    state = out / STATE_DIR
    if state.is_dir() and not os.access(state, os.W_OK | os.X_OK):
        raise InputError(f"{state} is not writable, so the map cannot be replaced")
