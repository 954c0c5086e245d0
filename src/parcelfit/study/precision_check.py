"""Run a precision check of a study: simulate each parameter at both ends of its range on the
study's cases and candidate cases, and judge what the real runs can determine
(`parcelfit.study.precision` holds the formulas).

For every parameter of the study, every fitted case and every candidate (the study's validation
and transfer cases and any named in ``candidates``, real runs from the first case's dataset) is
simulated with the parameter at the low and at the high end of its range, every other parameter
at the centre of its range or at the values ``at`` gives (catalogue units), over K seeded
placements (seeds 1..K, the same at both ends); the same K placements at the point itself give
the placements' scatter there. Each run's statistics are written to
``statistics.json`` in the output folder the moment it arrives (the file rewritten through a
temporary one, `parcelfit.atomic.write_text_atomic`), so a killed or interrupted check keeps
every finished simulation and resumes with the others, and a rerun with more candidates
simulates only the new cases; a folder holding the runs of a check at
another point, range or simulator is refused, never overwritten. The table goes to
``precision-check.md``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from parcelfit.atomic import write_text_atomic
from parcelfit.errors import ParcelfitError, os_error
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
from parcelfit.study.joint import simulate_items
from parcelfit.study.loop import study_executor
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
from parcelfit.study.studyfile import CaseSpec, fixed_to_si, load_study

STATISTICS_FILE = "statistics.json"
# what statistics.json holds per run: the raw statistics, then the ridden speeds (an adjustment
# of the transit time is applied when the table is made, so one cache serves both)
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
    cache_file = out / STATISTICS_FILE
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
    cache: dict[str, list[float] | None] = {}
    if cache_file.exists():
        saved = json.loads(cache_file.read_text(encoding="utf-8"))
        if saved.get("setup") != setup:
            # never overwrite another check's simulations (hours of them, perhaps)
            raise ParcelfitError(
                f"{cache_file} holds the runs of a check at another point, range or simulator",
                file=cache_file,
                fix="give another --out folder, or delete the file to simulate afresh",
            )
        cache = saved["runs"]

    keys = []
    items = []
    owners = []
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
                if run_id not in cache:
                    items.append((Task(dict(values), spec.case, run_id), seed))
                    owners.append((spec.label, run_id))
    simulator = make_simulator(study.simulator)
    if items and not callable(getattr(simulator, "with_placement", None)):
        raise ParcelfitError(
            f"the {type(simulator).__name__} simulator has no seeded placements "
            "(with_placement), so every placement would repeat one run",
            file=study_file,
            fix="use a simulator with seeded placements (mujoco)",
        )

    def save() -> None:
        try:
            write_text_atomic(cache_file, json.dumps({"setup": setup, "runs": cache}))
        except OSError as exc:  # a full disk: the file keeps the runs saved before
            raise os_error(exc, cache_file, resumes=True) or exc from None

    start = time.perf_counter()
    total = len(items)
    progress(
        ProgressEvent("precision", f"{total} simulations ({len(keys) - total} kept)", 0, total)
    )
    if items:
        with study_executor(study, executor, None, workers) as pool:
            for done, (i, result) in enumerate(simulate_items(pool, simulator, items), 1):
                label, run_id = owners[i]
                stats = None
                if result.ok and result.run is not None:
                    stats = run_statistics(result.run, comparisons[label])
                    if stats is not None:  # raw statistics and the speeds an adjustment needs
                        stats = [*stats, *ridden_speeds(result.run.trajectory)]
                cache[run_id] = None if stats is None else [float(v) for v in stats]
                save()  # every run as it arrives: a kill loses only the runs still going
                message = f"{done}/{total} simulations ({time.perf_counter() - start:.0f} s)"
                progress(ProgressEvent("precision", message, done, total))
    wall = time.perf_counter() - start

    per_end: dict[tuple[str, str, str], list[np.ndarray | None]] = {}
    for label, name, end, run_id in keys:
        v = cache[run_id]
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
        for spec in specs
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
    """How many simulations a check in ``folder`` has kept (`STATISTICS_FILE`; 0 if none)."""
    cache = folder / STATISTICS_FILE
    return len(json.loads(cache.read_text(encoding="utf-8"))["runs"]) if cache.is_file() else 0


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
