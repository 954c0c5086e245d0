"""Twin benchmark: are the calibrated parameters right, not only passing?

    python benchmarks/bench_twin.py [--out bench-twin] [--workers 2] [--truths 3]
                                    [--placements 2] [--e1-placements N] [--budget 48]
                                    [--setups published,joint]
                                    [--real-timestep 1/4800] [--model-timestep 1/2400]
                                    [--belt-friction mujoco|coulomb]
                                    [--parameters NAME=LOW:HIGH ...]

For each of several hidden truths (other than the bundled twin's), the benchmark makes a twin
dataset with parcelfit's MuJoCo model (E3/KPBW at speed settings 1 and 2, E1/KPBW at 1 and 3,
10 runs each; `parcelfit.synth`; the "real" runs at half the model's time step, where the
model's transit times are closer to converged), calibrates it with each setup and prints one table row per
truth and setup:

* ``published``: the published method (E3 setting 1 against its reference run, validation at
  setting 2, the published optimiser configuration, budget 80);
* ``joint``: E3 setting 1 and E1 setting 3 fitted jointly with the ensemble cost (``placements``
  seeded placements per case and evaluation, or ``--e1-placements`` on E1), validation on E3
  setting 2, transfer check on E1 setting 1, the default optimiser, ``budget`` evaluations;
* ``joint-adjusted`` (only when named in ``--setups``): the joint setup with the transit times
  adjusted for the belt speeds each run rode at (``cost.transit: adjusted``,
  `parcelfit.metrics.transit_adjustment`).

``--parameters`` calibrates four other parameters than the published set (catalogue names and
units, e.g. the four a precision check names as the ones the cases determine best); the truths
put them at the same fractions of their ranges, every other parameter at its default.

Columns: parameters whose calibrated value is within 10 % of the range of the truth; how many
the identifiability analysis calls determined, and how many of those are within 10 % (the
report's values); how many reported intervals contain the truth; optimiser evaluations;
simulations (fits, validations, transfer and advice runs); wall time [min]; the validation
verdict (published criteria) and the transfer check (cases passed). The table is also written
as ``results.json`` and ``results.md`` in the output folder. Everything resumes: rerunning the
same command reuses the twin datasets and finished studies.

With MuJoCo it takes 40-95 min on 2 cores for three truths with the published and one joint
setup, the twin datasets made once (each 40 simulations; each calibration up to budget x the
cases' placements simulations; docs/research/twin-benchmark.md has the measured tables); it runs on
demand, not in CI. The test suite runs the
same code on the analytic test simulator with a tiny budget.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

import yaml

from parcelfit.study.calibration import Calibration
from parcelfit.study.results import read_results
from parcelfit.study.store import STORE_FILE, Store
from parcelfit.study.studyfile import load_study

TOLERANCE = 0.10  # of the range's width
PARAMETERS = {  # catalogue units, the published KP/BW calibration set
    "mu_d_BePa": [0.3, 0.6],
    "mu_d_MePa": [0.15, 0.35],
    "E_Pa": [200, 1600],
    "k_MePa": [100, 1000],
}
# hidden truths as fractions of the ranges (the bundled twin is 0.33 / 0.75 / 0.29 / 0.33)
FRACTIONS = [
    (0.70, 0.30, 0.70, 0.70),
    (0.25, 0.60, 0.40, 0.20),
    (0.50, 0.85, 0.15, 0.55),
    (0.85, 0.50, 0.60, 0.85),
]


@dataclass(frozen=True)
class Setup:
    """One way to calibrate: a name and the study-file keys it sets (paths relative to the
    study file; ``{dataset}`` is replaced by the twin dataset's folder); ``kind`` is what
    ``--setups`` selects it by, its name that kind with ``suffix`` (such as ``-e1x2``)."""

    kind: str
    keys: Mapping[str, Any]
    suffix: str = ""

    @property
    def name(self) -> str:
        """The setup's name: its kind and suffix (the folder and table row of its runs)."""
        return self.kind + self.suffix


@dataclass
class Row:
    """One calibration's line of the table."""

    truth: str
    setup: str
    within: int
    parameters: int
    determined: int
    determined_within: int
    covered: int
    evaluations: int
    simulations: int
    minutes: float
    validated: bool | None
    transfer: str
    details: dict[str, Any] = field(default_factory=dict)


def mujoco_setups(placements: int, budget: int, e1_placements: int | None = None) -> list[Setup]:
    """The published, the joint ensemble and the joint ensemble on adjusted transit times
    setups on the E3/E1 twin data (module docstring); ``e1_placements`` gives the E1 case its
    own number of placements (the joint setups' names then end in ``-e1x<N>``)."""
    e1: dict[str, Any] = {"rig": "E1", "speed_setting": 3}
    suffix = ""
    if e1_placements is not None and e1_placements != placements:
        e1["placements"] = e1_placements
        suffix = f"-e1x{e1_placements}"
    published = Setup(
        "published",
        {
            "reference": {"dataset": "{dataset}", "rig": "E3", "speed_setting": 1},
            "validation": {"speed_setting": 2, "every": 5},
            "optimizer": {"sampler": "published"},
            "budget": 80,
        },
    )
    joint = Setup(
        "joint",
        suffix=suffix,
        keys={
            "cases": [{"dataset": "{dataset}", "rig": "E3", "speed_setting": 1}, e1],
            "validation": {"every": 5, "cases": [{"rig": "E3", "speed_setting": 2}]},
            "transfer": [{"rig": "E1", "speed_setting": 1}],
            "cost": {"kind": "ensemble", "placements": placements},
            "budget": budget,
        },
    )
    adjusted = Setup(
        "joint-adjusted",
        suffix=suffix,
        keys={
            **joint.keys,
            "cost": {"kind": "ensemble", "placements": placements, "transit": "adjusted"},
        },
    )
    return [published, joint, adjusted]


def _fill(value: Any, dataset: str) -> Any:
    """``value`` with every ``{dataset}`` string replaced."""
    if isinstance(value, str):
        return value.replace("{dataset}", dataset)
    if isinstance(value, list):
        return [_fill(v, dataset) for v in value]
    if isinstance(value, dict):
        return {k: _fill(v, dataset) for k, v in value.items()}
    return value


def write_study_file(
    folder: Path,
    setup: Setup,
    simulator: Mapping[str, Any],
    parameters: Mapping[str, Sequence[float]],
    dataset: Path,
    seed: int,
    extra: Mapping[str, Any] | None = None,
) -> Path:
    """The study file of one setup on one twin dataset (``folder/<setup>.yaml``)."""
    doc = {
        "name": setup.name,
        "simulator": dict(simulator),
        "parameters": {k: list(v) for k, v in parameters.items()},
        "seed": seed,
        **_fill(dict(setup.keys), str(dataset.resolve())),
        **dict(extra or {}),
    }
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{setup.name}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


ANALYTIC_CHOICES_FILE = "analytic-choices.txt"


def add_analytic_arguments(ap: argparse.ArgumentParser, mirrored: bool = True) -> None:
    """The options of a benchmark on the analytic test simulator: ``--r-nominal`` (the twins
    before 2026-12-06, `analytic_nominal_rigs`) and, with ``mirrored``, ``--mirrored``."""
    ap.add_argument(
        "--r-nominal",
        action="store_true",
        help="rig R's twin runs at the nominal placement, as before 2026-12-06 (the model's "
        "ensemble placements on R scatter: the twin and the model then disagree)",
    )
    if mirrored:
        ap.add_argument(
            "--mirrored",
            action="store_true",
            help="calibrate with antithetic placements (cost.mirrored: each placement beside "
            "its mirror image)",
        )


def analytic_cost(mirrored: bool) -> dict[str, Any]:
    """The ensemble cost of the benchmarks on the analytic test simulator: 2 placements per
    case, mirrored (``cost.mirrored``) with ``--mirrored``."""
    return {"kind": "ensemble", "placements": 2, **({"mirrored": True} if mirrored else {})}


def analytic_nominal_rigs(out: Path, r_nominal: bool, mirrored: bool = False) -> tuple[str, ...]:
    """The rigs whose twin runs start at the nominal placement in a benchmark on the analytic
    test simulator (`tests.fake_sim.write_reference_dataset`'s ``nominal_rigs``): none, so
    that every rig's runs scatter as the calibration's ensemble placements do; ``("R",)`` with
    ``r_nominal`` (``--r-nominal``), the twins these benchmarks made before 2026-12-06, whose
    rig-R runs did not scatter while the model's placements on R did. The choices (and
    ``mirrored``, the calibrations' antithetic placements) are written to ``out``; a rerun into
    the same folder with other choices is refused (its stored datasets and calibrations were
    made the other way), and a folder that holds a benchmark but no record of its choices was
    made before they existed: rig R nominal, independent placements."""
    out.mkdir(parents=True, exist_ok=True)
    mark = out / ANALYTIC_CHOICES_FILE
    said = (
        ("rig R: nominal placement" if r_nominal else "every rig: placement scatter")
        + "; calibrations: "
        + (
            "mirrored placements (transit variance from the pairs' means)"
            if mirrored
            else "independent placements"
        )
    )
    before = "rig R: nominal placement; calibrations: independent placements"
    if mark.is_file():
        made = mark.read_text().strip()
    elif any(p.name != ANALYTIC_CHOICES_FILE for p in out.iterdir()):
        made = before  # a folder of a benchmark from before the choices were recorded
    else:
        made = said
    if made != said:
        raise SystemExit(
            f"{out} holds a benchmark made with {made!r}, not {said!r}: give another --out"
            + (" (or --r-nominal to resume it)" if made == before else "")
        )
    mark.write_text(said + "\n")
    return ("R",) if r_nominal else ()


def truth_values(fractions: Sequence[float], parameters: Mapping[str, Sequence[float]]) -> dict:
    """Catalogue values at ``fractions`` of the parameters' ranges."""
    return {
        name: round(lo + f * (hi - lo), 6)
        for (name, (lo, hi)), f in zip(parameters.items(), fractions, strict=True)
    }


def assess(folder: Path, truth_si: Mapping[str, float]) -> dict[str, Any]:
    """Recovery, intervals and effort of a finished study folder against the truth (SI)."""
    store = Store(folder / STORE_FILE, readonly=True)
    try:
        record = store.read_study()
        recommended = store.read_recommended()
        fits, vals = store.evaluations("fit"), store.evaluations("validation")
        advice = store.get_meta("advice")
    finally:
        store.close()
    results = read_results(folder)
    assert record is not None
    names = list(record.parameters)
    bounds = dict(zip(names, record.bounds, strict=True))
    best = {} if recommended is None else recommended.params
    err = {n: abs(best[n] - truth_si[n]) / (hi - lo) for n, (lo, hi) in bounds.items() if n in best}
    ident = None if results is None else results.identifiability
    intervals = {} if ident is None else {p.name: p for p in ident.parameters}
    determined = [n for n, p in intervals.items() if p.determined]
    # an evaluation: every case's placements (a case may have its own number; a failed
    # evaluation stores no parts, so the count is read from those that have them), or one run
    per_eval = max(
        (
            sum(len(part.seeds) or 1 for part in f.details.cases) if f.details.cases else 1
            for f in fits
        ),
        default=1,
    )
    fit_sims = len(fits) * per_eval
    n_advice = 0
    if advice is not None:
        a = advice["advice"]
        n_advice = 2 * len(a["parameters"]) * len(a["changes"])
    transfer = [] if results is None else list(results.transfer)
    by_iter: dict[int, list[bool]] = {}
    for v in vals:
        by_iter.setdefault(v.iteration, []).append(bool(v.details.passed))
    return {
        "within": sum(e <= TOLERANCE for e in err.values()),
        "errors": err,
        "parameters": len(names),
        "determined": len(determined),
        "determined_within": sum(
            abs(intervals[n].estimate - truth_si[n]) / (bounds[n][1] - bounds[n][0]) <= TOLERANCE
            for n in determined
        ),
        "covered": sum(p.contains(truth_si[n]) for n, p in intervals.items()),
        "verdicts": {n: p.verdict for n, p in intervals.items()},
        "intervals": {n: list(p.interval) for n, p in intervals.items()},
        "evaluations": len(fits),
        "fit_simulations": fit_sims,
        "simulations": fit_sims + len(vals) + len(transfer) + n_advice,
        "validated": any(all(g) for g in by_iter.values()) if by_iter else None,
        "transfer": f"{sum(v.passed for v in transfer)}/{len(transfer)}" if transfer else "-",
    }


def calibrate_timed(
    path: Path, folder: Path, *, workers: int | None = None, figures: bool = False
) -> float:
    """Run (or resume) the study file ``path`` in ``folder``; returns the wall time [min] of the
    run that did the work, kept in ``folder/wall_time.json`` so that a resumed benchmark reports
    the first run's time, not the seconds a resume takes to find everything done."""
    timing = folder / "wall_time.json"
    t0 = time.perf_counter()
    Calibration(load_study(path), folder, workers=workers, figures=figures, key_frames=False).run()
    if not timing.is_file():
        timing.write_text(json.dumps({"minutes": (time.perf_counter() - t0) / 60}))
    stored = json.loads(timing.read_text())
    # files written before the helper by bench_parcel_optimizers hold seconds
    return float(stored["minutes"]) if "minutes" in stored else float(stored["seconds"]) / 60


def run(
    truths: Mapping[str, Mapping[str, float]],
    setups: Sequence[Setup],
    make_dataset: Callable[[Path, Mapping[str, float], int], Path],
    simulator: Mapping[str, Any],
    parameters: Mapping[str, Sequence[float]],
    out: Path,
    *,
    to_si: Callable[[str, float], float],
    extra: Mapping[str, Any] | None = None,
    workers: int | None = None,
    figures: bool = True,
    say: Callable[[str], None] = print,
) -> list[Row]:
    """Make each truth's twin dataset (``make_dataset(folder, truth, seed)`` returns its folder),
    calibrate it with every setup and assess it; ``truths`` maps a label to catalogue values,
    ``to_si`` converts one. ``extra`` adds study-file keys to every setup (e.g. a small
    ``optimizer``); ``figures`` writes each study's figures (the report needs them)."""
    rows = []
    for k, (label, truth) in enumerate(truths.items()):
        dataset = make_dataset(out / label / "data", truth, 100 + k)
        truth_si = {n: to_si(n, v) for n, v in truth.items()}
        for setup in setups:
            path = write_study_file(
                out / label, setup, simulator, parameters, dataset, seed=k, extra=extra
            )
            folder = out / label / setup.name
            say(f"{label} / {setup.name}: calibrating ({folder})")
            minutes = calibrate_timed(path, folder, workers=workers, figures=figures)
            a = assess(folder, truth_si)
            rows.append(
                Row(
                    label,
                    setup.name,
                    a["within"],
                    a["parameters"],
                    a["determined"],
                    a["determined_within"],
                    a["covered"],
                    a["evaluations"],
                    a["simulations"],
                    minutes,
                    a["validated"],
                    a["transfer"],
                    {"truth": dict(truth), **a},
                )
            )
    (out / "results.json").write_text(json.dumps([r.__dict__ for r in rows], indent=1))
    (out / "results.md").write_text(table(rows))
    return rows


def table(rows: Sequence[Row]) -> str:
    """The benchmark's table (Markdown)."""
    lines = [
        "| truth | setup | within 10 % | determined | determined within 10 % | intervals "
        "containing the truth | evaluations | simulations | wall [min] | validation | transfer |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        verdict = "-" if r.validated is None else ("passed" if r.validated else "failed")
        lines.append(
            f"| {r.truth} | {r.setup} | {r.within}/{r.parameters} | {r.determined} | "
            f"{r.determined_within}/{r.determined} | {r.covered}/{r.parameters} | "
            f"{r.evaluations} | {r.simulations} | {r.minutes:.1f} | {verdict} | {r.transfer} |"
        )
    return "\n".join(lines) + "\n"


def parse_ranges(items: Sequence[str]) -> dict[str, list[float]]:
    """``NAME=LOW:HIGH`` items as a parameter space (catalogue units); exits with a message
    naming the bad item."""
    from parcelfit.sim.params import CATALOGUE

    known = {p.name for p in CATALOGUE}
    out: dict[str, list[float]] = {}
    for item in items:
        name, _, span = item.partition("=")
        low, _, high = span.partition(":")
        try:
            lo, hi = float(low), float(high)
        except ValueError:
            raise SystemExit(
                f"--parameters {item}: write NAME=LOW:HIGH, e.g. E_Pa=200:1600"
            ) from None
        if name not in known:
            raise SystemExit(f"--parameters {item}: {name} is not a catalogue parameter")
        if not lo < hi:
            raise SystemExit(f"--parameters {item}: LOW must be below HIGH")
        out[name] = [lo, hi]
    return out


def _seconds(text: str) -> float:
    """A time step [s] as a number or a fraction (``1/2400``)."""
    return float(Fraction(text))


def _rig_step(text: str) -> tuple[str, float]:
    """``RIG=STEP``: a rig's own time step [s], a number or a fraction (``E1=1/4800``)."""
    rig, eq, step = text.partition("=")
    if not eq or not rig:
        raise argparse.ArgumentTypeError(f"expected RIG=STEP (e.g. E1=1/4800), got {text!r}")
    try:
        return rig, _seconds(step)
    except (ValueError, ZeroDivisionError) as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: {step!r} is not a time step") from exc


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--out", type=Path, default=Path("bench-twin"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--truths", type=int, default=3, help=f"1-{len(FRACTIONS)}")
    ap.add_argument("--placements", type=int, default=2)
    ap.add_argument(
        "--e1-placements",
        type=int,
        default=None,
        help="placements of the joint setups' E1 case, if not --placements (E1's placements "
        "scatter far less than its real runs; the setups' names then end in -e1x<N>)",
    )
    ap.add_argument("--budget", type=int, default=48)
    ap.add_argument("--setups", default="published,joint")
    ap.add_argument(
        "--real-timestep",
        type=_seconds,
        default=1 / 4800,
        help="time step [s] of the twin's 'real' runs (default 1/4800 s: half the model's "
        "1/2400 s, so the 'real' side is the more converged one)",
    )
    ap.add_argument(
        "--model-timestep",
        type=_seconds,
        default=None,
        help="time step [s] of the calibrated model (default: the model's own default)",
    )
    ap.add_argument(
        "--rig-timestep",
        type=_rig_step,
        nargs="*",
        default=[],
        metavar="RIG=STEP",
        help="a rig's own time step [s] in the calibrated model (simulator.rig_timesteps), "
        "e.g. E1=1/4800",
    )
    ap.add_argument(
        "--belt-friction",
        choices=("mujoco", "coulomb"),
        default="mujoco",
        help="law of friction on belts, strips and rollers, for the twin and the model alike",
    )
    ap.add_argument(
        "--parameters",
        nargs=4,
        metavar="NAME=LOW:HIGH",
        help="the four parameters to calibrate and hide truths for, catalogue units "
        "(default: the published mu_d_BePa, mu_d_MePa, E_Pa, k_MePa over their ranges)",
    )
    args = ap.parse_args()
    parameters = PARAMETERS if args.parameters is None else parse_ranges(args.parameters)

    from parcelfit.runs import TestCase
    from parcelfit.sim.params import CATALOGUE
    from parcelfit.synth import TwinSettings, make_twin_dataset

    specs = {p.name: p for p in CATALOGUE}
    cases = [TestCase("E3", "KPBW", 1), TestCase("E3", "KPBW", 2)]
    cases += [TestCase("E1", "KPBW", 1), TestCase("E1", "KPBW", 3)]

    def make_dataset(folder: Path, truth: Mapping[str, float], seed: int) -> Path:
        if not (folder / "dataset.yaml").is_file():
            make_twin_dataset(
                folder,
                cases,
                {"KPBW": dict(truth)},
                settings=TwinSettings(
                    real_timestep=args.real_timestep, real_belt_friction=args.belt_friction
                ),
                seed=seed,
                name=f"twin-{folder.parent.name}",
                workers=args.workers,
            )
        return folder

    wanted = set(args.setups.split(","))
    setups = [
        s
        for s in mujoco_setups(args.placements, args.budget, args.e1_placements)
        if s.kind in wanted
    ]
    truths = {
        f"truth{k + 1}": truth_values(f, parameters) for k, f in enumerate(FRACTIONS[: args.truths])
    }
    rows = run(
        truths,
        setups,
        make_dataset,
        {
            "backend": "mujoco",
            "rig": "E3",
            "consignment": "KPBW",
            "belt_friction": args.belt_friction,
        }
        | ({} if args.model_timestep is None else {"timestep": args.model_timestep})
        | ({"rig_timesteps": dict(args.rig_timestep)} if args.rig_timestep else {}),
        parameters,
        args.out,
        to_si=lambda n, v: specs[n].to_si(v),
        workers=args.workers,
    )
    print(table(rows))


if __name__ == "__main__":
    main()
