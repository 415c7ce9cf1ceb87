"""The project's one way to write files: atomic, synced, umask-respecting, locked.

Every file and directory the project writes goes through this module (torch-free, so
``graph`` and the CLI share it):

* :func:`atomic_write_bytes` / :func:`atomic_write_text` / :func:`atomic_write_with`:
  write a temporary file with a unique name beside the target, ``fsync`` it, give it
  the mode the user's umask asks for (``mkstemp`` would leave 600), rename it over the
  target, ``fsync`` the parent directory. A reader sees the old file or the new one,
  never a part.
* :func:`write_directory_atomically`: a directory of files (saved maps, datasets). The
  new directory is written and synced under a unique hidden name, then swapped with the
  old one by ``renameat2(RENAME_EXCHANGE)`` where the platform has it (Linux >= 3.15 on
  most file systems): one atomic step, so at every instant the target holds a complete
  directory, old or new. Where the exchange is refused the swap takes two renames
  (``target -> .NAME.old-*``, ``.NAME.new-* -> target``); a crash between them leaves
  the target missing but both complete copies beside it, and
  :func:`recover_directory` (called by the loaders) puts the newest complete one back.
* :class:`DirectoryLock`: one writer per output directory (``fcntl.flock`` on a hidden
  lock file holding the owner's pid and start time); a second writer stops at once with
  a line naming the first.
* :class:`Manifest`: the files a command wrote into a directory, so that ``--overwrite``
  removes only those and refuses, naming them, when the directory holds anything else.

For crash tests, the environment variable ``TORCHRATSLAM_CRASH_AT=N`` makes the process
``os._exit(86)`` at the N-th file-system step of these functions (counted from 1), and
``TORCHRATSLAM_NO_EXCHANGE=1`` forces the two-rename swap.
"""

from __future__ import annotations

import ctypes
import errno
import json
import os
import secrets
import shutil
import sys
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import IO, Any, BinaryIO

from ratslam_graph.errors import InputError

__all__ = [
    "LOCK_NAME",
    "MANIFEST_NAME",
    "DirectoryLock",
    "Manifest",
    "atomic_write_bytes",
    "atomic_write_text",
    "atomic_write_with",
    "dir_mode",
    "file_mode",
    "fsync_dir",
    "leftovers",
    "make_dirs",
    "recover_directory",
    "unique_name",
    "write_directory_atomically",
]

LOCK_NAME = ".torchratslam.lock"
MANIFEST_NAME = ".torchratslam-manifest.json"
CRASH_EXIT_CODE = 86

_steps = 0


def _step() -> None:
    """One file-system step done; exit abruptly here if ``TORCHRATSLAM_CRASH_AT`` says so."""
    global _steps
    at = os.environ.get("TORCHRATSLAM_CRASH_AT")
    if not at:
        return
    _steps += 1
    if _steps == int(at):
        os._exit(CRASH_EXIT_CODE)


# ------------------------------------------------------------------------- permissions
def _umask() -> int:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    old = os.umask(0o022)  # no /proc: read it by setting it (and put it back)
    os.umask(old)
    return old


def file_mode() -> int:
    """The mode a new file gets under the user's umask (``0o666 & ~umask``)."""
    return 0o666 & ~_umask()


def dir_mode() -> int:
    """The mode a new directory gets under the user's umask (``0o777 & ~umask``)."""
    return 0o777 & ~_umask()


def make_dirs(path: str | os.PathLike) -> list[Path]:
    """``mkdir -p`` that returns the directories it created (outermost first)."""
    p = Path(path)
    created: list[Path] = []
    for q in [*reversed(p.parents), p]:
        if not q.exists():
            try:
                q.mkdir()
            except FileExistsError:
                continue
            created.append(q)
    return created


# ------------------------------------------------------------------------- primitives
def unique_name(target: str | os.PathLike, kind: str) -> Path:
    """A hidden name beside ``target`` unique to this process and call:
    ``.NAME.KIND-PID-RANDOM``."""
    t = Path(target)
    return t.parent / f".{t.name}.{kind}-{os.getpid()}-{secrets.token_hex(4)}"


