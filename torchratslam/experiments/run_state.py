"""The saved state of a dataset run and what a resumed run needs: OUT/state (the map and
its per-frame history) and OUT/run.json (the run's options and config).

A run saves its state here at every checkpoint and when it stops;
:func:`torchratslam.experiments.run_dataset.resume_run` reads it back.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ratslam_graph.atomic import Manifest, atomic_write_text
from torchratslam.errors import InputError
from torchratslam.experiments.run_options import RunOptions

__all__ = [
    "HISTORY",
    "RUN_RECORD",
    "STATE_DIR",
    "RunRecord",
    "json_default",
    "read_record",
    "restore_history",
    "save_run_state",
]

STATE_DIR = "state"
RUN_RECORD = "run.json"
HISTORY = "history.npz"


@dataclass(frozen=True)
class RunRecord:
    """OUT/run.json: the run's options and flat config, all a resumed run needs.

    Attributes:
        options: the run's options.
        config_flat: the config as flat keys (``RatSLAMConfig.to_flat``).
        format: the record's format name.
        version: the record's format version.
    """

    options: RunOptions
    config_flat: dict[str, Any]
    format: str = "torchratslam-run"
    version: int = 1

    def to_json(self) -> dict[str, Any]:
        """The record as run.json holds it (format, version, options, config_flat)."""
        return {
            "format": self.format,
            "version": self.version,
            "options": asdict(self.options),
            "config_flat": self.config_flat,
        }


def json_default(v: Any) -> Any:
    """JSON for numpy scalars and arrays; any other object as its ``str``."""
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)


def _history_writer(slam: Any) -> Any:
    """A writer of the per-frame history (trajectory, ground truth, odometry, pose-cell
    centres) that a resumed run needs to give the same outputs as one run."""
    core = getattr(slam, "slam", slam)
    arrays = core.history.arrays()
    return lambda fh: np.savez(fh, **arrays)


def restore_history(slam: Any, path: Path) -> None:
    """Put the per-frame history saved at ``path`` back into ``slam``.

    Raises:
        InputError: the history cannot be read.
    """
    core = getattr(slam, "slam", slam)
    try:
        with np.load(path, allow_pickle=False) as h:
            a = {k: h[k] for k in h.files}
        core.history.restore(a)
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(f"{path}: the run's history cannot be read ({exc}); re-run") from None


def save_run_state(slam: Any, out: Path, record: RunRecord, info: dict[str, Any]) -> None:
    """OUT/state (with the history) and OUT/run.json, each atomically; state first."""
    from torchratslam.maps.native import save_map
    from torchratslam.maps.running import state_from_slam

    Manifest(out).add([STATE_DIR, RUN_RECORD])  # recorded before they are written
    save_map(
        state_from_slam(slam),
        out / STATE_DIR,
        info=info,
        extra_files={HISTORY: _history_writer(slam)},
    )
    atomic_write_text(
        out / RUN_RECORD, json.dumps(record.to_json(), indent=1, default=json_default)
    )


def read_record(out: Path) -> dict[str, Any]:
    """OUT/run.json as written (its options and config are checked to be mappings).

    Raises:
        InputError: no record, or one that cannot be read.
    """
    p = out / RUN_RECORD
    if not p.is_file():
        raise InputError(
            f"--resume {out}: no {RUN_RECORD} there; only a run of this torchratslam that "
            "stopped early can be resumed"
        )
    try:
        record = json.loads(p.read_text())
        if not isinstance(record, dict) or not isinstance(record.get("options"), dict):
            raise ValueError("no options")
        if not isinstance(record.get("config_flat"), dict):
            raise ValueError("no config")
    except (OSError, ValueError) as exc:
        raise InputError(f"{p}: cannot be read ({exc}); start the run again") from None
    return record
