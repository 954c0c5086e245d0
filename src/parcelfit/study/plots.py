"""Figures of a calibration study, read from its store.

* ``history``: the cost of every fitting evaluation by iteration, the best cost so far, and the
  validations (green: passed, red: failed), like the published Figure 12.
* ``traces``: each fitted parameter by evaluation, coloured by cost, the best one marked.
* ``partial_dependence``: the GP's predicted cost as one parameter varies, averaged over the
  others (uniform Monte Carlo sample of 256 points per value), with a +-1 standard deviation
  band; the GP is refitted from the store exactly as the optimiser saw it, with the optimiser
  settings the store records (`surrogate_optimizer`). The curves are `DependenceCurve`s
  (`parcelfit.study.results`), which the calibration also stores for the report.
* ``pairwise``: the sample of the plausible set of the identifiability analysis
  (`parcelfit.study.identify`), each parameter's histogram with its interval and each pair's
  scatter with its correlation (`pairwise_figure`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Literal

import numpy as np
from matplotlib.figure import Figure

from parcelfit.figures import save_figure
from parcelfit.optimize.bo import BatchBO, BOSettings
from parcelfit.optimize.space import Dimension, Space
from parcelfit.sim.params import catalogue_unit, to_catalogue_units
from parcelfit.study.identify import Identifiability
from parcelfit.study.results import DependenceCurve
from parcelfit.study.store import STORE_FILE, Evaluation, Store, StudyRecord


def _label(name: str) -> str:
    unit = catalogue_unit(name)
    return f"{name} [{unit}]" if unit not in ("-", "SI") else name


def history(fits: list[Evaluation], validations: list[Evaluation]) -> Figure:
    """Cost by iteration with the best so far and the validation verdicts."""
    fig = Figure(figsize=(7, 4), layout="constrained")
    ax = fig.subplots()
    ok = [e for e in fits if e.status == "ok" and e.cost is not None]
    bad = [e for e in fits if e.status not in ("ok", "pending")]
    ax.scatter(
        [e.iteration for e in ok], [e.cost for e in ok], s=14, color="#7f8c8d", label="evaluation"
    )
    if bad:
        top = max((e.cost for e in ok), default=1.0)
        ax.scatter(
            [e.iteration for e in bad],
            [top] * len(bad),
            marker="x",
            color="#c0392b",
            label="failed / unstable (plotted at the worst cost)",
        )
    iters = sorted({e.iteration for e in fits})
    best, run = [], np.inf
    for it in iters:
        run = min([run, *[e.cost for e in ok if e.iteration == it]])
        best.append(run)
    ax.step(iters, best, where="post", color="#2c3e50", label="best so far")
    for v in validations:
        if v.status == "pending":
            continue
        passed = bool(v.details.passed)
        ax.axvline(v.iteration, color="#27ae60" if passed else "#e74c3c", ls="--", lw=1)
        ax.text(
            v.iteration,
            ax.get_ylim()[1],
            "valid" if passed else "invalid",
            rotation=90,
            va="top",
            ha="right",
            fontsize=8,
            color="#27ae60" if passed else "#e74c3c",
        )
    ax.set_xlabel("iteration (0 = initial design)")
    ax.set_ylabel("cost (eq. 3)")
    if ok and min(e.cost for e in ok) > 0:  # type: ignore[type-var]
        ax.set_yscale("log")
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.legend(fontsize=8)
    return fig


def traces(fits: list[Evaluation], names: list[str]) -> Figure:
    """Each parameter by evaluation, coloured by cost; the best evaluation starred."""
    fig = Figure(figsize=(7, 1.8 * len(names) + 0.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(names), 1, sharex=True))
    ok = [(i, e) for i, e in enumerate(fits) if e.status == "ok" and e.cost is not None]
    best = min(ok, key=lambda ie: ie[1].cost)[0] if ok else None  # type: ignore[arg-type, return-value]
    costs = np.array([e.cost for _, e in ok]) if ok else np.array([])
    for ax, name in zip(axes, names, strict=True):
        xs = [i for i, _ in ok]
        ys = [to_catalogue_units(name, e.params[name]) for _, e in ok]
        sc = ax.scatter(xs, ys, c=costs, cmap="viridis_r", s=14)
        failed = [(i, e) for i, e in enumerate(fits) if e.status not in ("ok", "pending")]
        ax.scatter(
            [i for i, _ in failed],
            [to_catalogue_units(name, e.params[name]) for _, e in failed],
            marker="x",
            color="#c0392b",
            s=14,
        )
        if best is not None:
            ax.scatter(
                [best],
                [to_catalogue_units(name, fits[best].params[name])],
                marker="*",
                s=120,
                color="#e67e22",
            )
        ax.set_ylabel(_label(name), fontsize=8)
    axes[-1].set_xlabel("evaluation")
    if ok:
        fig.colorbar(sc, ax=list(axes), label="cost")
    return fig


def dependence_curves(
    bo: BatchBO, n_grid: int = 40, n_mc: int = 256, seed: int = 0
) -> list[DependenceCurve] | None:
    """GP partial dependence curves of every parameter (None before two successes)."""
    fitted = bo._fit(np.random.default_rng([bo.seed, len(bo.observations)]), [])
    if fitted is None:
        return None
    gp, mean, std = fitted[:3]
    scale = std if std > 0 else 1.0
    transformed = fitted.transform != "none"
    rng = np.random.default_rng(seed)
    d = len(bo.space)
    others = rng.random((n_mc, d))
    grid = np.linspace(0, 1, n_grid)
    curves = []
    for j, dim in enumerate(bo.space.dims):
        mu_pd, sd_pd = [], []
        for g in grid:
            pts = others.copy()
            pts[:, j] = g
            mu, sd = gp.predict(pts, return_std=True)
            mu_pd.append(mu.mean())
            sd_pd.append(sd.mean())
        mu_c = mean - np.asarray(mu_pd) * scale  # back to cost units (y = -(c - mean) / std)
        sd_c = np.asarray(sd_pd) * scale
        xs = np.array(
            [bo.space.from_unit(np.r_[np.zeros(j), g, np.zeros(d - j - 1)])[dim.name] for g in grid]
        )
        curves.append(
            DependenceCurve(
                name=dim.name,
                values=np.asarray(to_catalogue_units(dim.name, xs)),
                cost=mu_c,
                sd=sd_c,
                log=dim.log,
                transformed=transformed,
            )
        )
    return curves


def partial_dependence(
    bo: BatchBO, n_grid: int = 40, n_mc: int = 256, seed: int = 0
) -> Figure | None:
    """GP partial dependence of the cost on each parameter (None before two successes)."""
    curves = dependence_curves(bo, n_grid, n_mc, seed)
    return None if curves is None else dependence_figure(curves)


def dependence_figure(curves: list[DependenceCurve]) -> Figure:
    """Partial dependence curves, one panel per parameter, with their +-1 sd band."""
    fig = Figure(figsize=(3.2 * len(curves), 3.0), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(curves)))
    for ax, c in zip(axes, curves, strict=True):
        ax.plot(c.values, c.cost, color="#2c3e50")
        ax.fill_between(c.values, c.cost - c.sd, c.cost + c.sd, color="#2c3e50", alpha=0.15)
        ax.set_xlabel(_label(c.name), fontsize=8)
        if c.log:
            ax.set_xscale("log")
    axes[0].set_ylabel(
        "predicted cost (after the output transform)" if curves[0].transformed else "predicted cost"
    )
    fig.suptitle("GP partial dependence (mean over the other parameters, +-1 sd)", fontsize=9)
    return fig


def study_optimizer(folder: str | Path) -> BatchBO | None:
    """The optimiser of a study folder, told every finished evaluation, with the study's own GP
    settings (None without a study record). A study whose sampler has no GP (tpe), or whose
    store predates the recorded settings, gets the default GP (`OptimizerRecord.note` says so)."""
    store = Store(Path(folder) / STORE_FILE, readonly=True)
    try:
        record = store.read_study()
        fits = store.evaluations("fit")
    finally:
        store.close()
    if record is None or not record.parameters:
        return None
    return surrogate_optimizer(record, fits)


def surrogate_optimizer(record: StudyRecord, fits: list[Evaluation]) -> BatchBO:
    """A GP optimiser over the record's space with its recorded settings (defaults where none
    are recorded), told every finished evaluation in ``fits`` in order."""
    space = Space(
        [
            Dimension(n, lo, hi, lg)
            for n, (lo, hi), lg in zip(record.parameters, record.bounds, record.log, strict=True)
        ]
    )
    stored = record.optimizer.settings
    bo = BatchBO(
        space,
        batch_size=record.batch_size,
        seed=record.seed,
        settings=BOSettings(**stored) if stored else BOSettings(),
    )
    for e in fits:
        if e.status != "pending":
            bo.tell(e.params, e.cost if e.status == "ok" else None)
    return bo


def study_figures(
    folder: str | Path, curves: list[DependenceCurve] | Literal["refit"] | None = "refit"
) -> list[Path]:
    """Write history, traces and partial dependence (PNG and SVG) into ``folder/figures``;
    ``curves`` are the partial dependence curves when already computed (None: there are none),
    else they are computed from the study's surrogate."""
    folder = Path(folder)
    store = Store(folder / STORE_FILE, readonly=True)
    try:
        record = store.read_study()
        fits, vals = store.evaluations("fit"), store.evaluations("validation")
    finally:
        store.close()
    names = [] if record is None else list(record.parameters)
    out = folder / "figures"
    paths = save_figure(history(fits, vals), out / "history")
    if not fits or not names:
        return paths
    paths += save_figure(traces(fits, names), out / "traces")
    if curves == "refit":
        bo = study_optimizer(folder)
        curves = None if bo is None else dependence_curves(bo)
    if curves:
        paths += save_figure(dependence_figure(curves), out / "partial_dependence")
    return paths


