"""The one exception type parcelfit raises for bad input, with where and how to fix it."""

from __future__ import annotations

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
