"""The terminal side of every command: the consoles, the command group that turns an error into
one red line, progress shown as a spinner, bar or log lines, and what an interrupted command
says it kept."""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

import typer
from rich.console import Console
from rich.progress import Progress, TimeElapsedColumn
from rich.text import Text
from typer.core import TyperGroup

from parcelfit.errors import ParcelfitError, os_error
from parcelfit.progress import ProgressCallback, ProgressEvent


class Commands(TyperGroup):
    """The command group. Errors are handled here, once for every command: a `ParcelfitError`,
    and an `OSError` a user can fix (a path too long, a full disk: `parcelfit.errors.os_error`),
    is shown as one red message and exits with status 2, without a traceback. Ctrl-C prints
    one line, for a resumable command (`resumes`) with what it stored and how to resume, and
    exits with status 130."""

    def invoke(self, ctx: typer.Context) -> Any:
        _resumable.clear()
        try:
            return super().invoke(ctx)
        except ParcelfitError as exc:
            fail(exc)
        except OSError as exc:  # a path too long, a full disk: wherever a file is written
            error = os_error(exc)
            if error is None:
                raise
            fail(error)
        except KeyboardInterrupt:  # Ctrl-C: the workers are stopped already (Executor.close)
            stored = _resumable.pop("stored", None)
            text = "interrupted"
            if stored is not None:
                with contextlib.suppress(Exception):  # what is stored, if it can be read
                    kept = stored()
                    text += "" if kept is None else f": {kept}"
                text += "; rerun the same command to resume"
            err_console.print(Text(text), highlight=False, soft_wrap=True)
            raise typer.Exit(code=130) from None


_resumable: dict[str, Callable[[], str | None]] = {}


def resumes(stored: Callable[[], str | None] = lambda: None) -> None:
    """Declare the running command resumable: interrupted (Ctrl-C), it says
    ``interrupted: <stored()>; rerun the same command to resume`` and exits with status 130.
    ``stored`` words what is kept, e.g. "12 evaluations stored" (None: not counted)."""
    _resumable["stored"] = stored


def stored_count(db: Path, kind: str, what: str) -> Callable[[], str]:
    """For `resumes`: a callable saying how many finished evaluations of ``kind`` the store
    ``db`` holds, as "N what stored" (read when the command is interrupted)."""

    def count() -> str:
        from parcelfit.study.store import finished_count

        return f"{finished_count(db, kind)} {what} stored"

    return count


def fail(exc: ParcelfitError) -> NoReturn:
    """Print ``exc`` as one red line on stderr and exit with status 2."""
    # user text (paths, keys, run ids) is printed as it is, never read as Rich markup
    message = Text.assemble(("error:", "bold red"), " ", str(exc))
    err_console.print(message, highlight=False, soft_wrap=True)
    raise typer.Exit(code=2) from None


console = Console()
err_console = Console(stderr=True)


def status_progress(status: Any, prefix: str) -> ProgressCallback:
    """A progress callback for a long job: on a terminal it updates the spinner's line; when
    the output goes to a log or CI (where the spinner shows nothing) it prints one line per
    event, i.e. per finished evaluation."""

    def say(event: ProgressEvent) -> None:
        if console.is_terminal:
            status.update(f"{prefix}{event.message}")
        else:
            console.print(Text(f"{prefix}{event.message}"), highlight=False)

    return say


def say_cost(estimate: Any) -> None:
    """Print a job's expected cost (`parcelfit.sim.cost.Estimate`) before it starts."""
    console.print(Text(estimate.text(), style="cyan"), highlight=False)


def cost_first(line: str, progress: ProgressCallback) -> ProgressCallback:
    """``progress``, printing the job's expected cost ``line`` at the first event: once its
    files, data and simulator are read and checked, so that an error found while reading them
    is the only line a refused job prints."""
    said: list[bool] = []

    def say(event: ProgressEvent) -> None:
        if not said:
            said.append(True)
            console.print(Text(line, style="cyan"), highlight=False)
        progress(event)

    return say


def progress_bar(job: str) -> tuple[Progress, ProgressCallback]:
    """A progress bar and the callback that drives it: on a terminal the bar appears with the
    first event (not before the inputs are checked); when the output goes to a log or CI, one
    line per event (`status_progress`'s convention). Stop the bar when the job ends."""
    bar = Progress(*Progress.get_default_columns(), TimeElapsedColumn(), console=console)
    task = bar.add_task(job, total=None)

    def show(event: ProgressEvent) -> None:
        if not console.is_terminal:
            console.print(Text(event.message), highlight=False)
            return
        bar.start()
        bar.update(task, description=event.message, completed=event.done, total=event.total)

    return bar, show


def frame_bar() -> Progress:
    return Progress(*Progress.get_default_columns(), TimeElapsedColumn(), console=console)

