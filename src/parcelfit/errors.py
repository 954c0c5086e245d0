"""The one exception type parcelfit raises for bad input, with where and how to fix it;
`os_error`: the operating-system errors a user can fix (a path too long, a full disk) as one;
`require`: an optional dependency, or the extra that installs it."""

from __future__ import annotations

import errno
import os
from pathlib import Path
from types import ModuleType


class ParcelfitError(ValueError):
    """Bad input a user can fix.

    The message names the file, the place inside it (key, row or column) and the fix, so that
    the command line can show it without a traceback.
    """

    def __init__(
        self,
        message: str,
        *,
        file: str | Path | None = None,
        where: str | None = None,
        fix: str | None = None,
    ) -> None:
        self.message = message
        self.file = None if file is None else str(file)
        self.where = where
        self.fix = fix
        super().__init__(self._render())

    def _render(self) -> str:
        head = ": ".join(p for p in (self.file, self.where) if p)
        text = f"{head}: {self.message}" if head else self.message
        if self.fix:
            text += f" Fix: {self.fix}"
        return text


# -- operating-system errors a user can fix -----------------------------------------------------

DISK_FULL = frozenset({errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)})


def short_path(path: str | Path, width: int = 80) -> str:
    """``path`` as text of at most ``width`` characters on one line: a longer one keeps its start
    and its end (the file's name) with ``...`` between; control characters become ``?``."""
    text = "".join(c if c.isprintable() else "?" for c in str(path))
    if len(text) <= width:
        return text
    tail = max(width // 2, width - 3 - 24)
    return f"{text[: width - 3 - tail]}...{text[-tail:]}"


def _limits(path: Path) -> tuple[int, int]:
    """The longest name and path [characters] of the file system holding ``path`` (its nearest
    existing ancestor); POSIX's usual 255 and 4096 where the system does not say."""
    for folder in (path, *path.parents):
        try:
            if folder.is_dir():
                return os.pathconf(folder, "PC_NAME_MAX"), os.pathconf(folder, "PC_PATH_MAX")
        except (OSError, ValueError, AttributeError):  # too long itself, or no pathconf
            continue
    return 255, 4096


def os_error(
    exc: OSError, path: str | Path | None = None, *, resumes: bool = False
) -> ParcelfitError | None:
    """The `ParcelfitError` for an operating-system error the user can fix, naming the file
    (``exc.filename``, else ``path``) shortened to one line: a path too long for the file system
    (with its length and the system's limits, in characters) or a full disk (or quota). With
    ``resumes``, the failed command is one whose results are stored as they arrive (a
    calibration, screen or precision check), and the message says that nothing stored is lost.
    None for any other error."""
    where = exc.filename if exc.filename is not None else path
    name = None if where is None else Path(os.fsdecode(where))
    if exc.errno == errno.ENAMETOOLONG:
        text = "" if name is None else str(name)
        longest = max((len(part) for part in Path(text).parts), default=0)
        most_name, most_path = (255, 4096) if name is None else _limits(name)
        return ParcelfitError(
            f"the path is too long for the file system: {len(text)} characters with a name of "
            f"{longest}, where names may have at most {most_name} and paths {most_path}",
            file=None if name is None else short_path(name),
            fix="choose a shorter path: a folder nearer the root, or shorter names",
        )
    if exc.errno in DISK_FULL:
        what = "a file" if name is None else short_path(name.name, 60)
        return ParcelfitError(
            f"disk full while writing {what}"
            + ("; nothing stored is lost" if resumes else "")
            + (" (or the disk quota is used up)" if exc.errno != errno.ENOSPC else ""),
            file=None if name is None else short_path(name),
            fix="free space on its disk, then rerun the same command"
            + (": it resumes" if resumes else ""),
        )
    return None


def require(module: str, *, extra: str, what: str) -> ModuleType:
    """Import the optional dependency ``module``, or stop with a `ParcelfitError` naming the
    extra of parcelfit that installs it: ``what`` (e.g. "the dask executor") needs it. Every
    import of an optional dependency in parcelfit goes through here."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise ParcelfitError(
            f"{what} needs the {extra!r} extra ({module} cannot be imported: {exc})",
            fix=f'pip install "parcelfit[{extra}]" (in a clone of the repository: '
            f'pip install -e ".[{extra}]")',
        ) from exc
