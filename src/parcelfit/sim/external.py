"""Any solver run as a command: parameters in through a file, trajectory out through a CSV.

A solver description (YAML)::

    name: my-recurdyn-model
    command: [python, "${solver_dir}/run_model.py", "${params_file}", "${output_file}"]  # no shell
    template: params.tmpl        # parameter file template, relative to this file
    params_file: params.txt      # name of the rendered file in the run's work folder
    output_file: trajectory.csv  # trajectory the solver writes (columns t,x,y,theta; SI units)
    transit_file: transit.txt    # optional: a file holding the transit time [s] (none written
                                 # or empty: the run crossed no second light barrier)
    timeout: 3600                # wall-clock limit [s]

The template and every command argument may use ``${name}`` placeholders: each catalogue
parameter in SI units (``${mu_d_BePa}``; one the study neither fits nor fixes takes its
catalogue default, a soft content's default for the parameters only a soft content has),
``${rig}``, ``${consignment}``, ``${speed_setting}``, ``${params_file}``, ``${output_file}``,
``${workdir}``, ``${solver_dir}`` (the folder of the description file), and a parameter of the
solver's own that the study fits or fixes. A malformed placeholder is an error when the
description is read (`load_external_solver`), one that names none of these when the study is
(`check_placeholders`), before anything runs; a value holding a line break or another control
character (which could add lines to the parameter file) stops the run it would be written into.
Each run gets its own work folder; the command runs there, is never passed through a shell,
reads nothing (stdin is empty) and writes its output to
``parcelfit-solver.stdout`` and ``parcelfit-solver.stderr`` there. The run ends when the command
exits or at the timeout, and then every process the command started is killed, on Linux also
those that started their own session (`parcelfit.sim.lifetime.run_command`). Exit status 0 and
a readable trajectory give ``ok``; a non-zero status ``failed`` at once, with the status and the
solver's last line on stderr in the message and its last output lines in ``output_tail``; the
timeout ``timeout``.
"""

from __future__ import annotations

import codecs
import signal
import string
import subprocess
import tempfile
import time
import unicodedata
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from parcelfit.config import (
    get_number,
    get_str,
    load_config,
)
from parcelfit.errors import ParcelfitError, shown
from parcelfit.runs import Run, TestCase, read_trajectory
from parcelfit.sim.lifetime import STDERR_FILE, STDOUT_FILE, run_command
from parcelfit.sim.params import defaults_si
from parcelfit.sim.protocol import SimResult, SimStatus

HELP = {  # every key of a solver description, shown in docs/reference/files.md
    "name": "the solver's name, shown in outputs and in its work folders' names",
    "command": "the command and its arguments as a list, run in the work folder without a "
    "shell; placeholders ${...} filled in",
    "template": "the parameter file's template, relative to this file",
    "params_file": "the filled-in template's name in the run's work folder",
    "output_file": "the trajectory your command writes: CSV with t [s], x [m], y [m], "
    "theta [rad] in the rig's frame",
    "transit_file": "optional: a file holding the transit time [s] between the light barriers",
    "timeout": "wall-clock limit of one run [s]",
}
_KEYS = tuple(HELP)
REQUIRED = ("name", "command", "template")  # the keys a description must give


@dataclass(frozen=True)
class ExternalSolver:
    """How to run an external solver (see the module docstring)."""

    name: str
    command: tuple[str, ...]
    template: str
    params_file: str = "params.txt"
    output_file: str = "trajectory.csv"
    transit_file: str | None = None
    timeout: float = 3600.0
    solver_dir: str = "."


def load_external_solver(path: str | Path) -> ExternalSolver:
    """Read and check a solver description file (YAML)."""
    path = Path(path)
    doc = load_config(path, allowed=_KEYS, required=REQUIRED)
    command = doc["command"]
    if (
        not isinstance(command, list)
        or not command
        or not all(isinstance(a, str | int | float) for a in command)
    ):
        raise ParcelfitError(
            "command must be a non-empty list of arguments",
            file=path,
            where="command",
            fix='write e.g. command: [python, model.py, "${params_file}"]',
        )
    template_path = path.parent / get_str(doc, "template", file=path, where="")
    if not template_path.is_file():
        raise ParcelfitError(
            f"template {template_path.name!r} not found",
            file=path,
            where="template",
            fix="give the template's path relative to this file",
        )
    transit = doc.get("transit_file")
    solver = ExternalSolver(
        name=get_str(doc, "name", file=path, where=""),
        command=tuple(str(a) for a in command),
        template=template_path.read_text(encoding="utf-8"),
        params_file=get_str(doc, "params_file", file=path, where="", default="params.txt"),
        output_file=get_str(doc, "output_file", file=path, where="", default="trajectory.csv"),
        transit_file=None if transit is None else get_str(doc, "transit_file", file=path, where=""),
        timeout=get_number(
            doc, "timeout", file=path, where="", default=3600.0, minimum=0.01, unit="s"
        )
        or 3600.0,
        solver_dir=str(path.parent.resolve()),
    )
    # malformed placeholders now; unknown names once the study's own parameters are known
    check_placeholders(solver, path, None)
    return solver


