"""Atomic writing of a directory of files (saved maps).

The files are written into a temporary directory beside the target, fsynced, and only
then swapped in by renames, so a crash or an error never leaves a half-written map and
an existing map is replaced only by a complete one.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import BinaryIO


def write_directory_atomically(
    target: Path, files: Mapping[str, Callable[[BinaryIO], None]]
) -> Path:
    """Write ``files`` (name -> writer of an open binary file) as the directory ``target``.

    Returns:
        ``target``.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.tmp-", dir=target.parent))
    try:
        for name, write in files.items():
            with open(tmp / name, "wb") as fh:
                write(fh)
                fh.flush()
                os.fsync(fh.fileno())
        if target.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{target.name}.old-", dir=target.parent))
            old.rmdir()
            os.rename(target, old)
            os.rename(tmp, target)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return target
