"""The HTML report: one self-contained file (figures embedded as PNG data) a person reads instead
of raw numbers.

Input is a calibration study folder (or a folder holding one as ``calibration/``, as
``parcelfit demo`` writes). From the study's store the report finds the dataset again; a
screening folder (``screen/`` beside the study, or given), the demo's stricter-criterion example
(``stricter-criterion.json``) and its reference runs of every test case (``reference_runs.json``)
are added when present.

Sections: summary and verdict; transit-time statistics; reference runs (distance matrices);
screening; calibration (history, parameters with their ranges and, for synthetic data, the truth;
what the evaluations determine: each parameter's interval and verdict, the pairwise plot, which
test case would help most); validation (published criteria and the stricter band test, figures
like the published Figures 16-19; every validation case of a joint study); the transfer check
(do the parameters carry over to other test cases?); the simulated run's key frames.

Architecture: the report renders, it does not analyse. The calibration writes what it concluded
into the study folder: the store (`parcelfit.study.store`: the evaluations and the typed
study, source and recommended records) and ``results.json`` (`parcelfit.study.results`,
schema in docs/data.md: the reference runs it used, every validation's verdict and curves, the
GP surrogate's partial dependence refitted with the optimiser settings the store records, the
key frames it drew). `build_report` reads those files, turns them into plain values and
embedded figures (one `Section` per heading, built by a ``_NAME_section`` function here; figures
drawn by `parcelfit.report.figures` and `parcelfit.study.plots`), and the Jinja2 templates
render the page (``templates/report.html.j2`` and one ``templates/sections/NAME.html.j2`` per
section). The templates escape every value (autoescaping); only the ``<img>`` tags made here are
marked safe, and the page's Content-Security-Policy forbids scripts should anything slip through.

Nothing is simulated, validated, selected or refitted here. Where a stored result is missing (a
study written by an earlier parcelfit, or one stopped before it validated) the page says so and
how to write it: `parcelfit calibrate` on the same study file and folder writes the results of a
finished study without simulating again. What the report still computes is description, not
analysis: the dataset's transit-time statistics (as `parcelfit stats` does), the history and
trace plots of the stored evaluations, and the pairwise plot of the stored sample.

What the data determine (stated in the report) is the calibration's stored identifiability
analysis (`parcelfit.study.identify`, formulas there): per parameter the interval of values the
evaluations cannot tell apart (those a GP surrogate of the log cost cannot exclude at 95 %
confidence from costing less than the real runs' largest cost) and its verdict:
determined (interval at most 20 % of the range; reported as its midpoint +- half-width, so
within 10 % of the range of anything in it), bounded on one side or narrowed (reported as the
bound or interval), or undetermined (no value is reported).
"""

from __future__ import annotations

import base64
import io
import json
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jinja2
from markupsafe import Markup
from matplotlib.figure import Figure

from parcelfit import __version__
from parcelfit.atomic import write_text_atomic
from parcelfit.config import load_yaml
from parcelfit.errors import ParcelfitError
from parcelfit.progress import ProgressCallback, ProgressEvent, ignore_progress
from parcelfit.runs import Dataset, load_dataset
from parcelfit.sim.params import catalogue_unit, to_catalogue_units
from parcelfit.study.identify import VERDICTS, Identifiability
from parcelfit.study.results import (
    ReferenceRecord,
    StudyResults,
    ValidationRecord,
    read_results,
)
from parcelfit.study.status import folder_verdict, study_status
from parcelfit.study.store import STORE_FILE, SourceRecord, Store, StudyRecord
from parcelfit.study.verdict import UNDETERMINED_MEANING, Verdict, study_verdict

RECOVERY_TOLERANCE = 0.10  # of the range's width
BOUNDED = ("lower bound", "upper bound", "narrowed")

