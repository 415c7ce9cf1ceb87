"""Where a command may write, checked before any work, from the command line and from
Python alike: an OUT directory must be new, empty, or hold an earlier run of the same
command (:func:`check_out_dir`); a single output file (``--json``, ``--figure``) must not
be one of the command's inputs, lie inside one, or be a file another command wrote
(recorded in its folder's manifest), and an existing file is replaced only when asked
(:func:`check_out_file`). Nothing is written when a check fails.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from ratslam_graph.atomic import LOCK_NAME, MANIFEST_NAME, Manifest
from ratslam_graph.errors import InputError, option

__all__ = ["check_out_dir", "check_out_file"]


def check_out_dir(
    out: str | Path, *, what: str, marks: Iterable[str], flag: tuple[str, str] = ("--out", "out")
) -> bool:
    """Refuse an OUT that exists and holds anything but an earlier ``what`` (one of
    ``marks`` present): a new or empty directory, or the command's own, is fine.

    Returns:
        True when OUT holds an earlier ``what`` (the caller decides whether to replace it).

    Raises:
        InputError: OUT is a file, or a non-empty directory holding something else.
    """
    p = Path(out)
    name = option(f"{flag[0]} {p}", f"{flag[1]}={str(p)!r}")
    if not p.exists():
        return False
    if not p.is_dir():
        raise InputError(f"{name}: exists and is not a directory; choose another path")
    entries = sorted(q.name for q in p.iterdir() if q.name not in (LOCK_NAME, MANIFEST_NAME))
    if not entries:
        return False
    if any((p / m).exists() for m in marks):
        return True
    shown = ", ".join(entries[:3]) + (" ..." if len(entries) > 3 else "")
    raise InputError(
        f"{name} is not empty and holds no {what} (it holds {shown}); a {what} writes into "
        f"a new or empty directory: choose another {option(flag[0], flag[1])}"
    )


def check_out_file(
    target: str | Path | None,
    *,
    inputs: Iterable[str | Path],
    flag: tuple[str, str],
    overwrite: bool = False,
) -> None:
    """Refuse an output file that is an input, lies inside one, or is a file another
    command wrote (its folder's manifest lists it: a run's ``metrics.json``, ``map.png``);
    any other existing file is replaced only with ``overwrite``.

    Raises:
        InputError: naming the option and the file.
    """
    if target is None:
        return
    t = Path(target)
    name = option(f"{flag[0]} {t}", f"{flag[1]}={str(t)!r}")
    if t.is_dir():
        raise InputError(f"{name}: is a directory; give a file name")
    rt = t.resolve()
    for src in inputs:
        rs = Path(src).resolve()
        if rt == rs or rs in rt.parents:
            raise InputError(
                f"{name} is (or lies in) the input {src}; a command never rewrites its "
                "inputs: choose another path"
            )
    if t.name in Manifest(t.parent).entries():
        raise InputError(
            f"{name} is a file another torchratslam command wrote in {t.parent} (it is in "
            "that folder's manifest); choose another path"
        )
    if t.exists() and not overwrite:
        raise InputError(
            f"{name} exists; choose another path, or replace it with "
            f"{option('--overwrite', 'overwrite=True')}"
        )
