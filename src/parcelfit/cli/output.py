"""The terminal side of every command: the consoles, the command group that turns an error into
one red line, progress shown as a spinner, bar or log lines, and what an interrupted command
says it kept."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import typer
from rich.console import Console
from rich.progress import Progress, TimeElapsedColumn
from rich.table import Table
from rich.text import Text
from typer.core import TyperGroup

from parcelfit.errors import ParcelfitError, os_error
from parcelfit.progress import ProgressCallback, ProgressEvent

if TYPE_CHECKING:
    from parcelfit.study.details import CaseCost
    from parcelfit.study.outcome import (
        CalibrationOutcome,
        CalibrationStart,
        Determination,
        ShownValue,
        StudySummary,
    )
    from parcelfit.study.status import StudyStatus
    from parcelfit.study.verdict import Verdict


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


def elapsed_text(started: float) -> str:
    """The wall time since ``started`` (a `time.perf_counter` value [s]) as a user reads it:
    seconds under two minutes, minutes with one decimal from there."""
    seconds = time.perf_counter() - started
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.1f} min"


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


# -- a calibration: its live table and what it concluded ---------------------------------------


class CalibrationDisplay:
    """The live status table of a calibration, as a context: ``started`` (a `CalibrationStart`)
    shows a spinner until the first progress event (while the data are read and the reference
    runs chosen), which prints the expected cost and brings up the table; ``update`` is the
    calibration's progress callback. Outside a terminal (a log, CI) every event is also one
    line and the table shows at the end. Leaving the context stops the display and, once it
    started, ends its line, so that an error found before (a test case the dataset lacks, ...)
    is the only line printed, and what follows starts on a line of its own."""

    def __init__(self, console: Console) -> None:
        self.console = console
        self._start: CalibrationStart | None = None
        self._spinner: Any = None
        self._live: Any = None
        self._event: ProgressEvent | None = None

    def __enter__(self) -> CalibrationDisplay:
        return self

    def started(self, start: CalibrationStart) -> None:
        """Show the spinner of the calibration ``start`` names (`CalibrationStart`)."""
        self._start = start
        self._spinner = self.console.status(
            Text(f"calibration {start.name}: starting (reference runs, workers)")
        )
        self._spinner.start()

    def update(self, event: ProgressEvent) -> None:
        """Show ``event`` (the progress callback)."""
        from rich.live import Live

        self._event = event
        assert self._start is not None  # `started` comes first
        if self._live is None:
            self._spinner.stop()
            if self._start.cost is not None:  # said once the study is read and checked
                self.console.print(Text(self._start.cost, style="cyan"), highlight=False)
            self._live = Live(
                self._table(), console=self.console, refresh_per_second=4, transient=False
            )
            self._live.start()
        self._live.update(self._table())
        if not self.console.is_terminal:  # a log or CI: the table shows only at the end
            best = "-" if event.best_cost is None else f"{event.best_cost:.4g}"
            self.console.print(
                Text(f"{event.message} ({event.done}/{event.total} evaluations, best cost {best})"),
                highlight=False,
            )

    def _table(self) -> Table:
        p, start = self._event, self._start
        assert p is not None and start is not None  # the table shows from the first event on
        table = Table(
            title=Text(f"calibration {start.name} -> {start.folder}"),
            title_justify="left",
            show_header=False,
        )
        table.add_column(style="bold")
        table.add_column()
        verdict = {None: "not yet", True: "[green]passed[/]", False: "[red]failed[/]"}[
            p.last_validation
        ]
        table.add_row("iteration", f"{p.iteration} (0 = initial design)")
        table.add_row("evaluations", f"{p.done} done, {p.running} running, budget {p.total}")
        table.add_row("best cost", "-" if p.best_cost is None else f"{p.best_cost:.4g}")
        table.add_row("last validation", verdict)
        table.add_row("last event", Text(p.message))
        return table

    def __exit__(self, *exc: object) -> None:
        if self._spinner is None:
            return
        self._spinner.stop()
        if self._live is not None:
            if self._event is not None and self._event.running:
                # the job has ended: nothing runs any more (the table stays on the screen)
                self._event = replace(self._event, running=0)
                self._live.update(self._table())
            self._live.stop()
        # outside a terminal the display's last line is left open: end it
        self.console.print()


def print_synthetic(console: Console, status: StudyStatus) -> None:
    """One yellow line naming a study's dataset when it is SYNTHETIC (nothing for real data)."""
    if status.synthetic:
        from parcelfit.runs.dataset import SYNTHETIC_NOTE

        console.print(Text(f"dataset {status.dataset} ({SYNTHETIC_NOTE})", style="yellow"))


def print_outcome(console: Console, outcome: CalibrationOutcome) -> None:
    """What a calibration concluded (`parcelfit.study.outcome.CalibrationOutcome`): how it
    stopped, the recommended parameters, what the data determine, where its figures are and
    the verdict; a SYNTHETIC dataset is named first."""
    if outcome.set_aside is not None:
        console.print(Text(f"the earlier study's outputs are in {outcome.set_aside}"))
    print_synthetic(console, outcome.summary.status)
    console.print(
        Text.assemble(
            (outcome.stop_reason, "bold"),
            f" after {outcome.evaluations} evaluations: "
            f"{iterations_text(outcome.last_iteration)}; study folder {outcome.folder}",
        )
    )
    print_summary(console, outcome.summary)
    figures = outcome.folder / "figures"
    console.print(Text(f"figures in {figures} ({outcome.figures} figures, PNG and SVG)"))
    print_verdict(console, outcome.summary.verdict)


