"""The one exception type parcelfit raises for bad input, with where and how to fix it, and
`shown`, the short one-line form in which a message quotes a value the user wrote."""

from __future__ import annotations

import math
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
