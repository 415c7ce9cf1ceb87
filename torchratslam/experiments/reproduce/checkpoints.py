"""Checkpoints of a long experiment: each finished part saved in ``OUT/checkpoints`` so a
rerun into the same OUT resumes without redoing it.

A part is ``NAME.npz`` (its arrays, no pickle) and ``NAME.json`` (its settings key and
its numbers), each written atomically, the JSON last: a part is finished when its JSON
is there. A part whose key differs from the run's (another seed, the quick version, other
settings) is refused with one line, never silently mixed in.
"""

from __future__ import annotations

import io
import json
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ratslam_graph.atomic import atomic_write_bytes, atomic_write_text
from torchratslam.errors import InputError
from torchratslam.experiments.reproduce.report import CHECKPOINTS

__all__ = ["load_part", "save_part"]

_VERSION = 1


def _paths(out: Path, name: str) -> tuple[Path, Path]:
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
        raise InputError(f"checkpoint name {name!r} must be letters, digits, '_', '.', '-'")
    folder = Path(out) / CHECKPOINTS
    return folder / f"{name}.npz", folder / f"{name}.json"


def save_part(
    out: Path,
    name: str,
    key: Mapping[str, Any],
    data: Mapping[str, Any],
    arrays: Mapping[str, np.ndarray],
) -> None:
    """Save one finished part: ``arrays`` (npz) then ``key`` and ``data`` (JSON).

    Args:
        out: the experiment's folder.
        name: the part (a file name stem).
        key: the settings the part was computed with (JSON values).
        data: its numbers (JSON values).
        arrays: its arrays (numeric dtypes).
    """
    npz, js = _paths(out, name)
    buf = io.BytesIO()
    named: dict[str, Any] = {k: np.asarray(v) for k, v in arrays.items()}
    np.savez(buf, **named)
    atomic_write_bytes(npz, buf.getvalue())
    doc = {"version": _VERSION, "key": dict(key), "data": dict(data), "arrays": sorted(arrays)}
    atomic_write_text(js, json.dumps(doc, indent=1) + "\n")


def load_part(
    out: Path, name: str, key: Mapping[str, Any]
) -> tuple[dict[str, Any], dict[str, np.ndarray]] | None:
    """A part a stopped run finished, or None when there is none.

    Returns:
        Its ``data`` and ``arrays``.

    Raises:
        InputError: the part was computed with another ``key``, or its files are
            damaged.
    """
    npz, js = _paths(out, name)
    if not js.exists():
        return None
    try:
        doc = json.loads(js.read_text(encoding="utf-8"))
        with np.load(npz, allow_pickle=False) as z:
            arrays = {k: z[k] for k in doc["arrays"]}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(
            f"checkpoint {js} is damaged ({exc}); pass --overwrite to redo the run or "
            "choose another --out"
        ) from None
    want = json.loads(json.dumps(dict(key)))
    if doc.get("version") != _VERSION or doc.get("key") != want:
        raise InputError(
            f"{js.parent} holds checkpoints of another run ({doc.get('key')}, not {want}); "
            "choose another --out or pass --overwrite"
        )
    return doc["data"], arrays
