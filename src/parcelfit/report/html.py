"""The HTML report: one self-contained file (figures embedded as PNG data) a person reads instead
of raw numbers.

Input is a calibration study folder (or a folder holding one as ``calibration/``, as
``parcelfit demo`` writes). From the study's store the report finds the study file and the
dataset again; a screening folder (``screen/`` beside the study, or given) and a stricter-
criterion example (``stricter-criterion.json``, written by the demo) are added when present.

Sections: summary and verdict; transit-time statistics; reference runs (distance matrices);
screening; calibration (history, parameters with their ranges and, for synthetic data, the truth;
identifiability from the surrogate); validation (published criteria and the stricter band test,
figures like the published Figures 16-19); the simulated run's key frames.

Identifiability rule (stated in the report): along each calibrated parameter, the GP's partial
dependence (mean cost averaged over the other parameters) is compared with its mean predictive
standard deviation sd; the values whose mean cost is within sd of the lowest are those the
evaluations cannot tell apart. A parameter is identifiable on this test case when that span is
at most 20 % of its range (so the calibrated value is pinned to about +-10 %, the recovery
tolerance); otherwise the report says it is not, and why.
"""

from __future__ import annotations

import base64
import io
import json
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import jinja2
import numpy as np
import yaml
from markupsafe import Markup, escape
from matplotlib.figure import Figure

from parcelfit import __version__
from parcelfit.errors import ParcelfitError
from parcelfit.metrics import ReferenceSelection, Validation, select_reference, validate
from parcelfit.metrics.envelope import EnvelopeBand, envelope_band
from parcelfit.optimize.store import StudyRecord
from parcelfit.progress import ProgressCallback, ProgressEvent, ignore_progress
from parcelfit.runs import Dataset, TestCase, Trajectory, load_dataset, read_trajectory
from parcelfit.sim.params import catalogue_unit, to_catalogue_units

