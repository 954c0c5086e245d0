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
(do the parameters carry over to other test cases?); the convergence check (does the verdict
depend on the mesh and step?); the simulated run's key frames.

Architecture: the report renders, it does not analyse. The calibration writes what it concluded
into the study folder: the store (`parcelfit.study.store`: the evaluations and the typed
study, source and recommended records) and ``results.json`` (`parcelfit.study.results`,
schema in docs/data.md: the reference runs it used, every validation's verdict and curves, the
GP surrogate's partial dependence refitted with the optimiser settings the store records, the
key frames it drew). `build_report` reads those files, turns them into plain values and
embedded figures (one `Section` per heading, built by a ``_NAME_section`` function here, the
calibration's in `parcelfit.report.calibration`, on the frame of `parcelfit.report.page`; figures
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
confidence from costing less than what real runs score) and its verdict:
determined (interval at most 20 % of the range; reported as its midpoint +- half-width, so
within 10 % of the range of anything in it), bounded on one side or narrowed (reported as the
bound or interval), or undetermined (no value is reported).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from markupsafe import Markup

from parcelfit import __version__
from parcelfit.config import load_yaml
from parcelfit.errors import ParcelfitError
from parcelfit.progress import ProgressCallback, ignore_progress
from parcelfit.report.calibration import (
    BOUNDED,
    RECOVERY_TOLERANCE,
    ParameterRow,
    calibration_section,
)
from parcelfit.report.page import (
    CONTENT_SECURITY_POLICY,
    CSS,
    NO_RESULTS,
    NOT_STORED,
    TEMPLATES,
    Page,
    Refused,
    embeddable,
    figure_html,
    inside,
    png_html,
    write_page,
)
from parcelfit.runs import Dataset, load_dataset, read_truth
from parcelfit.study.results import (
    ReferenceRecord,
    StudyResults,
    ValidationRecord,
    read_results,
)
from parcelfit.study.status import folder_verdict
from parcelfit.study.store import STORE_FILE, SourceRecord, Store, StudyRecord
from parcelfit.study.verdict import (
    CONVERGENCE_ADVICE,
    UNDETERMINED_MEANING,
    Verdict,
    convergence_pairs,
    last_validation,
    study_verdict,
)


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


# -- transit-time statistics (a description of the dataset) -------------------------------------


def _statistics_section(page: Page, ds: Dataset) -> None:
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
    page: Page, results: StudyResults | None, root: Path, ds: Dataset | None
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
        "missing": None if results is not None else NOT_STORED,
        "refused": [str(refused)] if isinstance(refused, Refused) else [],
        "figures": [
            figure_html(distance_heatmaps(r), f"distance matrices {r.case}") for r in stored
        ],
    }
    page.add("reference", title, "reference", data)


# -- screening ---------------------------------------------------------------------------------


def _screen_section(page: Page, screen: Path | None) -> None:
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
            chart = embeddable(screen, png.name, "image/png", where)
            if isinstance(chart, bytes):
                data["charts"].append(png_html(chart, png.stem))
            elif chart is not None:
                data["refused"].append(str(chart))
    page.add("screening", title, "screening", data)


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
    page: Page, results: StudyResults | None, record: StudyRecord
) -> ValidationRecord | None:
    title = page.start("Validation")
    data: dict[str, Any] = {"missing": None, "shown": None, "views": []}
    group = [] if results is None else results.shown_validations()
    shown = group[0] if group else None
    if results is None:
        data["missing"] = NOT_STORED if record.validation_setting is not None else None
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


def _transfer_section(page: Page, results: StudyResults | None) -> None:
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


def _convergence_section(page: Page, results: StudyResults | None) -> None:
    """The convergence check: each validation and transfer case's published criteria on the
    model and on the refined model, side by side (only for a study that ran it)."""
    if results is None or results.convergence is None or not results.convergence.runs:
        return
    title = page.start("Does the verdict depend on the mesh and step? (convergence check)")
    judged = [*last_validation(results), *results.transfer]  # paired as the verdict pairs them
    rows = convergence_pairs(results.convergence.runs, judged)
    page.add(
        "convergence",
        title,
        "convergence",
        {"rows": rows, "refinement": results.convergence.refinement, "advice": CONVERGENCE_ADVICE},
    )


def _stricter_example_section(page: Page, root: Path) -> None:
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
    page: Page, folder: Path, results: StudyResults | None, animation: bool
) -> None:
    title = page.start("The simulated run")
    data: dict[str, Any] = {"note": None, "image": None, "animation": None, "no_animation": None}
    kf = None if results is None else results.key_frames
    if results is None:
        data["note"] = NOT_STORED
    elif kf is None:
        data["note"] = (
            "No key frames are stored: the calibration draws them when it stops (with its figures)."
        )
    else:
        data["note"] = kf.note
        if kf.image is not None:
            image = embeddable(folder, kf.image, "image/png", "the study folder")
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
                else embeddable(folder, kf.animation, "image/gif", "the study folder")
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
        cases = store.read_cases()
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
    page = Page(progress or ignore_progress)
    ds: Dataset | None = None
    dataset_dir = Path(source.dataset) if source.dataset else None
    if dataset_dir is not None and (dataset_dir / "dataset.yaml").is_file():
        ds = load_dataset(dataset_dir)
    rig, cons = source.rig, source.consignment
    truth = read_truth(dataset_dir, cons) if (dataset_dir and cons and ds and ds.synthetic) else {}
    if ds is not None:
        _statistics_section(page, ds)
    _reference_section(page, results, places.root, ds)
    _screen_section(page, places.screen)
    best, rows = calibration_section(
        page, places.study, record, results, truth, bool(ds and ds.synthetic)
    )
    _validation_section(page, results, record)
    _transfer_section(page, results)
    _convergence_section(page, results)
    _stricter_example_section(page, places.root)
    if key_frames and best is not None:
        _frames_section(page, places.study, results, animation)
    doc = TEMPLATES.get_template("report.html.j2").render(
        csp=CONTENT_SECURITY_POLICY,
        css=Markup(CSS),
        title=f"parcelfit report: {record.name}",
        version=__version__,
        generated=time.strftime("%Y-%m-%d %H:%M"),
        folder=places.study.name,
        rig=rig,
        consignment=cons,
        fitted=[c.case for c in (results.cases if results is not None else ()) if c.role == "fit"],
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
    write_page(target, doc)
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
    "build_report",
    "locate",
    "verdict_text",
]