def iterations_text(last: int | None) -> str:
    """The iterations done, in the one numbering (0 = initial design, k >= 1 optimiser batches)."""
    if last is None:
        return "no iteration yet"
    if last == 0:
        return "the initial design (iteration 0)"
    return "the initial design (iteration 0) and " + (
        "iteration 1" if last == 1 else f"iterations 1-{last}"
    )


def print_summary(console: Console, summary: StudySummary) -> None:
    """A study's recommended parameters (what it validates and reports), or while it runs the
    lowest-cost ones so far, their cost case by case (joint and ensemble studies) and what
    the data determine (`parcelfit.study.outcome.StudySummary`); for `calibrate` and
    `status`."""
    rec, low = summary.status.recommended, summary.status.lowest_cost
    if rec is not None:
        at = "" if rec.iteration is None else f", evaluated in iteration {rec.iteration}"
        _print_values(
            console, summary.recommended, f"recommended parameters (cost {rec.cost:.4g}{at})"
        )
        if low is not None and low.params != rec.params:
            console.print(
                f"the lowest single cost was {low.cost:.4g} (iteration {low.iteration}); "
                "the recommendation is the evaluated point with the lowest GP mean cost "
                "(optimizer: {recommend: posterior_mean}, the default)",
                markup=False,
            )
    elif low is not None:
        _print_values(
            console,
            summary.lowest_cost,
            f"lowest-cost parameters so far (cost {low.cost:.4g}, iteration "
            f"{low.iteration}); the study recommends its parameters when it stops",
        )
    shown = summary.status.shown
    if shown is not None and shown.parts:
        _print_parts(console, shown.parts)
    if summary.determined is not None:
        _print_determined(console, summary.determined)


def _print_values(console: Console, values: list[ShownValue] | None, title: str) -> None:
    table = Table(title=Text(title), title_justify="left")
    table.add_column("parameter")
    table.add_column("value", justify="right")
    table.add_column("unit")
    for v in values or ():
        table.add_row(v.name, f"{v.value:.5g}", v.unit)
    console.print(table)


def _print_parts(console: Console, parts: list[CaseCost]) -> None:
    """The per-case parts of a joint or ensemble evaluation's cost (`CaseCost`)."""
    table = Table(title=Text("its cost, case by case"), title_justify="left")
    for col in ("case", "weight", "cost", "parts"):
        table.add_column(col, justify="left" if col in ("case", "parts") else "right")
    for p in parts:
        if p.trajectory_term is not None:
            se = "" if p.se is None else f" (se {p.se:.3g})"
            tt = "-" if p.transit_term is None else f"{p.transit_term:.3g}"
            adjusted = " (adjusted times)" if p.adjusted_transit_times is not None else ""
            what = f"trajectories {p.trajectory_term:.3g}{se}, transit {tt}{adjusted}"
            what += f", {len(p.seeds)} placement{'s' if len(p.seeds) != 1 else ''}"
        else:
            what = f"DTW_xy {p.dtw_xy:.3g} m, DTW_theta {p.dtw_theta:.3g} rad"
        table.add_row(p.case, f"{p.weight:g}", f"{p.cost:.4g}", what)
    console.print(table)


def _print_determined(console: Console, determined: list[Determination]) -> None:
    """Which parameters the data determine: an undetermined parameter's value above is one
    of many the data do not rule out."""
    words = []
    for p in determined:
        unit = f" {p.unit}" if p.unit else ""
        lo, hi = p.low, p.high
        if p.determined:
            words.append(f"{p.name} determined: {(lo + hi) / 2:.4g} +- {(hi - lo) / 2:.2g}{unit}")
        elif p.verdict == "undetermined":
            words.append(
                f"{p.name} NOT determined (less than 10 % of its range ruled out at either end)"
            )
        else:
            words.append(f"{p.name} {p.verdict}: {lo:.4g} - {hi:.4g}{unit}")
    console.print(Text("what the data determine: " + "; ".join(words)), markup=False)


_LEVEL_STYLE = {"trustworthy": "green", "incomplete": "yellow", "not trustworthy": "red"}


def print_verdict(console: Console, verdict: Verdict, tail: str = "") -> None:
    """Every check of a study's overall verdict on a line of its own (published criteria,
    band test, transfer check, convergence check, parameters determined) and the verdict
    (`parcelfit.study.verdict.Verdict`), followed by ``tail``."""
    *checks, _ = verdict.lines()
    for line in checks:
        console.print(Text(line), highlight=False)
    console.print(
        Text.assemble(
            ("verdict: ", "bold"), (verdict.text, f"bold {_LEVEL_STYLE[verdict.level]}"), tail
        ),
        highlight=False,
    )
