"""The one exception type parcelfit raises for bad input, with where and how to fix it;
`shown`: the short one-line form in which a message quotes a value the user wrote;
`os_error`: the operating-system errors a user can fix (a path too long, a full disk) as one;
`require`: an optional dependency, or the extra that installs it."""

from __future__ import annotations

import errno
import math
import os
import reprlib
from pathlib import Path
from typing import Any

# the longest a quoted value (`shown`) and each part of a rendered message may be [characters]
SHOWN_LIMIT = 80
PART_LIMIT = 400
# characters that end a line on a terminal or in a text file (str.splitlines splits at these)
_LINE_BREAKS = "\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"
_ESCAPES = {
    ord(c): f"\\x{ord(c):02x}" if ord(c) < 0x100 else f"\\u{ord(c):04x}" for c in _LINE_BREAKS
}
_ESCAPES.update({ord("\n"): "\\n", ord("\r"): "\\r"})


class _ShortRepr(reprlib.Repr):
    """`reprlib.Repr` that never expands a big value: a few items per level, a few levels, and
    a huge whole number by its size (its full text would take long, or fail beyond 4300 digits)."""

    def __init__(self) -> None:
        super().__init__()
        self.maxlevel = 3
        self.maxlist = self.maxtuple = self.maxset = self.maxfrozenset = self.maxdeque = 6
        self.maxdict = 4
        self.maxstring = self.maxother = SHOWN_LIMIT - 10
        self.maxlong = 40

    def repr_int(self, x: int, level: int) -> str:
        if x.bit_length() > 256:
            return f"<a whole number of about {int(x.bit_length() * math.log10(2)) + 1} digits>"
        return super().repr_int(x, level)


_REPR = _ShortRepr()


def one_line(text: str) -> str:
    """``text`` with its line breaks (also U+2028, U+2029, U+0085) written as escapes."""
    return text.translate(_ESCAPES)


def _clip(text: str, limit: int) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def shown(value: Any, limit: int = SHOWN_LIMIT) -> str:
    """``repr(value)`` for a message: one line of at most ``limit`` characters, cut with ``...``;
    a big list, mapping or text is never expanded in full (a YAML alias bomb stays cheap)."""
    try:
        text = _REPR.repr(value)
    except Exception:  # a value whose repr fails is still named by its type
        text = f"<{type(value).__name__}>"
    return _clip(one_line(text), limit)


class ParcelfitError(ValueError):
    """Bad input a user can fix.

    The message names the file, the place inside it (key, row or column) and the fix, so that
    the command line can show it without a traceback. The rendered text (``str(error)``) is one
    line: line breaks in any part are written as escapes and each part is cut at `PART_LIMIT`
    characters, so a value quoted in the message can never flood the terminal.
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
        def part(text: str) -> str:
            return _clip(one_line(text), PART_LIMIT)

        head = ": ".join(part(p) for p in (self.file, self.where) if p)
        text = f"{head}: {part(self.message)}" if head else part(self.message)
        if self.fix:
            text += f" Fix: {part(self.fix)}"
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


def missing_extra(module: str, exc: ImportError, *, extra: str, what: str) -> ParcelfitError:
    """The error for an optional dependency ``module`` that cannot be imported: ``what`` (e.g.
    "the dask executor") needs it, and the extra of parcelfit named ``extra`` installs it.

    Every import of an optional dependency in parcelfit is written out where it is used (so that
    deptry sees it) inside ``try: ... except ImportError as exc: raise missing_extra(...)``."""
    return ParcelfitError(
        f"{what} needs the {extra!r} extra ({module} cannot be imported: {exc})",
        fix=f'pip install "parcelfit[{extra}]" (in a clone of the repository: '
        f'pip install -e ".[{extra}]")',
    )
