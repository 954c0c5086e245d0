"""One process at a time per study or screen folder: an exclusive lock file, taken before the
store is touched and held until the run ends.

The lock is an OS-level file lock (the ``filelock`` package: ``flock`` on POSIX, ``msvcrt`` on
Windows), so it is released by the operating system when its holder dies, even by SIGKILL: a
killed study never leaves a stale lock behind. ``status`` and ``report`` only read and take no
lock, so they work while a study runs.
"""

from __future__ import annotations

import os
from pathlib import Path

from filelock import FileLock, Timeout

from parcelfit.errors import ParcelfitError, os_error

LOCK_FILE = ".parcelfit.lock"


def check_writable(folder: Path, files: tuple[str, ...] = ()) -> None:
    """Refuse a folder (or one of its ``files``) parcelfit cannot write, naming it and the fix;
    a path too long for the file system is refused too (`parcelfit.errors.os_error`)."""
    try:
        _check_writable(folder, files)
    except OSError as exc:
        raise (os_error(exc, folder) or exc) from None


def _check_writable(folder: Path, files: tuple[str, ...]) -> None:
    if folder.exists() and not folder.is_dir():
        raise ParcelfitError(
            "the output folder is a file", file=folder, fix="choose another output folder"
        )
    paths = [p for p in (folder, *(folder / f for f in files)) if p.exists()]
    for path in paths:
        if not os.access(path, os.W_OK):
            raise ParcelfitError(
                f"this {'folder' if path.is_dir() else 'file'} is read-only, so the run cannot go "
                "on (the results already in it are intact)",
                file=path,
                fix="make it writable, or copy the folder somewhere writable and run there",
            )


def lock_folder(folder: Path, what: str) -> FileLock:
    """Take ``folder``'s lock without waiting; a folder another process holds is refused."""
    lock = FileLock(str(folder / LOCK_FILE), timeout=0)
    try:
        lock.acquire(timeout=0)
    except Timeout:
        raise ParcelfitError(
            f"another parcelfit process is running {what} in this folder",
            file=folder,
            fix="wait for it to finish (`parcelfit status` shows its progress), "
            "or use another output folder",
        ) from None
    except OSError as exc:
        raise ParcelfitError(
            f"cannot take the folder's lock ({exc.strerror or exc})",
            file=folder,
            fix="make the folder writable, or run in a writable folder",
        ) from None
    return lock