def fsync_dir(path: str | os.PathLike) -> None:
    """``fsync`` a directory, so renames and new entries in it survive a power cut."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:  # some file systems refuse fsync on directories
        pass
    finally:
        os.close(fd)


def atomic_write_with(path: str | os.PathLike, write: Callable[[BinaryIO], None]) -> Path:
    """Write ``path`` through ``write(binary_file)``, atomically (see the module docstring).

    Returns:
        ``path``.
    """
    path = Path(path)
    make_dirs(path.parent)
    tmp = unique_name(path, "tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
            os.fchmod(fh.fileno(), file_mode())
        _step()
        os.replace(tmp, path)
        _step()
        fsync_dir(path.parent)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically."""

    def write(fh: BinaryIO) -> None:
        fh.write(data)

    return atomic_write_with(path, write)


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8, newlines as given) to ``path`` atomically."""
    return atomic_write_bytes(path, text.encode("utf-8"))


# ------------------------------------------------------------------------- directories
_AT_FDCWD = -100
_RENAME_EXCHANGE = 2


def _exchange(a: Path, b: Path) -> bool:
    """Swap ``a`` and ``b`` atomically with renameat2(RENAME_EXCHANGE); False where the
    platform or the file system cannot."""
    if os.environ.get("TORCHRATSLAM_NO_EXCHANGE") or not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    rc = fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE)
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EPERM):
        return False
    raise OSError(err, os.strerror(err), str(a))


def write_directory_atomically(
    target: str | os.PathLike, files: Mapping[str, Callable[[BinaryIO], None]]
) -> Path:
    """Write ``files`` (relative name -> writer of an open binary file) as the directory
    ``target``, replacing an existing one with no instant where ``target`` is missing
    (where the platform has an atomic exchange; see the module docstring).

    Returns:
        ``target``.
    """
    target = Path(target)
    make_dirs(target.parent)
    new = unique_name(target, "new")
    new.mkdir(mode=0o700)
    _step()
    try:
        for name, write in files.items():
            p = new / name
            if p.parent != new:
                p.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(p, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            with os.fdopen(fd, "wb") as fh:
                write(fh)
                fh.flush()
                os.fsync(fh.fileno())
                os.fchmod(fh.fileno(), file_mode())
            _step()
        os.chmod(new, dir_mode())
        fsync_dir(new)
        _step()
        swap_in(new, target)
    except BaseException:
        shutil.rmtree(new, ignore_errors=True)
        raise
    remove_stale_leftovers(target)
    return target


def swap_in(new: Path, target: Path) -> None:
    """Put the complete directory ``new`` at ``target`` (replacing what is there) and
    remove the old one; ``target`` never disappears where the exchange is available."""
    if not target.exists() and not target.is_symlink():
        os.rename(new, target)
        _step()
        fsync_dir(target.parent)
        _step()
        return
    if _exchange(new, target):
        _step()
        fsync_dir(target.parent)
        _step()
        shutil.rmtree(new, ignore_errors=True)  # ``new`` now holds the old directory
        _step()
        return
    old = unique_name(target, "old")
    os.rename(target, old)
    _step()
    os.rename(new, target)
    _step()
    fsync_dir(target.parent)
    _step()
    shutil.rmtree(old, ignore_errors=True)
    _step()


def leftovers(target: str | os.PathLike) -> list[Path]:
    """The hidden ``.NAME.new-*`` / ``.NAME.old-*`` / ``.NAME.tmp-*`` entries an
    interrupted write of ``target`` left beside it (newest first)."""
    t = Path(target)
    if not t.parent.is_dir():
        return []
    found = [
        p
        for kind in ("new", "old", "tmp")
        for p in t.parent.glob(f".{t.name}.{kind}-*")
        if p.name.split(".")[-1].split("-")[0] == kind
    ]
    return sorted(found, key=lambda p: p.stat().st_mtime_ns if p.exists() else 0, reverse=True)


def _pid_alive(name: str) -> bool:
    try:
        pid = int(name.rsplit("-", 2)[-2])
    except (ValueError, IndexError):
        return False
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def recover_directory(
    target: str | os.PathLike, is_complete: Callable[[Path], bool]
) -> Path | None:
    """After a crash in the middle of a two-rename swap, put a complete leftover back.

    When ``target`` is missing and a leftover ``.NAME.new-*`` or ``.NAME.old-*`` of a
    process that is no longer running passes ``is_complete``, it is renamed to
    ``target`` (new before old: the save that crashed had finished writing it).

    Returns:
        The leftover that was put back, or None.
    """
    t = Path(target)
    if t.exists():
        return None
    cands = [p for p in leftovers(t) if ".tmp-" not in p.name and not _pid_alive(p.name)]
    cands.sort(key=lambda p: (".new-" not in p.name, -p.stat().st_mtime_ns))
    for p in cands:
        if p.is_dir() and is_complete(p):
            try:
                os.rename(p, t)
                fsync_dir(t.parent)
            except OSError:
                return p  # read-only: the caller can still read it in place
            return p
    return None


def remove_stale_leftovers(target: str | os.PathLike) -> list[Path]:
    """Remove leftovers of ``target`` written by processes that are no longer running
    (only while ``target`` itself exists). Returns what was removed."""
    t = Path(target)
    if not t.exists():
        return []
    gone = []
    for p in leftovers(t):
        if not _pid_alive(p.name):
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)
            gone.append(p)
    return gone


# ------------------------------------------------------------------------- lock
class DirectoryLock:
    """An exclusive lock on a directory for one writer (``fcntl.flock`` on
    ``DIR/.torchratslam.lock``, released when the process ends, even by a crash).

    Args:
        directory: the directory (created when missing).
        what: how to describe the holder in messages, e.g. ``"torchratslam run"``.

    Raises:
        InputError: another process holds the lock (its pid and start time are named).
    """

    def __init__(self, directory: str | os.PathLike, what: str = "torchratslam") -> None:
        self.directory = Path(directory)
        self.path = self.directory / LOCK_NAME
        self.what = what
        self._fh: IO[str] | None = None

    def acquire(self) -> DirectoryLock:
        import fcntl

        make_dirs(self.directory)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, file_mode())
        fh = os.fdopen(fd, "r+")
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.seek(0)
            try:
                holder = json.loads(fh.read() or "{}")
            except ValueError:
                holder = {}
            fh.close()
            pid = holder.get("pid", "?") if isinstance(holder, dict) else "?"
            started = holder.get("started", "?") if isinstance(holder, dict) else "?"
            cmd = holder.get("what", "another run") if isinstance(holder, dict) else "?"
            raise InputError(
                f"{self.directory} is in use by {cmd} (pid {pid}, started {started}); "
                "wait for it to finish or choose another output directory"
            ) from None
        fh.seek(0)
        fh.truncate()
        started = time.strftime("%Y-%m-%d %H:%M:%S %Z", time.localtime())
        fh.write(json.dumps({"pid": os.getpid(), "started": started, "what": self.what}))
        fh.flush()
        self._fh = fh
        return self

    def release(self) -> None:
        if self._fh is not None:
            self._fh.close()  # closing the descriptor drops the flock
            self._fh = None

    def __enter__(self) -> DirectoryLock:
        return self.acquire()

    def __exit__(self, *exc: Any) -> None:
        self.release()


# ------------------------------------------------------------------------- manifest
class Manifest:
    """The entries (relative paths) the project wrote into a directory, recorded in
    ``DIR/.torchratslam-manifest.json``."""

    def __init__(self, directory: str | os.PathLike) -> None:
        self.directory = Path(directory)
        self.path = self.directory / MANIFEST_NAME

    def entries(self) -> set[str]:
        """The recorded entries (empty when there is no manifest or it is unreadable)."""
        try:
            data = json.loads(self.path.read_text())
        except (OSError, ValueError):
            return set()
        files = data.get("files") if isinstance(data, dict) else None
        return {str(f) for f in files if isinstance(f, str)} if isinstance(files, list) else set()

    def add(self, names: Iterable[str]) -> None:
        """Record ``names`` (plus the lock and the manifest itself), atomically."""
        merged = sorted(self.entries() | set(names) | {MANIFEST_NAME, LOCK_NAME})
        atomic_write_text(self.path, json.dumps({"files": merged}, indent=1) + "\n")

    def foreign(self, ignore: Iterable[str] = ()) -> list[str]:
        """Top-level entries of the directory the project did not record (hidden
        leftovers of the project's own atomic writes excepted)."""
        if not self.directory.is_dir():
            return []
        own = {e.split("/", 1)[0] for e in self.entries()} | {MANIFEST_NAME, LOCK_NAME}
        own |= set(ignore)
        out = []
        for p in sorted(self.directory.iterdir()):
            if p.name in own:
                continue
            if any(f".{o}." in p.name and p.name.startswith(f".{o}.") for o in own):
                continue  # .NAME.new-*, .NAME.tmp-* of an entry we own
            out.append(p.name)
        return out

    def check_overwrite(self, what: str) -> None:
        """Raise :class:`InputError` naming the entries ``--overwrite`` would not remove."""
        foreign = self.foreign()
        if foreign:
            shown = ", ".join(foreign[:5]) + (" ..." if len(foreign) > 5 else "")
            raise InputError(
                f"{self.directory} holds files torchratslam did not write ({shown}); "
                f"refusing to {what}: move them away or choose another directory"
            )

    def remove_recorded(self) -> None:
        """Remove every recorded entry (and the manifest); nothing else is touched."""
        for name in sorted(self.entries(), reverse=True):
            if name in (LOCK_NAME, MANIFEST_NAME):
                continue
            p = self.directory / name
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p)
            elif p.exists() or p.is_symlink():
                p.unlink()
