"""The one exception type parcelfit raises for bad input, with where and how to fix it."""

from __future__ import annotations

from pathlib import Path


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
