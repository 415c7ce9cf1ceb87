"""The saved state of a dataset run and what a resumed run needs: OUT/state (the map and
its per-frame history) and OUT/run.json (the run's options, config, identity and whether
it finished).

A run writes OUT/run.json after its first frame (``finished: false``), saves its state at
every checkpoint and when it stops, and marks the record finished last of all; so an OUT
whose record is not finished holds a run that stopped (a crash or ``kill -9`` included),
and :func:`torchratslam.experiments.run_dataset.resume_run` continues it from its last
saved state (or from the first frame when none was saved).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ratslam_graph.atomic import Manifest, atomic_write_text
from torchratslam.errors import InputError, RatSLAMError
from torchratslam.experiments.run_options import RunOptions

__all__ = [
    "HISTORY",
    "LOADED_DIR",
    "RUN_RECORD",
    "STATE_DIR",
    "RunRecord",
    "SaveError",
    "drop_loaded",
    "finished_run",
    "json_default",
    "keep_loaded",
    "loaded_maps",
    "new_run_id",
    "read_record",
    "restore_history",
    "restore_multisession",
    "save_run_state",
    "stopped_run",
    "write_record",
]

STATE_DIR = "state"
RUN_RECORD = "run.json"
HISTORY = "history.npz"
LOADED_DIR = "loaded"
"""OUT/loaded/mapK: a copy of the K-th ``--load`` map, kept while the run can be resumed
(a resumed run reads its stored maps there, so the originals may move or go)."""


@dataclass(frozen=True)
class RunRecord:
    """OUT/run.json: the run's options and flat config, all a resumed run needs.

    Attributes:
        options: the run's options.
        config_flat: the config as flat keys (``RatSLAMConfig.to_flat``).
        run_id: this run's identity (a saved state carries it too, so a state left by an
            earlier run in OUT is never taken for this one's).
        finished: True once every output of the run is written.
        format: the record's format name.
        version: the record's format version.
    """

    options: RunOptions
    config_flat: dict[str, Any]
    run_id: str = ""
    finished: bool = False
    format: str = "torchratslam-run"
    version: int = 1

    def to_json(self) -> dict[str, Any]:
        """The record as run.json holds it (format, version, run_id, finished, options,
        config_flat)."""
        return {
            "format": self.format,
            "version": self.version,
            "run_id": self.run_id,
            "finished": self.finished,
            "options": asdict(self.options),
            "config_flat": self.config_flat,
        }


class SaveError(RatSLAMError):
    """A checkpoint or an output could not be written (a full disk, a lost mount); the
    message names the file, the last good checkpoint and how to resume."""


def new_run_id() -> str:
    """A fresh run identity (time and random bits)."""
    import time
    import uuid

    return f"{time.strftime('%Y%m%dT%H%M%S')}-{uuid.uuid4().hex[:12]}"


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


def _multisession_info(slam: Any) -> dict[str, Any] | None:
    """What a multisession run (``--load``) needs besides its map to go on: the stored
    maps not merged yet and the merges so far (None for a single-session run)."""
    if not hasattr(slam, "pending") or not hasattr(slam, "merges"):
        return None
    merges = json.loads(json.dumps(slam.merges, default=json_default))
    return {"pending": [int(k) for k in slam.pending], "merges": merges}


def restore_multisession(slam: Any, info: dict[str, Any]) -> None:
    """Put a saved multisession run's pending maps and merges back into ``slam``."""
    saved = info.get("multisession")
    if saved is None or not hasattr(slam, "pending"):
        return
    slam.pending = [int(k) for k in saved.get("pending", [])]
    slam.merges = list(saved.get("merges", []))


def keep_loaded(slam: Any, out: Path, *, replace: bool) -> None:
    """Copy a ``--load`` run's stored maps to OUT/loaded/mapK (each atomically, recorded in
    OUT's manifest first), so that a resumed run needs only OUT; ``replace`` False keeps
    the copies already there."""
    from torchratslam.maps.native import save_map

    stored = getattr(slam, "stored", None)
    if not stored:
        return
    Manifest(out).add([LOADED_DIR])
    (out / LOADED_DIR).mkdir(exist_ok=True)
    for k, state in enumerate(stored):
        target = out / LOADED_DIR / f"map{k}"
        if replace or not target.is_dir():
            save_map(state, target)