IDENTIFIABLE_SPAN = 0.20  # widest share of the range the surrogate may leave undecided
RECOVERY_TOLERANCE = 0.10  # of the range's width

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
)


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;max-width:1100px;margin:2em auto;
padding:0 1em;color:#222;line-height:1.45}
h1{margin-bottom:.2em}h2{border-bottom:2px solid #ddd;padding-bottom:.2em;margin-top:2em}
.synthetic{background:#fff3cd;border:1px solid #e0b000;padding:.6em 1em;border-radius:6px}
.verdict{font-size:1.15em;padding:.7em 1em;border-radius:6px;margin:1em 0}
.pass{background:#e3f6e8;border:1px solid #27ae60}.fail{background:#fdecea;border:1px solid #e74c3c}
table{border-collapse:collapse;margin:.8em 0;font-size:.92em}
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:right}th{background:#f3f3f3}
td:first-child,th:first-child{text-align:left}
img{max-width:100%;height:auto;display:block;margin:.6em 0}
.grid{display:flex;flex-wrap:wrap;gap:1%}.grid img{max-width:49%}
.note{color:#555;font-size:.92em}.ok{color:#1e8449;font-weight:600}.bad{color:#c0392b;font-weight:600}
code{background:#f4f4f4;padding:0 .2em}
"""


def _esc(value: object) -> Markup:
    """User text (names, ids, messages) made safe to place inside HTML."""
    return escape(str(value))


def figure_html(fig: Figure, alt: str, dpi: int = 100) -> str:
    """A matplotlib figure as an embedded PNG ``<img>``."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return png_html(buf.getvalue(), alt)


def png_html(data: bytes, alt: str, mime: str = "image/png") -> str:
    """Image bytes (PNG unless ``mime`` says otherwise) as an embedded ``<img>``."""
    b64 = base64.b64encode(data).decode("ascii")
    return f'<img src="data:{mime};base64,{b64}" alt="{_esc(alt)}">'


def _table(header: list[str], rows: list[list[str]]) -> str:
    head = "".join(f"<th>{h}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _mark(passed: bool | None) -> str:
    if passed is None:
        return "-"
    return '<span class="ok">pass</span>' if passed else '<span class="bad">fail</span>'


@dataclass(frozen=True)
class StudyFolders:
    """Where a report's inputs are."""

    study: Path
    root: Path
    screen: Path | None


def locate(folder: str | Path, screen: str | Path | None = None) -> StudyFolders:
    """Find the study store in ``folder`` (or ``folder/calibration``) and a screening folder."""
    from parcelfit.optimize.calibration import STORE_FILE

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
    if screen is not None:
        screen_dir: Path | None = Path(screen)
        if not (screen_dir / "stage1-effects.csv").is_file():  # type: ignore[operator]
            raise ParcelfitError(
                "no screening results here (no stage1-effects.csv)",
                file=screen_dir,
                fix="point --screen at the folder `parcelfit screen` wrote",
            )
    else:
        candidates = [root / "screen", study.parent / "screen"]
        screen_dir = next((c for c in candidates if (c / "stage1-effects.csv").is_file()), None)
    return StudyFolders(study, root, screen_dir)


class _Builder:
    """The sections' HTML fragments, in page order. Fragments are markup written by this module;
    every piece of user text inside them passes through `_esc` (the page template escapes the
    rest, and the page's Content-Security-Policy forbids scripts should anything slip through)."""

    def __init__(self, progress: ProgressCallback | None) -> None:
        self.parts: list[Markup] = []
        self.progress = progress or ignore_progress

    def add(self, text: str) -> None:
        self.parts.append(Markup(text))

    def section(self, title: str, anchor: str) -> None:
        self.progress(ProgressEvent("report", title))
        self.parts.append(Markup('<h2 id="{}">{}</h2>').format(anchor, title))


def _load_truth(dataset_dir: Path, consignment: str) -> dict[str, float]:
    path = dataset_dir / "truth.yaml"
    if not path.is_file():
        return {}
    doc = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    return {k: float(v) for k, v in (doc.get("truth", {}).get(consignment) or {}).items()}


def _statistics_section(b: _Builder, ds: Dataset) -> None:
    from parcelfit.analysis import dataset_title
    from parcelfit.stats.plots import transit_time_boxplots
    from parcelfit.stats.transit import compare_transit_times, transit_time_table

    b.section("Transit times of the consignment types", "stats")
    times = transit_time_table(ds)
    if times.empty:
        b.add("<p>The dataset has no transit times.</p>")
        return
    tests = compare_transit_times(ds)
    b.add(
        "<p>Pairwise Mann-Whitney U tests per rig and speed setting, p-values adjusted by "
        "Benjamini-Hochberg within each rig and setting; brackets mark significant pairs "
        "(* p&lt;0.05, ** p&lt;0.01, *** p&lt;0.001).</p>"
    )
    b.add(figure_html(transit_time_boxplots(times, tests, dataset_title(ds)), "transit times"))
    sig = tests[tests["significant"]]
    b.add(
        f"<p>{len(sig)} of {len(tests)} pairs differ significantly "
        f"({len(times)} runs with a transit time).</p>"
    )


def _reference_section(
    b: _Builder, ds: Dataset, shown: list[TestCase]
) -> dict[TestCase, ReferenceSelection]:
    from parcelfit.report.figures import distance_heatmaps

    b.section("Reference runs", "reference")
    b.add(
        "<p>For every test case the run with the smallest sum of normalised DTW distances to "
        "the other runs (path, heading and, where known, transit time) is its reference run "
        "(method section 4).</p>"
    )
    sels: dict[TestCase, ReferenceSelection] = {}
    rows = []
    for case_data in (ds.cases[c] for c in sorted(ds.cases)):
        sel = select_reference(case_data)
        sels[case_data.case] = sel
        rows.append(
            [
                _esc(case_data.case.label),
                _esc(sel.reference_id),
                str(len(sel.run_ids)),
                f"{math.sqrt(sel.max_xy):.3f}",
                f"{math.sqrt(sel.max_theta):.3f}",
            ]
        )
    b.add(
        _table(
            [
                "test case",
                "reference run",
                "runs",
                "largest DTW<sub>xy</sub> between two runs [m]",
                "largest DTW<sub>&theta;</sub> [rad]",
            ],
            rows,
        )
    )
    for case in shown:
        if case in sels:
            b.add(figure_html(distance_heatmaps(sels[case]), f"distance matrices {case.label}"))
    return sels


def _screen_section(b: _Builder, screen: Path | None) -> None:
    b.section("Screening", "screening")
    if screen is None:
        b.add("<p class='note'>No screening results were found beside this study.</p>")
        return
    sel_file = screen / "selection.yaml"
    if sel_file.is_file():
        doc = yaml.safe_load(sel_file.read_text(encoding="utf-8")) or {}
        chosen = doc.get("selected") or []
        b.add(
            f"<p>Selected for calibration: <b>{_esc(', '.join(map(str, chosen)) or 'none')}</b>."
            "</p>"
        )
        reasons = doc.get("reasons") or {}
        if reasons:
            b.add(_table(["parameter", "why"], [[_esc(k), _esc(v)] for k, v in reasons.items()]))
    charts = sorted(screen.glob("stage*-pareto-*.png"))
    if charts:
        b.add(
            "<p>Pareto charts of the standardised effects on the DTW distances to the reference "
            "run, per stage (red: significant; dashed: the critical value).</p>"
        )
        b.add(
            "<div class='grid'>"
            + "".join(png_html(png.read_bytes(), png.stem) for png in charts)
            + "</div>"
        )


@dataclass(frozen=True)
class ParameterRow:
    """One calibrated parameter in catalogue units, with recovery and identifiability."""

    name: str
    unit: str
    low: float
    high: float
    best: float
    truth: float | None
    amplitude: float | None  # change of the GP's mean cost across the range
    span: tuple[float, float] | None = None  # values the surrogate cannot tell apart

    @property
    def error_share(self) -> float | None:
        """|best - truth| as a share of the range's width."""
        if self.truth is None:
            return None
        return abs(self.best - self.truth) / (self.high - self.low)

    @property
    def identifiable(self) -> bool | None:
        """Does the surrogate pin this parameter down: are the values it cannot tell apart
        from the best within ``IDENTIFIABLE_SPAN`` of the range?"""
        if self.span is None:
            return None
        return (self.span[1] - self.span[0]) <= IDENTIFIABLE_SPAN * (self.high - self.low)


def parameter_rows(
    record: StudyRecord, best: dict[str, float], truth: dict[str, float], curves: list | None
) -> list[ParameterRow]:
    """The calibrated parameters' table rows (catalogue units)."""
    by_name = {c.name: c for c in curves} if curves else {}
    rows = []
    for name, (lo, hi) in zip(record.parameters, record.bounds, strict=True):
        curve = by_name.get(name)
        rows.append(
            ParameterRow(
                name,
                catalogue_unit(name),
                float(to_catalogue_units(name, lo)),
                float(to_catalogue_units(name, hi)),
                float(to_catalogue_units(name, best[name])),
                truth.get(name),
                None if curve is None else curve.amplitude,
                None if curve is None else curve.indistinct(),
            )
        )
    return rows


def _iteration_span(last: int) -> str:
    """Iterations 1 to ``last`` (0 is the initial design, numbered as everywhere else)."""
    return "iteration 1" if last == 1 else f"iterations 1-{last}"


def _calibration_section(
    b: _Builder, folder: Path, meta: StudyRecord, truth: dict[str, float], synthetic: bool
) -> tuple[dict[str, float] | None, list[ParameterRow]]:
    from parcelfit.optimize.calibration import STORE_FILE, study_status
    from parcelfit.optimize.plots import dependence_curves, history, study_optimizer, traces
    from parcelfit.optimize.store import Store

    b.section("Calibration", "calibration")
    status = study_status(folder)
    store = Store(folder / STORE_FILE, readonly=True)
    fits, vals = store.evaluations("fit"), store.evaluations("validation")
    store.close()
    sim_time = sum(e.wall_time or 0.0 for e in fits + vals)
    done = [e for e in fits if e.finished_at is not None]
    span = (
        max(e.finished_at for e in done) - min(e.asked_at for e in fits)  # type: ignore[type-var]
        if done
        else 0.0
    )
    last = status["last_iteration"]
    b.add(
        f"<p>{status['evaluations']} simulations: the initial design (iteration 0)"
        + (f" and {_iteration_span(last)}" if last else "")
        + (f" (batches of {meta.batch_size})" if last else "")
        + f", {len(vals)} validation runs; "
        f"{span / 60:.1f} min from the first to the last result, {sim_time / 60:.1f} min of "
        f"simulation in all. Stopped: {_esc(status.get('stop_reason') or 'not finished')}.</p>"
    )
    b.add(figure_html(history(fits, vals), "cost history"))
    best = status["lowest_cost"]
    if best is not None and status["recommended"] is not None:  # what the study validated
        best = {**status["recommended"], "lowest_cost": best["cost"]}
    if best is None:
        b.add("<p class='bad'>No simulation succeeded; no parameters to report.</p>")
        return None, []
    names = list(meta.parameters)
    bo = study_optimizer(folder)
    curves = None if bo is None else dependence_curves(bo)
    rows = parameter_rows(meta, best["params"], truth, curves)
    header = ["parameter", "unit", "range", "calibrated"]
    if truth:
        header += ["truth (hidden)", "error / range width", "recovered (&le; 10 %)"]
    header += [
        "cost change across the range (GP)",
        "fit about equally well (GP)",
        "identifiable here",
    ]
    body = []
    for r in rows:
        cells = [
            _esc(r.name),
            _esc(r.unit),
            f"{r.low:g} - {r.high:g}",
            f"{r.best:.4g}",
        ]
        if truth:
            err = r.error_share
            cells += [
                "-" if r.truth is None else f"{r.truth:g}",
                "-" if err is None else f"{err * 100:.1f} %",
                "-" if err is None else _mark(err <= RECOVERY_TOLERANCE),
            ]
        cells += [
            "-" if r.amplitude is None else f"{r.amplitude:.3g}",
            "-" if r.span is None else f"{r.span[0]:.4g} - {r.span[1]:.4g}",
            "-"
            if r.identifiable is None
            else ("yes" if r.identifiable else '<span class="bad">no</span>'),
        ]
        body.append(cells)
    b.add(
        f"<p>Calibrated parameters: the evaluation made in iteration {best['iteration']} with cost "
        f"{best['cost']:.4g}"
        + (
            f" (recommended by the GP's mean cost; the lowest single cost was "
            f"{best['lowest_cost']:.4g})"
            if "lowest_cost" in best
            else ""
        )
        + ". "
        + ("<b>The truth column is shown because the data are SYNTHETIC.</b>" if truth else "")
        + "</p>"
    )
    b.add(_table(header, body))
    flat = [r for r in rows if r.identifiable is False]
    missed = [r for r in rows if r.error_share is not None and r.error_share > RECOVERY_TOLERANCE]
    if flat:
        b.add(
            "<p>Not identifiable here: "
            f"<b>{_esc(', '.join(r.name for r in flat))}</b>. Along each, the GP surrogate's "
            "mean cost (averaged over the other parameters, the partial dependence below) stays "
            "within one predictive standard deviation of its lowest value over more than "
            f"{IDENTIFIABLE_SPAN * 100:.0f} % of the range (the 'fit about equally well' "
            "column): the evaluations cannot tell those values apart, so the calibrated value "
            "within that span is as good as chance. This test case does not constrain them; "
            "another test case (rig or speed setting), more runs, or a direct measurement is "
            "needed to pin them down.</p>"
        )
    if missed and synthetic:
        unexplained = [r for r in missed if r.identifiable is not False]
        if unexplained:
            b.add(
                f"<p class='bad'>Not recovered although the surrogate pins it down: "
                f"{_esc(', '.join(r.name for r in unexplained))}. The model-form difference "
                "between the twin runs and the calibrated model, or too small a budget, can "
                "cause this.</p>"
            )
    if curves:
        from parcelfit.optimize.plots import dependence_figure

        b.add(figure_html(dependence_figure(curves), "partial dependence"))
    b.add(figure_html(traces(fits, names), "parameter traces"))
    return best["params"], rows


def _validation_figures(
    b: _Builder,
    sel: ReferenceSelection,
    traj: Trajectory,
    transit_time: float | None,
    label: str,
) -> Validation:
    from parcelfit.report.figures import (
        validation_mean_dtw,
        validation_overlays,
        validation_transit,
    )

    verdict = validate(traj, transit_time, sel)
    prepared = sel.comparison.prepare(traj)
    real_prepared = [
        Trajectory(t=np.arange(len(xy), dtype=float), x=xy[:, 0], y=xy[:, 1], theta=th)
        for xy, th in zip(sel.xy_series, sel.theta_series, strict=True)
    ]
    band: EnvelopeBand | None = None
    if len(real_prepared) >= 2:
        band = envelope_band(prepared, real_prepared)
    rows = [
        [
            "1. transit time within the real runs' [min, max]",
            "-"
            if verdict.transit_time.simulated is None
            else f"{verdict.transit_time.simulated:.3f} s",
            f"[{verdict.transit_time.low:.3f}, {verdict.transit_time.high:.3f}] s",
            _mark(verdict.transit_time.passed),
        ],
        [
            "2. mean DTW<sub>xy</sub> to the real runs &le; the largest real run's",
            f"{verdict.xy.simulated_mean:.3g} m&sup2;",
            f"&le; {verdict.xy.largest_real_mean:.3g} m&sup2;",
            _mark(verdict.xy.passed),
        ],
        [
            "3. mean DTW<sub>&theta;</sub> likewise",
            f"{verdict.theta.simulated_mean:.3g} rad&sup2;",
            f"&le; {verdict.theta.largest_real_mean:.3g} rad&sup2;",
            _mark(verdict.theta.passed),
        ],
    ]
    env = verdict.envelope
    if env is not None:
        rows.append(
            [
                "stricter (parcelfit): inside the real runs' band along x (&plusmn; 3 mm, "
                "&plusmn; 1&deg;) at &ge; 95 % of the path",
                f"y {env.inside_y * 100:.0f} %, &theta; {env.inside_theta * 100:.0f} % inside; "
                f"worst {env.worst_y * 1e3:.1f} mm, {math.degrees(env.worst_theta):.1f}&deg; out",
                "&ge; 95 %",
                _mark(env.passed),
            ]
        )
    b.add(_table(["criterion", "simulation", "required", "verdict"], rows))
    b.add(
        "<div style='display:flex;gap:1em;flex-wrap:wrap'>"
        + figure_html(validation_transit(sel, verdict, label), "transit-time validation")
        + figure_html(validation_mean_dtw(verdict, label), "mean DTW validation")
        + "</div>"
    )
    b.add(
        figure_html(
            validation_overlays(sel, prepared.xy, prepared.theta, band), "trajectory overlays"
        )
    )
    return verdict


def _key_frames(
    b: _Builder, study_file: Path, params: dict[str, float], case: TestCase, animation: bool
) -> None:
    from parcelfit.optimize.study import load_study
    from parcelfit.sim.factory import make_simulator
    from parcelfit.sim.mujoco import MujocoSimulator
    from parcelfit.sim.mujoco.render import animate_run, key_frame_indices, snapshot

    study = load_study(study_file)
    sim = make_simulator(study.simulator, study.folder)
    if not isinstance(sim, MujocoSimulator):
        b.add("<p class='note'>Key frames are drawn for the MuJoCo backend only.</p>")
        return
    recorder = MujocoSimulator(
        replace(sim.options, record_vertices=True),
        rigs={case.rig: sim.rig(case.rig)},
        consignments={case.consignment: sim.consignment(case.consignment)},
    )
    result, frames = recorder.run_with_frames({**study.fixed, **params}, case, run_id="report")
    if frames is None or not result.ok:
        b.add(f"<p class='bad'>The key-frame run ended {result.status.value}.</p>")
        return
    rig = recorder.rig(case.rig)
    idx = key_frame_indices(len(frames.t), 7)
    b.add(
        figure_html(
            snapshot(rig, frames, idx, f"{case.label}, calibrated parameters"), "key frames"
        )
    )
    if animation:
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            gif = animate_run(rig, frames, Path(tmp) / "run.gif", f"{case.label} (calibrated)")
            b.add(png_html(gif.read_bytes(), "animation of the simulated run", "image/gif"))


def _stricter_example_section(b: _Builder, root: Path, ds: Dataset | None) -> None:
    path = root / "stricter-criterion.json"
    if not path.is_file() or ds is None:
        return
    doc = json.loads(path.read_text(encoding="utf-8"))
    case = TestCase.parse(doc["case"])
    traj = read_trajectory(root / doc["run_file"])
    b.section("Why a stricter criterion", "stricter")
    b.add(
        f"<p>{_esc(doc.get('description', ''))}</p>"
        "<p>Below: the published three criteria against the band test for this run.</p>"
    )
    _validation_figures(b, select_reference(ds[case]), traj, doc.get("transit_time"), doc["label"])


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
    ``progress`` receives a `ProgressEvent` as each section starts."""
    from parcelfit.optimize.store import STORE_FILE, SourceRecord, Store

    places = locate(folder, screen)
    target = _report_target(Path(out) if out is not None else Path(folder) / "report.html")
    store = Store(places.study / STORE_FILE, readonly=True)
    meta = store.read_study()
    source = store.read_source() or SourceRecord()
    stop_reason = store.get_meta("stop_reason")
    vals = [v for v in store.evaluations("validation") if v.status != "pending"]
    store.close()
    if meta is None:
        raise ParcelfitError(
            "the study store has no study description",
            file=places.study / STORE_FILE,
            fix="run `parcelfit calibrate` on it first",
        )
    b = _Builder(progress)
    ds: Dataset | None = None
    dataset_dir = Path(source.dataset) if source.dataset else None
    if dataset_dir is not None and (dataset_dir / "dataset.yaml").is_file():
        ds = load_dataset(dataset_dir)
    rig, cons = source.rig, source.consignment
    truth = _load_truth(dataset_dir, cons) if (dataset_dir and cons and ds and ds.synthetic) else {}
    title = f"parcelfit report: {meta.name}"
    if ds is not None:
        _statistics_section(b, ds)
        shown = []
        if rig and cons:
            shown = [TestCase(rig, cons, meta.fit_setting)]
            if meta.validation_setting is not None:
                shown.append(TestCase(rig, cons, meta.validation_setting))
        sels = _reference_section(b, ds, shown)
    else:
        sels = {}
        b.add("<p class='bad'>The study's dataset was not found; data sections are left out.</p>")
    _screen_section(b, places.screen)
    best, rows = _calibration_section(b, places.study, meta, truth, bool(ds and ds.synthetic))
    b.section("Validation", "validation")
    verdict: Validation | None = None
    val_row = next((v for v in reversed(vals) if v.details.get("passed")), None) or (
        vals[-1] if vals else None
    )
    val_case = (
        TestCase(rig, cons, meta.validation_setting)
        if rig and cons and meta.validation_setting is not None
        else None
    )
    if val_row is None or val_case is None:
        b.add("<p>No validation run yet.</p>")
    elif val_row.run_file is None:
        b.add(
            f"<p class='bad'>The validation run after iteration {val_row.iteration} ended "
            f"{_esc(val_row.status)}: {_esc(val_row.details.get('message'))}</p>"
        )
    elif val_case in sels:
        b.add(
            f"<p>The calibrated parameters, validated after iteration {val_row.iteration}, "
            "simulated at the other "
            f"speed setting ({_esc(val_case.label)}) and compared with its real runs (method section "
            "8). The published criteria are the first three rows; the last is parcelfit's "
            "stricter band test.</p>"
        )
        traj = read_trajectory(places.study / val_row.run_file)
        verdict = _validation_figures(
            b, sels[val_case], traj, val_row.transit_time, "calibrated simulation"
        )
    _stricter_example_section(b, places.root, ds)
    if key_frames and best is not None and rig and cons and source.study_file:
        b.section("The simulated run", "frames")
        case = val_case or TestCase(rig, cons, meta.fit_setting)
        study_file = Path(source.study_file)
        if study_file.is_file():
            _key_frames(b, study_file, best, case, animation)
        else:
            b.add("<p class='note'>The study file has moved; no key frames.</p>")
    doc = _TEMPLATES.get_template("report.html.j2").render(
        csp=CONTENT_SECURITY_POLICY,
        css=Markup(_CSS),
        title=title,
        version=__version__,
        generated=time.strftime("%Y-%m-%d %H:%M"),
        folder=places.study.name,
        rig=rig,
        consignment=cons,
        synthetic=bool(ds is not None and ds.synthetic),
        description="" if ds is None else ds.description,
        summary=Markup(_summary(verdict, rows, stop_reason, bool(truth))),
        sections=b.parts,
    )
    _write_page(target, doc)
    return target


def _report_target(path: Path) -> Path:
    """Check, before anything is computed, that the report can be written to ``path``."""
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
    tmp = target.with_name(target.name + ".tmp")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text(doc, encoding="utf-8")
        tmp.replace(target)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise ParcelfitError(
            f"cannot write the report ({exc.strerror or exc})",
            file=target,
            fix="choose a writable --out",
        ) from None


def _summary(
    verdict: Validation | None, rows: list[ParameterRow], stop_reason: str | None, truth: bool
) -> str:
    if verdict is None:
        return "<div class='verdict fail'>No validation verdict: the study has not validated.</div>"
    published = verdict.passed
    strict = verdict.envelope.passed if verdict.envelope is not None else None
    cls = "pass" if published else "fail"
    text = (
        f"<b>Validation {'PASSED' if published else 'FAILED'}</b> by the published criteria; "
        f"parcelfit's stricter band test: {'passed' if strict else 'failed' if strict is False else 'n/a'}."
    )
    if truth and rows:
        recovered = [r for r in rows if (r.error_share or 0) <= RECOVERY_TOLERANCE]
        flat = [r for r in rows if r.identifiable is False]
        text += (
            f"<br>Parameters recovered within {RECOVERY_TOLERANCE * 100:.0f} % of their range: "
            f"{len(recovered)} of {len(rows)}"
            + (
                f"; not identifiable on this test case (the surrogate cannot tell apart "
                f"values across more than {IDENTIFIABLE_SPAN * 100:.0f} % of the range): "
                f"{_esc(', '.join(r.name for r in flat))}"
                if flat
                else ""
            )
            + "."
        )
    if stop_reason:
        text += f"<br><span class='note'>{_esc(stop_reason)}</span>"
    return f"<div class='verdict {cls}'>{text}</div>"


def verdict_text(path: str | Path) -> str:
    """A one-line verdict of a study folder (for the command line)."""
    from parcelfit.optimize.calibration import study_status

    st = study_status(locate(path).study)
    vals = st["validations"]
    if not vals:
        return "no validation yet"
    return "validation passed" if any(v["passed"] for v in vals) else "validation failed"


__all__ = ["build_report", "figure_html", "locate", "parameter_rows", "png_html", "verdict_text"]