# The report promises to be script-free and to fetch nothing: the page forbids every script,
# frame, font and connection, and allows only embedded (data:) images and its own inline styles.
CONTENT_SECURITY_POLICY = (
    "default-src 'none'; img-src data:; style-src 'unsafe-inline'; base-uri 'none'; "
    "form-action 'none'"
)
_TEMPLATES = jinja2.Environment(
    loader=jinja2.PackageLoader("parcelfit.report", "templates"),
    autoescape=True,
    undefined=jinja2.StrictUndefined,
    trim_blocks=True,
    lstrip_blocks=True,
)

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;max-width:1100px;margin:2em auto;
padding:0 1em;color:#222;line-height:1.45}
h1{margin-bottom:.2em}h2{border-bottom:2px solid #ddd;padding-bottom:.2em;margin-top:2em}
.synthetic{background:#fff3cd;border:1px solid #e0b000;padding:.6em 1em;border-radius:6px}
.verdict{font-size:1.15em;padding:.7em 1em;border-radius:6px;margin:1em 0}
.pass{background:#e3f6e8;border:1px solid #27ae60}.fail{background:#fdecea;border:1px solid #e74c3c}
.incomplete{background:#fff8e1;border:1px solid #e0a000}.verdict ul{margin:.3em 0;font-size:.9em}
table{border-collapse:collapse;margin:.8em 0;font-size:.92em}
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:right}th{background:#f3f3f3}
td:first-child,th:first-child{text-align:left}
img{max-width:100%;height:auto;display:block;margin:.6em 0}
.grid{display:flex;flex-wrap:wrap;gap:1%}.grid img{max-width:49%}
.note{color:#555;font-size:.92em}.ok{color:#1e8449;font-weight:600}.bad{color:#c0392b;font-weight:600}
.warn{color:#9a6700;font-weight:600}
code{background:#f4f4f4;padding:0 .2em}
"""

# what a missing stored result means, and how to write it (said once, at the top of the page)
NO_RESULTS = (
    "This study folder has no stored results (results.json): it was written by a parcelfit "
    "before the calibration stored them, or the study stopped before it validated. The "
    "sections that need them say so; nothing is recomputed here. Run `parcelfit calibrate` "
    "again on the same study file and folder to write them: a finished study then only writes "
    "its results, figures and key frames (no evaluation is simulated again)."
)
_NOT_STORED = "Not stored in this study folder (see the note at the top of the page)."


def figure_html(fig: Figure, alt: str, dpi: int = 100) -> Markup:
    """A matplotlib figure as an embedded PNG ``<img>``."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return png_html(buf.getvalue(), alt)


def png_html(data: bytes, alt: str, mime: str = "image/png") -> Markup:
    """Image bytes (PNG unless ``mime`` says otherwise) as an embedded ``<img>``."""
    b64 = base64.b64encode(data).decode("ascii")
    return Markup('<img src="data:{};base64,{}" alt="{}">').format(mime, b64, alt)


# The files the report embeds or reads are named by stored data (``results.json``'s key frames)
# or found by name in the folders it is given; a study folder may come from someone else. A file
# is read only when its resolved path (symbolic links followed) lies inside the resolved folder,
# so neither ``../../secret.txt``, an absolute path nor a link leading out is ever opened; the
# page says which file it refused. Embedded images must also be what they claim (PNG, GIF) and
# at most `MAX_EMBED_BYTES`.
MAX_EMBED_BYTES = 64 * 1024 * 1024
_MAGIC = {"image/png": (b"\x89PNG\r\n\x1a\n",), "image/gif": (b"GIF87a", b"GIF89a")}


@dataclass(frozen=True)
class Refused:
    """Why a file named by stored data or found in a folder was not read."""

    name: str
    reason: str

    def __str__(self) -> str:
        return f"{self.name} is not embedded: {self.reason}."


def inside(folder: Path, name: object, what: str = "the study folder") -> Path | Refused | None:
    """The file ``name`` (relative to ``folder``, as stored) resolved, when it lies inside the
    resolved ``folder`` and is a regular file; `Refused` (saying why) when it leads out of it
    or is not a file name; None when it does not exist. Never opens the file."""
    shown = str(name)
    if not isinstance(name, str) or not name or "\0" in name:
        return Refused(shown, "not a file name")
    try:
        base = folder.resolve(strict=True)
        path = (folder / name).resolve()
        if not path.is_relative_to(base):
            return Refused(shown, f"outside {what}")
        return path if path.is_file() else None
    except (OSError, RuntimeError, ValueError):  # a loop of links, an unreadable folder
        return Refused(shown, "not readable")


def _embeddable(folder: Path, name: object, mime: str, what: str) -> bytes | Refused | None:
    """The bytes of a file that `inside` accepts and that is a ``mime`` image (PNG or GIF) of
    at most `MAX_EMBED_BYTES`; `Refused` or None (missing) otherwise."""
    path = inside(folder, name, what)
    if not isinstance(path, Path):
        return path
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
            if not head.startswith(_MAGIC[mime]):
                return Refused(str(name), f"not a {mime.split('/')[1].upper()} image")
            if fh.seek(0, io.SEEK_END) > MAX_EMBED_BYTES:
                return Refused(str(name), f"larger than {MAX_EMBED_BYTES >> 20} MiB")
            fh.seek(0)
            return fh.read()
    except OSError:
        return Refused(str(name), "not readable")


@dataclass(frozen=True)
class StudyFolders:
    """Where a report's inputs are."""

    study: Path
    root: Path
    screen: Path | None


def locate(folder: str | Path, screen: str | Path | None = None) -> StudyFolders:
    """Find the study store in ``folder`` (or ``folder/calibration``) and a screening folder."""
    folder = Path(folder)
    if (folder / STORE_FILE).is_file():
        study, root = folder, folder.parent
    elif (folder / "calibration" / STORE_FILE).is_file():
        study, root = folder / "calibration", folder
    else:
        raise ParcelfitError(
            f"no calibration study here (no {STORE_FILE}, nor calibration/{STORE_FILE})",
            file=folder,
            fix="point at the folder `parcelfit calibrate` or `parcelfit demo` wrote",
        )
    screen_dir: Path | None
    if screen is not None:
        screen_dir = Path(screen)
        if not (screen_dir / "stage1-effects.csv").is_file():
            raise ParcelfitError(
                "no screening results here (no stage1-effects.csv)",
                file=screen_dir,
                fix="point --screen at the folder `parcelfit screen` wrote",
            )
    else:
        candidates = [root / "screen", study.parent / "screen"]
        screen_dir = next((c for c in candidates if (c / "stage1-effects.csv").is_file()), None)
    return StudyFolders(study, root, screen_dir)


@dataclass(frozen=True)
class Section:
    """One heading of the page: its template (``templates/sections/KIND.html.j2``), title,
    anchor and the values the template shows."""

    kind: str
    title: str
    anchor: str
    data: Any


@dataclass
class _Page:
    """The sections in page order; announces each as it is made."""

    progress: ProgressCallback
    sections: list[Section] = field(default_factory=list)

    def start(self, title: str) -> str:
        """Announce a section as its making starts; returns its title."""
        self.progress(ProgressEvent("report", title))
        return title

    def add(self, kind: str, title: str, anchor: str, data: Any) -> None:
        """Append a made section."""
        self.sections.append(Section(kind, title, anchor, data))


def _load_truth(dataset_dir: Path, consignment: str) -> dict[str, float]:
    path = dataset_dir / "truth.yaml"
    if not path.is_file():
        return {}
    doc = load_yaml(path) or {}
    return {k: float(v) for k, v in (doc.get("truth", {}).get(consignment) or {}).items()}


# -- transit-time statistics (a description of the dataset) -------------------------------------


def _statistics_section(page: _Page, ds: Dataset) -> None:
    from parcelfit.analysis import dataset_title
    from parcelfit.stats.plots import transit_time_boxplots
    from parcelfit.stats.transit import compare_transit_times, transit_time_table

    title = page.start("Transit times of the consignment types")
    times = transit_time_table(ds)
    data: dict[str, Any] = {"runs": len(times)}
    if not times.empty:
        tests = compare_transit_times(ds)
        data.update(
            figure=figure_html(
                transit_time_boxplots(times, tests, dataset_title(ds)), "transit times"
            ),
            significant=int(tests["significant"].sum()),
            tests=len(tests),
        )
    page.add("stats", title, "stats", data)


# -- reference runs ----------------------------------------------------------------------------


@dataclass(frozen=True)
class ReferenceRow:
    """A test case's reference run: its id, number of runs and largest DTW distances (m, rad)."""

    case: str
    reference: str
    runs: int
    largest_xy: float
    largest_theta: float


def _dataset_references(root: Path, ds: Dataset | None) -> list[ReferenceRow] | None:
    """The demo's reference runs of every test case (``reference_runs.json`` beside the study),
    when they are of the study's dataset."""
    path = inside(root, "reference_runs.json", "its folder")
    if ds is None or not isinstance(path, Path):
        return None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        if not doc or any(e.get("dataset") != ds.name for e in doc):
            return None
        return [
            ReferenceRow(
                str(e["test_case"]),
                str(e["reference_run"]),
                len(e["run_ids"]),
                math.sqrt(float(e["max_d_xy_m2"])),
                math.sqrt(float(e["max_d_theta_rad2"])),
            )
            for e in doc
        ]
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        return None


def _reference_section(
    page: _Page, results: StudyResults | None, root: Path, ds: Dataset | None
) -> None:
    from parcelfit.report.figures import distance_heatmaps

    title = page.start("Reference runs")
    stored = [] if results is None else list(results.references.values())
    everything = _dataset_references(root, ds)
    refused = inside(root, "reference_runs.json", "its folder")
    rows = everything or [
        ReferenceRow(
            r.case, r.reference_id, len(r.run_ids), math.sqrt(r.max_xy), math.sqrt(r.max_theta)
        )
        for r in stored
    ]
    data = {
        "rows": rows,
        "all_cases": everything is not None,
        "missing": None if results is not None else _NOT_STORED,
        "refused": [str(refused)] if isinstance(refused, Refused) else [],
        "figures": [
            figure_html(distance_heatmaps(r), f"distance matrices {r.case}") for r in stored
        ],
    }
    page.add("reference", title, "reference", data)


# -- screening ---------------------------------------------------------------------------------


def _screen_section(page: _Page, screen: Path | None) -> None:
    title = page.start("Screening")
    data: dict[str, Any] = {
        "found": screen is not None,
        "selected": None,
        "reasons": [],
        "charts": [],
        "refused": [],
    }
    if screen is not None:
        where = "the screening folder"
        sel_file = inside(screen, "selection.yaml", where)
        if isinstance(sel_file, Refused):
            data["refused"].append(str(sel_file))
        elif sel_file is not None:
            doc = load_yaml(sel_file) or {}
            data["selected"] = ", ".join(map(str, doc.get("selected") or [])) or "none"
            data["reasons"] = [(str(k), str(v)) for k, v in (doc.get("reasons") or {}).items()]
        for png in sorted(screen.glob("stage*-pareto-*.png")):
            chart = _embeddable(screen, png.name, "image/png", where)
            if isinstance(chart, bytes):
                data["charts"].append(png_html(chart, png.stem))
            elif chart is not None:
                data["refused"].append(str(chart))
    page.add("screening", title, "screening", data)


# -- calibration -------------------------------------------------------------------------------


@dataclass(frozen=True)
class ParameterRow:
    """One calibrated parameter in catalogue units: its range, the optimiser's recommended
    value, the hidden truth (synthetic data) and what the evaluations determine about it
    (`parcelfit.study.identify`: the interval, the verdict and, for a determined parameter,
    the reported value; None where no analysis is stored)."""

    name: str
    unit: str
    low: float
    high: float
    best: float
    truth: float | None
    interval: tuple[float, float] | None = None
    verdict: str | None = None
    estimate: float | None = None  # the reported value: determined parameters only

    @property
    def determined(self) -> bool | None:
        """Do the data fix this parameter (None: no analysis stored)?"""
        return None if self.verdict is None else self.verdict == "determined"

    @property
    def error_share(self) -> float | None:
        """|calibrated - truth| as a share of the range's width."""
        if self.truth is None:
            return None
        return abs(self.best - self.truth) / (self.high - self.low)

    @property
    def recovered(self) -> bool | None:
        """Is the calibrated value within ``RECOVERY_TOLERANCE`` of the range from the truth?"""
        err = self.error_share
        return None if err is None else err <= RECOVERY_TOLERANCE

    @property
    def covers_truth(self) -> bool | None:
        """Does the interval contain the hidden truth (None without both)?"""
        if self.truth is None or self.interval is None:
            return None
        return self.interval[0] <= self.truth <= self.interval[1]

    @property
    def bound_text(self) -> str:
        """The verdict in words with its numbers, e.g. ``at least 0.41``."""
        if self.interval is None or self.verdict is None:
            return "-"
        a, b = self.interval
        if self.verdict == "determined":
            return f"{(a + b) / 2 if self.estimate is None else self.estimate:.4g} +- {(b - a) / 2:.2g}"
        return {
            "lower bound": f"at least {a:.4g}",
            "upper bound": f"at most {b:.4g}",
            "narrowed": f"between {a:.4g} and {b:.4g}",
            "undetermined": "no value: the data cannot tell",
        }.get(self.verdict, "-")


def parameter_rows(
    record: StudyRecord,
    best: dict[str, float],
    truth: dict[str, float],
    ident: Identifiability | None,
) -> list[ParameterRow]:
    """The calibrated parameters' table rows (catalogue units), with the stored identifiability
    analysis ``ident`` (None: not stored)."""
    by_name = {p.name: p for p in ident.parameters} if ident is not None else {}
    rows = []
    for name, (lo, hi) in zip(record.parameters, record.bounds, strict=True):
        p = by_name.get(name)

        def cat(v: float, name: str = name) -> float:
            return float(to_catalogue_units(name, v))

        rows.append(
            ParameterRow(
                name,
                catalogue_unit(name),
                cat(lo),
                cat(hi),
                cat(best[name]),
                truth.get(name),
                None if p is None else (cat(p.interval[0]), cat(p.interval[1])),
                None if p is None else p.verdict,
                None if p is None or p.estimate is None else cat(p.estimate),
            )
        )
    return rows


def _iteration_span(last: int) -> str:
    """Iterations 1 to ``last`` (0 is the initial design, numbered as everywhere else)."""
    return "iteration 1" if last == 1 else f"iterations 1-{last}"


def _surrogate_note(results: StudyResults | None) -> dict[str, Any]:
    """What the template says about the surrogate the identifiability test read."""
    if results is None:
        return {"missing": _NOT_STORED}
    sur = results.surrogate
    if sur is None:
        return {"missing": "The stored results hold no surrogate (no study record)."}
    opt = sur.optimizer
    settings = ", ".join(
        f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
        for k, v in (opt.settings or {}).items()
    )
    return {
        "missing": None,
        "evaluations": sur.evaluations,
        "sampler": opt.sampler,
        "settings": settings,
        "note": opt.note,
        "fitted": sur.curves is not None,
    }


def _identifiability_view(
    results: StudyResults | None,
    rows: list[ParameterRow],
    truth: dict[str, float],
    synthetic: bool,
) -> dict[str, Any]:
    """What the template says about what the evaluations determine (`parcelfit.study.identify`),
    with the pairwise figure and the advice."""
    from parcelfit.study.plots import pairwise_figure

    ident = None if results is None else results.identifiability
    if results is None:
        return {"missing": _NOT_STORED}
    if ident is None:
        return {
            "missing": "The stored results hold no identifiability analysis (fewer than three "
            "successful evaluations, or results written by an earlier parcelfit: rerun "
            "`parcelfit calibrate` on the study to write it without simulating again)."
        }
    by = {v: [r for r in rows if r.verdict == v] for v in VERDICTS}
    advice = results.advice
    return {
        "missing": None,
        "determined": ", ".join(r.name for r in by["determined"]),
        "bounded": [(r.name, r.bound_text) for r in rows if r.verdict in BOUNDED],
        "undetermined": ", ".join(r.name for r in by["undetermined"]),
        "evaluations": ident.evaluations,
        "threshold": ident.threshold,
        "threshold_source": ident.threshold_source,
        "noise_sd": ident.noise_sd,
        "level": f"{ident.level * 100:.0f}",
        "reached": ident.reached,
        "best_acceptance": ident.best_acceptance,
        "converged": ident.converged,
        "correlations": [(a, b, f"{r:+.2f}") for a, b, r in ident.strongest_correlations()],
        "missed": ", ".join(r.name for r in rows if synthetic and r.covers_truth is False),
        "figure": figure_html(
            pairwise_figure(ident, _truth_si(truth) if synthetic else None),
            "pairwise plot of the values not excluded",
        ),
        "advice": None
        if advice is None
        else {
            "best": advice.best,
            "rows": [
                (case, ", ".join(f"{p} {v:.3g}" for p, v in ch.items()) or "-", sum(ch.values()))
                for case, ch in advice.changes.items()
            ],
            "parameters": ", ".join(advice.parameters),
        },
    }


def _truth_si(truth: dict[str, float]) -> dict[str, float]:
    """The hidden truth (catalogue units, as truth.yaml holds it) in SI."""
    from parcelfit.sim.params import CATALOGUE

    units = {p.name: p for p in CATALOGUE}
    return {n: units[n].to_si(v) if n in units else v for n, v in truth.items()}


def _calibration_section(
    page: _Page,
    folder: Path,
    record: StudyRecord,
    results: StudyResults | None,
    truth: dict[str, float],
    synthetic: bool,
) -> tuple[dict[str, float] | None, list[ParameterRow]]:
    from parcelfit.study.plots import dependence_figure, history, traces

    title = page.start("Calibration")
    status = study_status(folder)
    store = Store(folder / STORE_FILE, readonly=True)
    try:
        fits, vals = store.evaluations("fit"), store.evaluations("validation")
    finally:
        store.close()
    done = [e for e in fits if e.finished_at is not None]
    last = status.last_iteration
    data: dict[str, Any] = {
        "evaluations": status.evaluations,
        "iterations": _iteration_span(last) if last else None,
        "batch_size": record.batch_size,
        "validations": len(vals),
        "span_min": (
            max(e.finished_at for e in done) - min(e.asked_at for e in fits)  # type: ignore[type-var]
            if done
            else 0.0
        )
        / 60,
        "sim_min": sum(e.wall_time or 0.0 for e in fits + vals) / 60,
        "stopped": status.stop_reason or "not finished",
        "history": figure_html(history(fits, vals), "cost history"),
        "best": None,
    }
    low, rec = status.lowest_cost, status.recommended
    if low is None:
        page.add("calibration", title, "calibration", data)
        return None, []
    best = low.to_json()
    if rec is not None:  # what the study validated
        best = {**rec.to_json(), "lowest_cost": low.cost}
    curves = None
    if results is not None and results.surrogate is not None:
        curves = results.surrogate.curves
    ident = None if results is None else results.identifiability
    rows = parameter_rows(record, best["params"], truth, ident)
    data.update(
        best=best,
        truth=bool(truth),
        rows=rows,
        surrogate=_surrogate_note(results),
        identifiability=_identifiability_view(results, rows, truth, synthetic),
        cases=[] if results is None else list(results.cases),
        parts=None if rec is None else rec.parts,
        dependence=None
        if not curves
        else figure_html(dependence_figure(list(curves)), "partial dependence"),
        traces=figure_html(traces(fits, list(record.parameters)), "parameter traces"),
    )
    page.add("calibration", title, "calibration", data)
    return best["params"], rows


# -- validation --------------------------------------------------------------------------------


def _validation_view(
    reference: ReferenceRecord, record: ValidationRecord, label: str
) -> dict[str, Any]:
    """The verdict's table values and figures of a stored validation (it has a verdict)."""
    from parcelfit.report.figures import (
        validation_mean_dtw,
        validation_overlays,
        validation_transit,
    )

    verdict = record.verdict
    assert verdict is not None and record.sim_xy is not None and record.sim_theta is not None
    return {
        "verdict": verdict,
        "transit": figure_html(
            validation_transit(reference.transit_times, verdict, label), "transit-time validation"
        ),
        "mean_dtw": figure_html(validation_mean_dtw(verdict, label), "mean DTW validation"),
        "overlays": figure_html(
            validation_overlays(reference, record.sim_xy, record.sim_theta, record.band),
            "trajectory overlays",
        ),
        "worst_y_mm": None if verdict.envelope is None else verdict.envelope.worst_y * 1e3,
        "worst_theta_deg": None
        if verdict.envelope is None
        else math.degrees(verdict.envelope.worst_theta),
    }


def _validation_section(
    page: _Page, results: StudyResults | None, record: StudyRecord
) -> ValidationRecord | None:
    title = page.start("Validation")
    data: dict[str, Any] = {"missing": None, "shown": None, "views": []}
    group = [] if results is None else results.shown_validations()
    shown = group[0] if group else None
    if results is None:
        data["missing"] = _NOT_STORED if record.validation_setting is not None else None
    elif shown is not None:
        data["shown"] = shown
        data["several"] = len(group) > 1
        for v in group:
            reference = results.reference(v.case)
            if reference is None and len(group) == 1:
                reference = results.references.get("validation")
            view = None
            if v.verdict is not None and reference is not None:
                view = _validation_view(reference, v, "calibrated simulation")
            data["views"].append((v, view))
    page.add("validation", title, "validation", data)
    return shown


def _transfer_section(page: _Page, results: StudyResults | None) -> None:
    """The transfer check (only for a study that has one)."""
    if results is None or not results.transfer:
        return
    title = page.start("Do the parameters carry over? (transfer check)")
    views = []
    for v in results.transfer:
        reference = results.reference(v.case)
        view = None
        if v.verdict is not None and reference is not None:
            view = _validation_view(reference, v, "calibrated parameters")
        views.append((v, view))
    data = {
        "views": views,
        "passed": sum(v.passed for v in results.transfer),
        "strict": sum(
            bool(v.verdict and v.verdict.envelope and v.verdict.envelope.passed)
            for v in results.transfer
        ),
        "total": len(results.transfer),
    }
    page.add("transfer", title, "transfer", data)


def _stricter_example_section(page: _Page, root: Path) -> None:
    path = inside(root, "stricter-criterion.json", "its folder")
    if path is None:
        return
    title = page.start("Why a stricter criterion")
    if isinstance(path, Refused):
        page.add(
            "stricter", title, "stricter", {"description": "", "view": None, "missing": str(path)}
        )
        return
    doc = json.loads(path.read_text(encoding="utf-8"))
    data: dict[str, Any] = {
        "description": str(doc.get("description", "")),
        "view": None,
        "missing": None,
    }
    if {"reference", "validation"} <= set(doc):
        record = ValidationRecord.from_json(doc["validation"])
        if record.verdict is not None:
            reference = ReferenceRecord.from_json(doc["reference"])
            data["view"] = _validation_view(reference, record, str(doc.get("label", "simulation")))
    else:
        data["missing"] = (
            "This example was written by an earlier parcelfit without its stored verdict and "
            "curves: rerun `parcelfit demo` with the same --out to add them (nothing is "
            "simulated again)."
        )
    page.add("stricter", title, "stricter", data)


# -- key frames --------------------------------------------------------------------------------


def _frames_section(
    page: _Page, folder: Path, results: StudyResults | None, animation: bool
) -> None:
    title = page.start("The simulated run")
    data: dict[str, Any] = {"note": None, "image": None, "animation": None, "no_animation": None}
    kf = None if results is None else results.key_frames
    if results is None:
        data["note"] = _NOT_STORED
    elif kf is None:
        data["note"] = (
            "No key frames are stored: the calibration draws them when it stops (with its figures)."
        )
    else:
        data["note"] = kf.note
        if kf.image is not None:
            image = _embeddable(folder, kf.image, "image/png", "the study folder")
            if isinstance(image, bytes):
                data["image"] = png_html(image, "key frames")
            elif image is None:
                data["note"] = f"The key-frame figure {kf.image} is missing from the study folder."
            else:
                data["note"] = f"The key-frame figure {image}"
        if animation:
            gif = (
                None
                if kf.animation is None
                else _embeddable(folder, kf.animation, "image/gif", "the study folder")
            )
            if isinstance(gif, bytes):
                data["animation"] = png_html(gif, "animation of the simulated run", "image/gif")
            elif isinstance(gif, Refused):
                data["no_animation"] = f"The animation {gif}"
            elif kf.image is not None:
                data["no_animation"] = (
                    "No animation is stored: `parcelfit calibrate --animation` (or the demo) "
                    "writes one."
                )
    page.add("frames", title, "frames", data)


# -- the page ----------------------------------------------------------------------------------


def build_report(
    folder: str | Path,
    *,
    out: str | Path | None = None,
    screen: str | Path | None = None,
    key_frames: bool = True,
    animation: bool = False,
    progress: ProgressCallback | None = None,
) -> Path:
    """Write the HTML report of a study folder (or of a folder holding ``calibration/``, like
    the demo's); returns the report's path (default: ``report.html`` inside ``folder``).
    ``key_frames`` shows the key frames the calibration drew, ``animation`` the animation it
    wrote (``calibrate --animation``); ``progress`` receives a `ProgressEvent` as each section
    starts. Renders stored results only (see the module docstring)."""
    places = locate(folder, screen)
    target = _report_target(Path(out) if out is not None else Path(folder) / "report.html")
    store = Store(places.study / STORE_FILE, readonly=True)
    try:
        record = store.read_study()
        source = store.read_source() or SourceRecord()
        stop_reason = store.get_meta("stop_reason")
        cases = store.get_meta("cases")
    finally:
        store.close()
    if record is None:
        raise ParcelfitError(
            "the study store has no study description",
            file=places.study / STORE_FILE,
            fix="run `parcelfit calibrate` on it first",
        )
    try:
        results = read_results(places.study)
        results_error = None
    except ParcelfitError as exc:  # a damaged file: the page says so, the rest still renders
        results, results_error = None, str(exc)
    page = _Page(progress or ignore_progress)
    ds: Dataset | None = None
    dataset_dir = Path(source.dataset) if source.dataset else None
    if dataset_dir is not None and (dataset_dir / "dataset.yaml").is_file():
        ds = load_dataset(dataset_dir)
    rig, cons = source.rig, source.consignment
    truth = _load_truth(dataset_dir, cons) if (dataset_dir and cons and ds and ds.synthetic) else {}
    if ds is not None:
        _statistics_section(page, ds)
    _reference_section(page, results, places.root, ds)
    _screen_section(page, places.screen)
    best, rows = _calibration_section(
        page, places.study, record, results, truth, bool(ds and ds.synthetic)
    )
    _validation_section(page, results, record)
    _transfer_section(page, results)
    _stricter_example_section(page, places.root)
    if key_frames and best is not None:
        _frames_section(page, places.study, results, animation)
    doc = _TEMPLATES.get_template("report.html.j2").render(
        csp=CONTENT_SECURITY_POLICY,
        css=Markup(_CSS),
        title=f"parcelfit report: {record.name}",
        version=__version__,
        generated=time.strftime("%Y-%m-%d %H:%M"),
        folder=places.study.name,
        rig=rig,
        consignment=cons,
        fitted=[
            str(c["case"])
            for c in (results.cases if results is not None else ())
            if c.get("role") == "fit"
        ],
        synthetic=bool(ds is not None and ds.synthetic),
        description="" if ds is None else ds.description,
        dataset_missing=ds is None,
        results_error=results_error,
        no_results=NO_RESULTS if results is None else None,
        summary=_summary(
            [] if results is None else results.shown_validations(),
            rows,
            stop_reason,
            bool(truth),
            study_verdict(results, cases, stop_reason is not None),
        ),
        sections=page.sections,
        recovery_tolerance=f"{RECOVERY_TOLERANCE * 100:.0f}",
    )
    _write_page(target, doc)
    return target


def _report_target(path: Path) -> Path:
    """Check, before anything is read, that the report can be written to ``path``."""
    if path.is_dir():
        raise ParcelfitError(
            "the report's path is a folder",
            file=path,
            fix=f"name the HTML file, e.g. --out {path / 'report.html'}",
        )
    if path.parent.exists() and not path.parent.is_dir():
        raise ParcelfitError(
            "the report's folder is a file", file=path.parent, fix="choose another --out"
        )
    return path


def _write_page(target: Path, doc: str) -> None:
    """Write the page atomically (a temporary file renamed); nothing is left behind on failure."""
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(target, doc)
    except OSError as exc:
        raise ParcelfitError(
            f"cannot write the report ({exc.strerror or exc})",
            file=target,
            fix="choose a writable --out",
        ) from None


_BOX = {"trustworthy": "pass", "incomplete": "incomplete", "not trustworthy": "fail"}


def _summary(
    shown: ValidationRecord | Sequence[ValidationRecord] | None,
    rows: list[ParameterRow],
    stop_reason: str | None,
    truth: bool,
    overall: Verdict | None = None,
) -> dict[str, Any]:
    """The verdict box's values: the one overall verdict with its checks (`overall`, by
    default that of no stored results) and the box's colour class (green only when the verdict
    is trustworthy), the published and stricter verdicts of the validation shown, the recovery
    count (synthetic data) and why the study stopped."""
    if overall is None:
        overall = study_verdict(None, stopped=stop_reason is not None)
    group = [shown] if isinstance(shown, ValidationRecord) else list(shown or [])
    verdicts = [v.verdict for v in group]
    verdict = None
    strict = None
    if group and all(v is not None for v in verdicts):  # every validation case must pass
        verdict = {"passed": all(v.passed for v in verdicts)}  # type: ignore[union-attr]
        if all(v.envelope is not None for v in verdicts):  # type: ignore[union-attr]
            strict = all(v.envelope.passed for v in verdicts)  # type: ignore[union-attr]
    return {
        "verdict": overall,
        "box": _BOX[overall.level],
        "undetermined_means": UNDETERMINED_MEANING,
        "validation": verdict,
        "strict": strict,
        "truth": truth and bool(rows),
        "recovered": sum((r.error_share or 0) <= RECOVERY_TOLERANCE for r in rows),
        "parameters": len(rows),
        "determined": ", ".join(r.name for r in rows if r.determined),
        "bounded": ", ".join(f"{r.name} ({r.bound_text})" for r in rows if r.verdict in BOUNDED),
        "open": ", ".join(r.name for r in rows if r.verdict == "undetermined"),
        "analysed": any(r.verdict is not None for r in rows),
        "covered": sum(bool(r.covers_truth) for r in rows),
        "stop_reason": stop_reason,
    }


def verdict_text(path: str | Path) -> str:
    """The one overall verdict of a study folder (or of a folder holding ``calibration/``) in
    one line, e.g. ``not trustworthy: band test failed, transfer check failed; 0 of 4
    parameters determined`` (`parcelfit.study.verdict`)."""
    return folder_verdict(locate(path).study).text


__all__ = [
    "Section",
    "build_report",
    "figure_html",
    "locate",
    "parameter_rows",
    "png_html",
    "verdict_text",
]
