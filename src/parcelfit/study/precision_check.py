"""Run a precision check of a study: simulate each parameter at both ends of its range on the
study's cases and candidate cases, and judge what the real runs can determine
(`parcelfit.study.precision` holds the formulas).

For every parameter of the study, every fitted case and every candidate (the study's validation
and transfer cases and any named in ``candidates``, real runs from the first case's dataset) is
simulated with the parameter at the low and at the high end of its range, every other parameter
at the centre of its range or at the values ``at`` gives (catalogue units), over K seeded
placements (seeds 1..K, the same at both ends); the same K placements at the point itself give
the placements' scatter there. Every simulation is kept in an evaluation store in the output
folder (``precision.sqlite``, `parcelfit.study.store`, kind ``precision``: its parameter
values, placement seed and case, written pending before the simulations start and finished the
moment each arrives, with its statistics and the ridden speeds), so a killed or interrupted
check keeps every finished simulation and resumes with the others, as a study does, and a
rerun with more candidates simulates only the new cases; a folder holding the runs of a check
at another point, range or simulator is refused, never overwritten. (A ``statistics.json``
kept by an earlier parcelfit is taken over.) The simulations run through the study loop
(`parcelfit.study.loop.DesignLoop`): 8 failing one after the other before the first success
stop the check, quoting the first failure, and what failed runs again on a rerun while nothing
has succeeded. The table goes to ``precision-check.md``.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from itertools import groupby
from pathlib import Path
from typing import Any

import numpy as np

from parcelfit.atomic import write_text_atomic
from parcelfit.errors import ParcelfitError
from parcelfit.metrics.comparison import Comparison
from parcelfit.metrics.transit_adjustment import (
    TransitAdjustment,
    fit_transit_adjustment,
    ridden_speeds,
)
from parcelfit.progress import ProgressCallback, ProgressEvent, ignore_progress
from parcelfit.runs import TestCase, load_dataset
from parcelfit.sim.ensemble import MAX_PLACEMENTS
from parcelfit.sim.executors import Task
from parcelfit.sim.factory import make_simulator
from parcelfit.study.details import EvaluationDetails
from parcelfit.study.joint import places_runs, simulate_items
from parcelfit.study.loop import DesignLoop, FixedDesign, study_executor
from parcelfit.study.objective import Evaluated
from parcelfit.study.precision import (
    STATISTICS,
    WITHIN,
    CaseSensitivity,
    Precision,
    Subset,
    best_subsets,
    half_width_text,
    precision,
    run_statistics,
    sensitivity,
)
from parcelfit.study.store import Evaluation, Store, finished_count
from parcelfit.study.studyfile import CaseSpec, Study, fixed_to_si, load_study

PRECISION_STORE = "precision.sqlite"  # a check's simulations, in its output folder
STATISTICS_FILE = "statistics.json"  # where an earlier parcelfit kept them
# what is kept per run: the raw statistics, then the ridden speeds (an adjustment of the
# transit time is applied when the table is made, so one store serves both)
CACHED = "transit s, rotation rad, lateral drift m, v_start m/s, v_end m/s"
TABLE_FILE = "precision-check.md"
SUBSET_SIZE = 4  # the method's "at most four parameters go into calibration" (method.md 6)
WIDE = 6  # with more parameters than this, the table lists one parameter per row


@dataclass(frozen=True)
class PrecisionCheck:
    """The outcome of a precision check: the sensitivity of every case (fitted first, then the
    candidates), how many simulations it took and how many of them ran now."""

    names: tuple[str, ...]
    fitted: tuple[str, ...]
    candidates: tuple[str, ...]
    sensitivities: Mapping[str, CaseSensitivity]
    placements: int
    simulations: int
    simulated_now: int
    wall_time: float  # s, of the simulations run now
    at_given: bool
    adjustments: Mapping[str, TransitAdjustment] = field(default_factory=dict)

    def rows(self) -> list[tuple[str, Precision]]:
        """The fitted cases jointly, each fitted case alone (if several), the fitted cases plus
        each candidate, and plus every candidate (if several)."""
        sens = self.sensitivities
        fitted = [sens[f] for f in self.fitted]
        groups = [(" + ".join(self.fitted) + " (fitted)", fitted)]
        if len(self.fitted) > 1:
            groups += [(f, [sens[f]]) for f in self.fitted]
        groups += [(f"fitted + {c}", [*fitted, sens[c]]) for c in self.candidates]
        if len(self.candidates) > 1:
            groups.append(("fitted + every candidate", list(sens.values())))
        return [(title, precision(group)) for title, group in groups]

    def subsets(self, top: int = 5) -> list[tuple[str, list[Subset]]]:
        """With more parameters than `SUBSET_SIZE`: the ``top`` subsets of that many that the
        fitted cases (and, with candidates, all cases) would determine best, the others fixed;
        otherwise nothing."""
        if len(self.names) <= SUBSET_SIZE:
            return []
        sens = self.sensitivities
        groups = [(" + ".join(self.fitted) + " (fitted)", [sens[f] for f in self.fitted])]
        if self.candidates:
            groups.append(("fitted + every candidate", list(sens.values())))
        return [(title, best_subsets(group, SUBSET_SIZE, top)) for title, group in groups]

    def write_tables(self, folder: Path, command: str, workers: int | None) -> Path:
        """Write `markdown` into ``folder``/`TABLE_FILE` (atomically); return the file."""
        path = folder / TABLE_FILE
        write_text_atomic(path, self.markdown(command, workers))
        return path

    def markdown(self, command: str, workers: int | None) -> str:
        """The tables of the check, headed by the ``command`` that wrote them."""
        lines = [
            "# Precision check: what the test cases can determine",
            "",
            f"Written by `{command}`: {self.simulations} simulations ({self.simulated_now} in "
            f"this run, {self.wall_time:.0f} s on {workers or 'all'} process(es)). Every other "
            "parameter at "
            + ("the given values" if self.at_given else "the centre of its range")
            + " (`parcelfit.study.precision`: linear, Gaussian estimate from the change of the "
            "mean transit time, rotation and lateral drift over each parameter's range and the "
            "scatter of the real runs or, where larger, of the placements).",
            "",
        ]
        if self.adjustments:
            lines += [
                "Transit times adjusted for the belt speeds each run rode at "
                "(`parcelfit.metrics.transit_adjustment`), real and simulated runs alike:",
                "",
                *(f"- {label}: {a.describe()}" for label, a in self.adjustments.items()),
                "",
            ]
        lines += [
            "95 % half-width each parameter could be determined to, as a share of its range (* "
            "where <= 10 %; 57 % means no information). Joint: the other parameters free; alone: "
            "the others known. Only the effects the placements resolve count.",
            "",
        ]
        rows = self.rows()
        if len(self.names) > WIDE:  # one row per parameter, one column per set of cases
            lines += [
                "| parameter | " + " | ".join(f"{t} joint / alone" for t, _ in rows) + " |",
                "|" + "---|" * (1 + len(rows)),
            ]
            for j, name in enumerate(self.names):
                cells = " | ".join(
                    f"{half_width_text(p.joint[j])} / {half_width_text(p.alone[j])}"
                    for _, p in rows
                )
                lines.append(f"| {name} | {cells} |")
        else:
            lines += [
                "| cases | " + " | ".join(f"{n} joint | {n} alone" for n in self.names) + " |",
                "|" + "---|" * (1 + 2 * len(self.names)),
            ]
            for title, p in rows:
                cells = " | ".join(
                    f"{half_width_text(j)} | {half_width_text(a)}"
                    for j, a in zip(p.joint, p.alone, strict=True)
                )
                lines.append(f"| {title} | {cells} |")
        doubtful = [(title, p, p.unresolved()) for title, p in rows]
        doubtful = [(title, p, names) for title, p, names in doubtful if names]
        if doubtful:
            lines += [
                "",
                "Not counted: effects the placements do not resolve (below twice their standard "
                "error, marked - below) carry no information. Counted as if they were real they "
                f"would determine these parameters within {100 * WITHIN:.0f} % alone; more "
                "placements (`--placements`) would tell whether they are:",
                "",
            ]
            for title, p, names in doubtful:
                found = ", ".join(
                    f"{n} {half_width_text(h)}"
                    for n, h in zip(p.names, p.alone_unresolved, strict=True)
                    if n in names
                )
                lines.append(f"- {title}: {found}")
        for title, found in self.subsets():
            lines += [
                "",
                f"Which {SUBSET_SIZE} to calibrate, {title}: the subsets these cases would "
                "determine best, each fitted with every other parameter fixed at the point's "
                "value (`parcelfit.study.precision.best_subsets`; 95 % half-widths).",
                "",
                f"| parameters | within {100 * WITHIN:.0f} % | half-widths |",
                "|---|---|---|",
            ]
            for sub in found:
                lines.append(f"| {', '.join(sub.names)} | {sub.determined} | {sub.widths_text()} |")
        lines += [
            "",
            "Sensitivity per case: change of the mean statistic over the parameter's whole range "
            "(standard error over the placements; - where not resolved, below twice it), the "
            "real runs' standard deviation and the placements' (at the point, over the same "
            "placements; the larger of the two counts).",
            "",
            "| case | statistic | real sd | placements' sd | " + " | ".join(self.names) + " |",
            "|" + "---|" * (4 + len(self.names)),
        ]
        for label, s in self.sensitivities.items():
            sd = s.real_sd
            model = s.model_sd if s.model_sd is not None else np.full(len(STATISTICS), np.nan)
            for k, stat in enumerate(STATISTICS):
                cells = " | ".join(
                    f"{s.jacobian[k, j]:+.4g} ({s.jacobian_se[k, j]:.2g})"
                    + ("" if s.resolved[k, j] else " -")
                    for j in range(len(self.names))
                )
                lines.append(
                    f"| {label} ({len(s.real)} real) | {stat} | {sd[k]:.3g} | {model[k]:.3g} "
                    f"| {cells} |"
                )
        return "\n".join(lines) + "\n"


def _key(label: str, values: Mapping[str, float], seed: int | None) -> str:
    """What identifies a run of a check: its case, parameter values (SI) and placement seed."""
    return json.dumps([label, dict(sorted(values.items())), seed])


def _statistics(row: Evaluation) -> list[float] | None:
    """A kept run's statistics and ridden speeds (`CACHED`), None without statistics."""
    d = row.details
    if row.status != "ok" or row.transit_time is None or d.lateral_drift is None:
        return None
    values = (row.transit_time, d.region_rotation, d.lateral_drift, d.start_speed, d.end_speed)
    return [math.nan if v is None else float(v) for v in values]