_VERDICT_COLOURS = {
    "determined": "#1e8449",
    "lower bound": "#d68910",
    "upper bound": "#d68910",
    "narrowed": "#d68910",
    "undetermined": "#c0392b",
}


def pairwise_figure(ident: Identifiability, truth: Mapping[str, float] | None = None) -> Figure:
    """The plausible set of the identifiability analysis, pair by pair (catalogue units):
    on the diagonal each parameter's histogram with its interval shaded in its verdict's colour,
    below it the sample of each pair with its correlation r; the hidden truth (synthetic data)
    as a black line or cross where given (SI values)."""
    names = ident.names
    d = len(names)
    fig = Figure(figsize=(2.3 * d + 0.6, 2.3 * d + 0.4), layout="constrained")
    axes = np.atleast_2d(fig.subplots(d, d, squeeze=False))
    values = [np.asarray(to_catalogue_units(n, ident.sample[:, j])) for j, n in enumerate(names)]
    truth_cat = {n: float(to_catalogue_units(n, v)) for n, v in (truth or {}).items() if n in names}
    for i, pi in enumerate(ident.parameters):
        lo_r, hi_r = (float(to_catalogue_units(pi.name, x)) for x in (pi.low, pi.high))
        for j, pj in enumerate(ident.parameters):
            ax = axes[i, j]
            if j > i:
                ax.set_axis_off()
                continue
            if i == j:
                ax.hist(values[i], bins=30, range=(lo_r, hi_r), color="#95a5a6")
                a, b = (float(to_catalogue_units(pi.name, x)) for x in pi.interval)
                ax.axvspan(a, b, color=_VERDICT_COLOURS.get(pi.verdict, "#7f8c8d"), alpha=0.2)
                ax.set_title(f"{pi.name}: {pi.verdict}", fontsize=8)
                ax.set_yticks([])
                if pi.name in truth_cat:
                    ax.axvline(truth_cat[pi.name], color="black", lw=1.2)
            else:
                lo_c, hi_c = (float(to_catalogue_units(pj.name, x)) for x in (pj.low, pj.high))
                ax.scatter(values[j], values[i], s=2, alpha=0.25, color="#2c3e50")
                ax.set_xlim(lo_c, hi_c)
                ax.set_ylim(lo_r, hi_r)
                ax.text(
                    0.03,
                    0.95,
                    f"r = {ident.correlation[i, j]:+.2f}",
                    transform=ax.transAxes,
                    va="top",
                    fontsize=7,
                    color="#c0392b",
                )
                if pi.name in truth_cat and pj.name in truth_cat:
                    ax.plot(truth_cat[pj.name], truth_cat[pi.name], "kx", ms=7, mew=1.5)
            ax.set_xlim(*((lo_r, hi_r) if i == j else ax.get_xlim()))
            if i == d - 1:
                ax.set_xlabel(_label(pj.name), fontsize=8)
            if j == 0 and i > 0:
                ax.set_ylabel(_label(pi.name), fontsize=8)
            ax.tick_params(labelsize=7)
    fig.suptitle(
        f"Parameter values the data cannot tell apart (not excluded at {ident.level * 100:.0f} % "
        "confidence by the GP surrogate; shaded: each parameter's interval)",
        fontsize=9,
    )
    return fig
