"""The results table: one row per run, written atomically as CSV (and Parquet when
pyarrow is installed), read back to resume.

Floats are written with ``repr`` (shortest round-trip form), so reading a table back
and writing it again gives the same bytes, and the same runs give the same file.
"""

from __future__ import annotations

import csv
import io
import logging
import os
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from ratslam_graph.io import atomic_write_text
from torchratslam.errors import InputError
from torchratslam.sweeps.runner import METRICS, TIMING_COLUMNS

__all__ = ["columns", "format_cell", "parse_cell", "read_table", "to_frame", "write_table"]

log = logging.getLogger(__name__)

IDENTITY = ("index", "run_id", "dataset", "max_frames", "seed", "backend")
STATUS = ("status", "error")


def columns(params: Sequence[str], extra: Iterable[str] = ()) -> list[str]:
    """The table's columns: identity, swept parameters, status, metrics, extras."""
    out = [*IDENTITY, *params, *STATUS, *METRICS]
    out += [c for c in extra if c not in out]
    return out


def format_cell(v: Any) -> str:
    """One CSV cell: floats by ``repr`` (``nan``, ``inf``), others by ``str``."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, float):
        return repr(v)
    return str(v)


def parse_cell(s: str) -> Any:
    """The value of a CSV cell (int, float, bool or str; '' stays '')."""
    if s in ("True", "False"):
        return s == "True"
    try:
        return int(s)
    except ValueError:
        pass
    try:
        return float(s)
    except ValueError:
        return s


def csv_text(rows: Sequence[dict[str, Any]], cols: Sequence[str]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for row in rows:
        w.writerow([format_cell(row.get(c, "")) for c in cols])
    return buf.getvalue()


def write_table(
    path: Path, rows: Sequence[dict[str, Any]], cols: Sequence[str], *, parquet: bool = True
) -> list[Path]:
    """Write ``rows`` (sorted by ``index``) to ``path`` (CSV) atomically, and beside it
    ``path.with_suffix('.parquet')`` when pyarrow is installed.

    Returns:
        The files written.
    """
    path = Path(path)
    ordered = sorted(rows, key=lambda r: int(r["index"]))
    atomic_write_text(path, csv_text(ordered, cols))
    written = [path]
    if parquet:
        pq_path = _write_parquet(path.with_suffix(".parquet"), ordered, cols)
        if pq_path is not None:
            written.append(pq_path)
    return written


def _write_parquet(path: Path, rows: Sequence[dict[str, Any]], cols: Sequence[str]) -> Path | None:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return None
    data: dict[str, list[Any]] = {}
    for c in cols:
        vals = [r.get(c) for r in rows]
        numeric = [isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals]
        if all(numeric) and not all(isinstance(v, int) for v in vals):
            vals = [float(v) for v in vals if v is not None]
        elif not all(numeric) and not all(isinstance(v, bool) for v in vals):
            vals = [format_cell(v) for v in vals]
        data[c] = vals
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        pq.write_table(pa.table(data), tmp)
        os.replace(tmp, path)
    except Exception as exc:  # the CSV is the table of record
        Path(tmp).unlink(missing_ok=True)
        log.warning("could not write %s (%s); the CSV has every result", path, exc)
        return None
    return path


def read_table(path: Path) -> list[dict[str, Any]]:
    """Rows of a table written by :func:`write_table` (values parsed back).

    Raises:
        InputError: the file is not such a table.
    """
    path = Path(path)
    try:
        with open(path, newline="") as fh:
            reader = csv.DictReader(fh)
            rows = [{k: parse_cell(v) for k, v in r.items()} for r in reader]
            fields = reader.fieldnames or []
    except (OSError, csv.Error, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read the results table ({exc})") from None
    missing = {"index", "run_id", "status"} - set(fields)
    if missing:
        raise InputError(
            f"{path}: not a sweep results table (no {', '.join(sorted(missing))} column)"
        )
    return rows


def to_frame(rows: Sequence[dict[str, Any]], cols: Sequence[str]) -> Any:
    """A pandas DataFrame of the rows when pandas is installed, else the list of dicts
    (each with every column)."""
    full = [{c: r.get(c, "") for c in cols} for r in sorted(rows, key=lambda r: int(r["index"]))]
    try:
        import pandas as pd
    except ImportError:
        return full
    return pd.DataFrame(full, columns=list(cols))


def deterministic_text(path: Path) -> str:
    """The table's CSV without the timing columns (what must not change between two
    runs of the same sweep)."""
    rows = read_table(path)
    with open(path, newline="") as fh:
        cols = next(csv.reader(fh))
    keep = [c for c in cols if c not in TIMING_COLUMNS]
    return csv_text(rows, keep)