Wanted = Mapping[str, tuple[CaseSpec, dict[str, float], int]]  # run id: case, values, seed


class _CheckRuns:
    """The simulations of one check in its store (module docstring): ``statistics`` of those
    finished by run id (None for a run without statistics), `pending` the others. A store or
    an earlier ``statistics.json`` of a check with another ``setup`` is refused."""

    def __init__(self, out: Path, setup: Mapping[str, Any], wanted: Wanted) -> None:
        self.wanted = wanted
        self.folder = out
        self._run_of: dict[int, str] = {}  # store row id: run id
        path, legacy = out / PRECISION_STORE, out / STATISTICS_FILE
        old: Mapping[str, list[float] | None] = {}
        if not path.is_file() and legacy.is_file():  # kept by an earlier parcelfit
            doc = json.loads(legacy.read_text(encoding="utf-8"))
            _same_setup(doc.get("setup"), setup, legacy)
            old = doc["runs"]
        self.store = Store(path)
        try:
            _same_setup(self.store.get_meta("setup"), setup, path)
            self.store.set_meta("setup", setup)
            by_key = {_key(s.label, v, seed): run_id for run_id, (s, v, seed) in wanted.items()}
            self.rows: dict[str, Evaluation] = {}
            for e in self.store.evaluations("precision"):
                run_id = by_key.get(_key(e.details.case or "", e.params, e.seed))
                if run_id is not None:
                    self.rows[run_id] = e
            self._add([r for r in wanted if r not in self.rows])
            self.statistics = {
                r: _statistics(e) for r, e in self.rows.items() if e.status != "pending"
            }
            for run_id, stats in old.items():
                if run_id in wanted and run_id not in self.statistics:
                    self.finish(run_id, "ok" if stats else "failed", stats, None)
        except BaseException:
            self.store.close()
            raise

    def _add(self, missing: Sequence[str]) -> None:
        """Record the ``missing`` runs as pending, one batch (iteration) per check run, each
        case's runs in slots of their own."""
        if not missing:
            return
        iteration = 1 + max((e.iteration for e in self.rows.values()), default=-1)
        slot = 0
        for _, group in groupby(missing, key=lambda r: self.wanted[r][0].label):
            ids = list(group)
            spec = self.wanted[ids[0]][0]
            self.store.add_pending(
                "precision",
                iteration,
                [self.wanted[r][1] for r in ids],
                spec.case.speed_setting,
                [self.wanted[r][2] for r in ids],
                first_slot=slot,
                details=EvaluationDetails(case=spec.label),  # so a resumed check finds them
            )
            slot += len(ids)
        added = [e for e in self.store.evaluations("precision") if e.iteration == iteration]
        self.rows.update(zip(missing, sorted(added, key=lambda e: e.slot), strict=True))

    def current(self) -> list[Evaluation]:
        """The store rows of the wanted runs as stored now, in the order of ``wanted``."""
        by_id = {e.id: e for e in self.store.evaluations("precision")}
        return [by_id[self.rows[r].id] for r in self.wanted]

    def loop(
        self,
        simulate: Callable[[list[Evaluation]], Iterator[Evaluated]],
        report: Callable[[int, int, Evaluated], None],
        folder: Path,
    ) -> tuple[DesignLoop, list[Evaluation]]:
        """The check's runs as a fixed design over the study loop (`DesignLoop`: what failed
        runs again while none has succeeded, a streak of failures before the first success
        stops it), and the rows still to simulate, in the order of ``wanted``."""
        loop = DesignLoop(
            FixedDesign([values for _, values, _ in self.wanted.values()]),
            self.current,
            None,  # every wanted run is stored (pending) when the runs are opened
            simulate,
            report,
            folder,
            reopen=partial(self.store.reopen, keep_case=True),
        )
        self._run_of = {e.id: r for r, e in self.rows.items()}
        todo = loop.replay()
        self.statistics = {
            r: _statistics(e)
            for r, e in zip(self.wanted, self.current(), strict=True)
            if e.status != "pending"
        }
        return loop, todo

    def run_id(self, row: Evaluation) -> str:
        """The run id of a store row of the check."""
        return self._run_of[row.id]

    def finish(
        self,
        run_id: str,
        status: str,
        stats: Sequence[float] | None,
        message: object,
        wall_time: float | None = None,
    ) -> None:
        """Keep the outcome of run ``run_id``: its status, statistics and ridden speeds
        (`CACHED`; None without statistics) and why it failed."""
        doc: dict[str, Any] = {"case": self.wanted[run_id][0].label}
        if stats is not None:
            doc.update(
                region_rotation=stats[1],
                lateral_drift=stats[2],
                start_speed=stats[3],
                end_speed=stats[4],
            )
        if message:
            doc["message"] = str(message)
        self.store.finish(
            self.rows[run_id].id,
            status=status,
            transit_time=None if stats is None else stats[0],
            wall_time=wall_time,
            details=EvaluationDetails.from_json(doc),
        )
        self.statistics[run_id] = None if stats is None else [float(v) for v in stats]


