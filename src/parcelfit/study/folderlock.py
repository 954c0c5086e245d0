"""One process at a time per study or screen folder: an exclusive lock file, taken before the
store is touched and held until the run ends.

The lock is an OS-level file lock (the ``filelock`` package: ``flock`` on POSIX, ``msvcrt`` on
Windows), so it is released by the operating system when its holder dies, even by SIGKILL: a
killed study never leaves a stale lock behind. ``status`` and ``report`` only read and take no
lock, so they work while a study runs.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from filelock import FileLock, Timeout

from parcelfit.errors import ParcelfitError, os_error
from parcelfit.study.store import STORE_FILE

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


STUDY_OUTPUTS = ("runs", "results.json", "figures", "report.html")  # beside the store


def _outputs(folder: Path) -> list[str]:
    """The outputs of a study that ``folder`` holds (a folder counts when not empty)."""
    return [
        name
        for name in STUDY_OUTPUTS
        if (folder / name).is_file()
        or ((folder / name).is_dir() and any((folder / name).iterdir()))
    ]


def refuse_orphaned_outputs(folder: Path) -> None:
    """Refuse to start a new study in a folder that holds an earlier study's outputs (run
    files, results, figures) without its store (``study.sqlite`` deleted or moved): the new
    study would overwrite them."""
    if (folder / STORE_FILE).exists():
        return
    found = _outputs(folder)
    if found:
        names = ", ".join(f"{n}/" if (folder / n).is_dir() else n for n in found)
        raise ParcelfitError(
            f"this folder holds an earlier study's outputs ({names}) but no {STORE_FILE}, so a "
            "new study would overwrite them",
            file=folder,
            fix=f"restore {STORE_FILE} to resume that study, use a new output folder, or "
            "rerun with --restart to move them into earlier-TIME/ in the folder and start afresh",
        )


def set_aside_outputs(folder: Path) -> Path | None:
    """Move a study's store and outputs out of the way, into ``folder/earlier-YYYYmmdd-HHMMSS``
    (the UTC time; a new name if taken), so that a new study starts afresh; returns that
    folder (None when there was nothing to move). Call with the folder locked."""
    names = [
        n for n in (STORE_FILE, f"{STORE_FILE}-wal", f"{STORE_FILE}-shm") if (folder / n).exists()
    ] + _outputs(folder)
    if not names:
        return None
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    target = folder / f"earlier-{stamp}"
    k = 1
    while target.exists():
        k += 1
        target = folder / f"earlier-{stamp}-{k}"
    target.mkdir()
    for name in names:  # the store's WAL files with it: they hold its latest transactions
        os.replace(folder / name, target / name)
    return target