def drop_loaded(out: Path) -> None:
    """Remove OUT/loaded once the run has finished (nothing is left to resume)."""
    import shutil

    if LOADED_DIR in Manifest(out).entries() and (out / LOADED_DIR).is_dir():
        shutil.rmtree(out / LOADED_DIR, ignore_errors=True)


def loaded_maps(out: Path, paths: tuple[str, ...], *, resume: bool) -> list[Any]:
    """The stored maps of a ``--load`` run: on ``resume`` the copies OUT/loaded holds
    (named by their original paths, as the run began), else the maps at ``paths``.

    Raises:
        InputError: a map cannot be found (a resumed run whose copy is missing names
            both places).
    """
    from torchratslam.maps import native
    from torchratslam.maps.io import load_state

    maps = []
    for k, p in enumerate(paths):
        copy = out / LOADED_DIR / f"map{k}"
        if resume and copy.is_dir():
            state = native.load_state(copy)
            state.name = str(Path(p))
        elif resume and not Path(p).exists():
            raise InputError(
                f"--resume {out}: the loaded map {p} is gone and {out / LOADED_DIR} holds no "
                f"copy of it (the run began before runs kept one); put the map back at {p}"
            )
        else:
            state = load_state(p)
        maps.append(state)
    return maps


def write_record(out: Path, record: RunRecord) -> None:
    """OUT/run.json, atomically (recorded in OUT's manifest first)."""
    Manifest(out).add([RUN_RECORD])
    atomic_write_text(
        out / RUN_RECORD, json.dumps(record.to_json(), indent=1, default=json_default)
    )


def save_run_state(slam: Any, out: Path, record: RunRecord, info: dict[str, Any]) -> None:
    """OUT/state (with the history) and OUT/run.json, each atomically; state first. The
    state's info carries the record's ``run_id`` (and a multisession run's pending maps
    and merges)."""
    from torchratslam.maps.native import save_map
    from torchratslam.maps.running import state_from_slam

    info = {**info, "run_id": record.run_id}
    ms = _multisession_info(slam)
    if ms is not None:
        info["multisession"] = ms
    Manifest(out).add([STATE_DIR, RUN_RECORD])  # recorded before they are written
    save_map(
        state_from_slam(slam, share=True),  # written now: the templates are not copied
        out / STATE_DIR,
        info=info,
        extra_files={HISTORY: _history_writer(slam)},
    )
    write_record(out, record)


def finished_run(out: Path) -> bool:
    """OUT holds a run that finished (its record says so)."""
    try:
        record = json.loads((out / RUN_RECORD).read_text())
    except (OSError, ValueError):
        return False
    return isinstance(record, dict) and bool(record.get("finished"))


def stopped_run(out: Path) -> str | None:
    """A description of the stopped run OUT holds (``"stopped at frame N (reason)"``), or
    None when OUT holds none (no record, or a finished run).

    A record without ``finished`` (an older one) counts as stopped when its state is
    marked partial.
    """
    from torchratslam.maps.native import read_map_info

    p = out / RUN_RECORD
    if not p.is_file():
        return None
    try:
        record = json.loads(p.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(record, dict):
        return None
    info: dict[str, Any] = {}
    if (out / STATE_DIR).is_dir():
        try:
            info = dict(read_map_info(out / STATE_DIR))
        except (RatSLAMError, OSError, ValueError):
            info = {}
    finished = record.get("finished")
    if finished is None:  # a record of an older version: the state says
        finished = not info.get("partial", False)
    if finished:
        return None
    same = info and info.get("run_id", record.get("run_id")) == record.get("run_id")
    if not same:
        return "stopped before its first checkpoint"
    if not info.get("partial"):
        return "stopped while writing its outputs"
    frame = info.get("stopped_at_frame", "?")
    reason = info.get("reason", "")
    if reason == "checkpoint":
        reason = "killed or crashed; last checkpoint"
    return f"stopped at frame {frame} ({reason})"


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