def _same_setup(saved: Any, setup: Mapping[str, Any], where: Path) -> None:
    """Refuse a folder whose kept runs are another check's (hours of them, perhaps)."""
    if saved is not None and saved != setup:
        raise ParcelfitError(
            f"{where} holds the runs of a check at another point, range or simulator",
            file=where,
            fix="give another --out folder, or delete the file to simulate afresh",
        )


def run_precision_check(
    study_file: Path,
    out: Path,
    *,
    placements: int = 10,
    candidates: Sequence[str] = (),
    at: Mapping[str, float] | None = None,
    adjust_transit: bool = False,
    executor: str | None = None,
    workers: int | None = None,
    progress: ProgressCallback = ignore_progress,
) -> PrecisionCheck:
    """Run the check of the module docstring for ``study_file`` into the folder ``out``;
    ``candidates`` are test-case labels (RIG/TYPE/SETTING), ``at`` values in catalogue units;
    ``adjust_transit`` compares transit times adjusted for the belt speeds each run rode at
    (`parcelfit.metrics.transit_adjustment`); ``executor`` and ``workers`` override the study
    file's ``executor`` (as for a calibration)."""
    if placements < 2:
        raise ParcelfitError(
            f"{placements} placement(s): the sensitivity's standard error needs two or more",
            fix="use --placements 2 or more (10 is the default)",
        )
    if placements > MAX_PLACEMENTS:
        raise ParcelfitError(
            f"{placements} placements per case and parameter end, more than {MAX_PLACEMENTS}",
            fix=f"use --placements {MAX_PLACEMENTS} or fewer (10 is the default)",
        )
    study = load_study(study_file)
    names = tuple(study.space.names)
    dims = {d.name: d for d in study.space.dims}
    given = fixed_to_si(dict(at or {}), study.simulator.backend, None, where="--at")
    unknown = sorted(set(given) - set(names))
    if unknown:
        raise ParcelfitError(
            f"--at names {', '.join(unknown)}, not a parameter of the study",
            file=study_file,
            fix=f"use one of {', '.join(names)}",
        )
    point = {**study.fixed, **{n: 0.5 * (dims[n].low + dims[n].high) for n in names}, **given}
    fitted = list(study.cases)
    extra = [*study.validation_cases, *study.transfer]
    for label in candidates:
        spec = CaseSpec(TestCase.parse(label), fitted[0].dataset)
        if all(spec.case != c.case for c in (*fitted, *extra)):
            extra.append(spec)
    specs = [*fitted, *extra]

    datasets = {}
    comparisons: dict[str, Comparison] = {}
    real: dict[str, list[np.ndarray | None]] = {}
    adjustments: dict[str, TransitAdjustment] = {}
    for spec in specs:
        if spec.dataset not in datasets:
            datasets[spec.dataset] = load_dataset(spec.dataset)
        data = datasets[spec.dataset][spec.case]
        comparisons[spec.label] = Comparison.for_case(data)
        if adjust_transit:
            adjustments[spec.label] = fit_transit_adjustment(data.runs)
        real[spec.label] = [
            run_statistics(r, comparisons[spec.label], adjustments.get(spec.label))
            for r in data.runs
        ]

    out.mkdir(parents=True, exist_ok=True)
    bounds = {n: [dims[n].low, dims[n].high] for n in names}
    setup = json.loads(
        json.dumps(
            {
                "point": point,
                "bounds": bounds,
                # the settings the study file gives, without the folder it lies in: the same
                # study in another checkout or folder keeps its runs
                "simulator": {k: repr(v) for k, v in dict(study.simulator).items()},
                "stored": CACHED,
            }
        )
    )
    keys: list[tuple[str, str, str, str]] = []
    wanted: dict[str, tuple[CaseSpec, dict[str, float], int]] = {}
    # (parameter, end, values, run-id tag): the point itself, for the placements' scatter there,
    # then each parameter at each end of its range
    variants = [("", "point", dict(point), "point")] + [
        (name, end, {**point, name: value}, f"{name}-{end}")
        for name in names
        for end, value in (("low", dims[name].low), ("high", dims[name].high))
    ]
    for spec in specs:
        for name, end, values, tag in variants:
            for seed in range(1, placements + 1):
                run_id = f"precision-{spec.label}-{tag}-{seed}"
                keys.append((spec.label, name, end, run_id))
                wanted[run_id] = (spec, dict(values), seed)
    runs = _CheckRuns(out, setup, wanted)
    try:
        return _simulate_and_judge(
            runs,
            study,
            study_file,
            keys,
            comparisons,
            adjustments,
            real,
            placements,
            progress,
            (executor, workers),
            (names, fitted, extra, given),
        )
    finally:
        runs.store.close()