def check_placeholders(
    solver: ExternalSolver, path: str | Path, parameters: Sequence[str] | None
) -> None:
    """Refuse a malformed placeholder in ``solver``'s template or command (file ``path``) and,
    given the study's own ``parameters`` (fitted and fixed), a placeholder that names neither
    one of them, a catalogue parameter nor one of `PLACEHOLDERS`: before anything runs."""
    known = None if parameters is None else {*PLACEHOLDERS, *catalogue_defaults(), *parameters}
    for text, what, where in (
        (solver.template, "the parameter template", "template"),
        *((a, f"command argument {shown(a)}", "command") for a in solver.command),
    ):
        template = string.Template(text)
        if not template.is_valid():
            raise ParcelfitError(
                f"{what} has a malformed placeholder",
                file=str(path),
                where=where,
                fix="write placeholders as ${name} (and a $ itself as $$)",
            )
        unknown = sorted(set(template.get_identifiers()) - known) if known is not None else []
        if unknown:
            raise ParcelfitError(
                f"{what} uses the unknown placeholder ${{{unknown[0]}}}",
                file=str(path),
                where=where,
                fix="use a catalogue parameter (parcelfit params), a parameter the study fits or "
                "fixes, or one of " + ", ".join(PLACEHOLDERS),
            )


# the placeholders beside the catalogue's parameters (the module docstring)
PLACEHOLDERS = (
    "rig",
    "consignment",
    "speed_setting",
    "workdir",
    "solver_dir",
    "params_file",
    "output_file",
)


def catalogue_defaults() -> dict[str, float]:
    """Every catalogue parameter's default [SI], those of a soft content's included: what a
    template's placeholder of a parameter the study neither fits nor fixes is filled with."""
    return {**defaults_si("soft"), **defaults_si("rigid")}


# characters a name must not hold: control characters (Cc: line feed, carriage return, U+0085,
# ...), Unicode's line and paragraph separators (Zl U+2028, Zp U+2029), which many programs and
# languages read as line breaks, and invisible format characters (Cf: U+200B-U+200F,
# U+202A-U+202E, U+2066-U+2069, U+FEFF, ...), which can hide or reorder what a line shows
_REFUSED_CATEGORIES = frozenset({"Cc", "Cf", "Zl", "Zp"})


def refused_character(text: str) -> str | None:
    """The first character of ``text`` that could add a line to a file or hide what it says
    (see `_REFUSED_CATEGORIES`), as ``U+XXXX``; None if there is none."""
    for c in text:
        if unicodedata.category(c) in _REFUSED_CATEGORIES:
            return f"U+{ord(c):04X}"
    return None


def _substitute(text: str, values: Mapping[str, Any], what: str) -> str:
    for key, value in values.items():
        # a line break (or any control character) in a name would add lines to the file
        found = refused_character(str(key)) or refused_character(str(value))
        if found is not None:
            name = shown(str(key)) if refused_character(str(key)) else key
            raise ParcelfitError(
                f"the value of ${{{name}}} ({shown(str(value))}) holds a line break or another "
                f"control or invisible format character ({found}), which would change {what}",
                fix="use names without line breaks, control or format characters",
            )
    try:
        out = string.Template(text).substitute({k: str(v) for k, v in values.items()})
    except KeyError as exc:
        raise ParcelfitError(
            f"{what} uses the unknown placeholder ${{{exc.args[0]}}}",
            fix=f"use one of: {', '.join(sorted(values))}",
        ) from None
    except ValueError as exc:
        raise ParcelfitError(
            f"{what} has a malformed placeholder ({exc})", fix="write placeholders as ${name}"
        ) from None
    if len(out.splitlines()) != len(text.splitlines()):  # the checks above hold: defence in depth
        raise ParcelfitError(
            f"filling in {what} would change its number of lines",
            fix="use names without line breaks or control characters",
        )
    return out


def _last_lines(*texts: str | bytes | None, n: int = 10) -> str:
    """The last ``n`` non-empty lines of ``texts`` joined (output captured as text or bytes)."""
    joined = "\n".join(
        t.decode("utf-8", "replace") if isinstance(t, bytes) else t for t in texts if t
    )
    return "\n".join([line for line in joined.splitlines() if line.strip()][-n:])


def _read_text(path: Path) -> str:
    """A small text file a solver wrote: UTF-8 (a byte-order mark allowed) or UTF-16 with its
    byte-order mark (as Windows PowerShell writes by default); other bytes are refused naming
    the file."""
    data = path.read_bytes()
    try:
        if data.startswith((codecs.BOM_UTF32_LE, codecs.BOM_UTF32_BE)):  # before UTF-16's
            return data.decode("utf-32")
        if data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
            return data.decode("utf-16")
        if b"\x00" in data:  # NUL bytes are valid UTF-8 but no digit: UTF-16 without its mark
            raise UnicodeDecodeError("utf-8", data, 0, len(data), "NUL bytes")
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ParcelfitError(
            "its transit file is not text (neither UTF-8 nor UTF-16 with a byte-order mark)",
            file=path,
            fix="write the transit time in seconds alone as UTF-8 text, e.g. 1.234",
        ) from None