def _simulate_and_judge(
    runs: _CheckRuns,
    study: Study,
    study_file: Path,
    keys: Sequence[tuple[str, str, str, str]],
    comparisons: Mapping[str, Comparison],
    adjustments: Mapping[str, TransitAdjustment],
    real: Mapping[str, list[np.ndarray | None]],
    placements: int,
    progress: ProgressCallback,
    where: tuple[str | None, int | None],
    what: tuple[tuple[str, ...], list[CaseSpec], list[CaseSpec], Mapping[str, float]],
) -> PrecisionCheck:
    """Simulate the runs ``runs`` does not hold yet (``where``: executor and workers), then
    judge every case from its kept statistics."""
    names, fitted, extra, given = what

    def simulate(rows: list[Evaluation]) -> Iterator[Evaluated]:
        """Simulate the pending ``rows`` at their placements, keep each as it arrives (a kill
        loses only the runs still going) and yield it."""
        ids = [runs.run_id(r) for r in rows]
        items = [
            (Task(dict(runs.wanted[i][1]), runs.wanted[i][0].case, i), runs.wanted[i][2])
            for i in ids
        ]
        with study_executor(study, where[0], None, where[1]) as pool:
            for i, result in simulate_items(pool, simulator, items):
                run_id, spec = ids[i], runs.wanted[ids[i]][0]
                stats = None
                if result.ok and result.run is not None:
                    stats = run_statistics(result.run, comparisons[spec.label])
                    if stats is not None:  # raw statistics and the speeds an adjustment needs
                        stats = [*stats, *ridden_speeds(result.run.trajectory)]
                message = None if result.ok else result.diagnostics.get("message")
                status, wall = result.status.value, result.wall_time
                runs.finish(run_id, status, stats, message, wall)
                said = None if message is None else str(message)
                yield Evaluated(rows[i], status, None, said, run_id)

    def report(done: int, total: int, _: Evaluated) -> None:
        message = f"{done}/{total} simulations ({time.perf_counter() - start:.0f} s)"
        progress(ProgressEvent("precision", message, done, total))

    loop, todo = runs.loop(simulate, report, runs.folder)
    simulator = make_simulator(study.simulator)
    if todo and not places_runs(simulator):
        raise ParcelfitError(
            f"the {type(simulator).__name__} simulator has no seeded placements "
            "(with_placement), so every placement would repeat one run",
            file=study_file,
            fix="use a simulator with seeded placements (mujoco)",
        )

    total = len(todo)
    progress(
        ProgressEvent("precision", f"{total} simulations ({len(keys) - total} kept)", 0, total)
    )
    start = time.perf_counter()
    if todo:
        loop.evaluate(todo)
    wall = time.perf_counter() - start

    per_end: dict[tuple[str, str, str], list[np.ndarray | None]] = {}
    for label, name, end, run_id in keys:
        v = runs.statistics[run_id]
        stats = None
        if v is not None:
            stats = np.array(v[:3])
            if label in adjustments:
                stats[0] = adjustments[label].adjust(v[0], v[3:5])
        per_end.setdefault((label, name, end), []).append(stats)
    sens = {
        spec.label: sensitivity(
            spec.label,
            names,
            {n: per_end[(spec.label, n, "low")] for n in names},
            {n: per_end[(spec.label, n, "high")] for n in names},
            real[spec.label],
            per_end[(spec.label, "", "point")],
        )
        for spec in (*fitted, *extra)
    }
    return PrecisionCheck(
        names,
        tuple(s.label for s in fitted),
        tuple(s.label for s in extra),
        sens,
        placements,
        len(keys),
        total,
        wall,
        bool(given),
        adjustments,
    )