def _signal_name(number: int) -> str:
    try:
        return signal.Signals(number).name
    except ValueError:
        return str(number)


class ExternalSimulator:
    """`Simulator` that renders a parameter file, runs a command and reads its trajectory back."""

    def __init__(self, solver: ExternalSolver, workroot: str | Path | None = None) -> None:
        self.solver = solver
        self.workroot = None if workroot is None else Path(workroot)

    def run(
        self, params: Mapping[str, float], case: TestCase, run_id: str | None = None
    ) -> SimResult:
        """Run the solver for SI ``params`` and ``case``; failures become a status, never an exception."""
        t0 = time.perf_counter()
        logs = {STDOUT_FILE, STDERR_FILE}
        if logs & {self.solver.params_file, self.solver.output_file, self.solver.transit_file}:
            raise ParcelfitError(
                f"the solver's files may not be named {' or '.join(sorted(logs))}: parcelfit "
                "writes the solver's output there",
                fix="rename params_file, output_file or transit_file in the solver description",
            )
        if self.workroot is not None:
            self.workroot.mkdir(parents=True, exist_ok=True)
        workdir = Path(tempfile.mkdtemp(prefix=f"{self.solver.name}-", dir=self.workroot))
        values: dict[str, Any] = {
            **catalogue_defaults(),
            **params,
            "rig": case.rig,
            "consignment": case.consignment,
            "speed_setting": case.speed_setting,
            "workdir": workdir,
            "solver_dir": self.solver.solver_dir,
            "params_file": workdir / self.solver.params_file,
            "output_file": workdir / self.solver.output_file,
        }
        (workdir / self.solver.params_file).write_text(
            _substitute(self.solver.template, values, "the parameter template"), encoding="utf-8"
        )
        args = [_substitute(a, values, f"command argument {shown(a)}") for a in self.solver.command]
        diagnostics: dict[str, object] = {"workdir": str(workdir), "command": args}
        try:
            proc = run_command(args, workdir, self.solver.timeout)
        except subprocess.TimeoutExpired as exc:
            diagnostics["message"] = f"killed after the timeout of {self.solver.timeout:g} s"
            diagnostics["output_tail"] = _last_lines(exc.stdout, exc.stderr)
            return SimResult(None, SimStatus.TIMEOUT, time.perf_counter() - t0, diagnostics)
        except OSError as exc:
            diagnostics["message"] = f"could not start the solver: {exc}"
            return SimResult(None, SimStatus.FAILED, time.perf_counter() - t0, diagnostics)
        diagnostics["output_tail"] = _last_lines(proc.stdout, proc.stderr)
        if proc.returncode != 0:
            # what the solver said last on stderr (else stdout) belongs in the one-line message
            said = _last_lines(proc.stderr, n=1) or _last_lines(proc.stdout, n=1)
            if proc.returncode < 0:
                how = f"was killed by signal {_signal_name(-proc.returncode)}"
            else:
                how = f"exited with status {proc.returncode}"
            diagnostics["message"] = (
                f"the solver {how}"
                + (f": {said}" if said else "")
                + f" (its output: {STDERR_FILE} in {workdir})"
            )
            return SimResult(None, SimStatus.FAILED, time.perf_counter() - t0, diagnostics)
        output = workdir / self.solver.output_file
        if not output.is_file():
            diagnostics["message"] = (
                f"the solver exited 0 but wrote no {self.solver.output_file} in its work folder "
                f"{workdir} (output_file in the solver description; its own output is in "
                f"{STDOUT_FILE} and {STDERR_FILE} there)"
            )
            return SimResult(None, SimStatus.FAILED, time.perf_counter() - t0, diagnostics)
        try:
            traj = read_trajectory(output)
            transit = None
            transit_path = workdir / self.solver.transit_file if self.solver.transit_file else None
            # no file, or an empty one: the parcel crossed no second light barrier
            if transit_path is not None and transit_path.is_file():
                text = _read_text(transit_path).strip()
                try:
                    transit = float(text) if text else None
                except ValueError:
                    raise ParcelfitError(
                        f"its transit file holds {shown(text)}, not a number of seconds",
                        file=transit_path,
                        fix="write the transit time in seconds alone, e.g. 1.234",
                    ) from None
            run = Run(
                run_id or f"ext-{case.rig}-{case.consignment}-{case.speed_setting}",
                case,
                traj,
                transit,
            )
        except (ParcelfitError, OSError, ValueError) as exc:
            diagnostics["message"] = f"unusable solver output: {exc}"
            return SimResult(None, SimStatus.FAILED, time.perf_counter() - t0, diagnostics)
        diagnostics["message"] = "ok"
        return SimResult(run, SimStatus.OK, time.perf_counter() - t0, diagnostics)