def stored_runs(folder: Path) -> int:
    """How many simulations a check in ``folder`` has kept (0 if none)."""
    legacy = folder / STATISTICS_FILE
    if not (folder / PRECISION_STORE).is_file() and legacy.is_file():
        return len(json.loads(legacy.read_text(encoding="utf-8"))["runs"])
    return finished_count(folder / PRECISION_STORE, "precision")


def command_line(
    program: str,
    study_file: Path,
    *,
    placements: int,
    candidates: Sequence[str],
    at: Sequence[str],
    adjust_transit: bool,
    repeated: bool,
) -> str:
    """The command that reproduces a check, as its tables cite it: ``program`` followed by the
    study file and the options as given (``repeated``: one ``--candidate``/``--at`` per value,
    as the CLI takes them; otherwise ``--candidates``/``--at`` followed by all values, as the
    script takes them)."""
    parts = [program, study_file.as_posix(), "--placements", str(placements)]
    for one, many, values in (("--candidate", "--candidates", candidates), ("--at", "--at", at)):
        if values and repeated:
            parts += [item for v in values for item in (one, v)]
        elif values:
            parts += [many, *values]
    if adjust_transit:
        parts.append("--adjust-transit")
    return " ".join(parts)


__all__ = [
    "STATISTICS_FILE",
    "TABLE_FILE",
    "PrecisionCheck",
    "command_line",
    "run_precision_check",
    "stored_runs",
]
