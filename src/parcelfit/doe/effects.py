"""Effects of two-level designs, their significance, Pareto charts, and a parameter selection.

Model: the response y of run i regressed on coded factors x (-1/+1) by ordinary least squares
(statsmodels), y = b0 + sum_j b_j x_j [+ sum_{j<l} b_jl x_j x_l]. An effect is the change of the
mean response from the low to the high level, effect = 2 b. Its standardised effect is
t = b / se(b).

Significance, two ways (the output names the one used):

* ``pooled``: the OLS standard errors and p-values of the fitted model, whose residual pools all
  terms left out (higher-order interactions; for a fractional design also their aliases). Needs
  at least one residual degree of freedom.
* ``lenth``: Lenth's pseudo standard error for unreplicated designs, over all 2^m - 1 orthogonal
  contrasts of the design (m base factors): s0 = 1.5 median|c|, PSE = 1.5 median(|c| : |c| <
  2.5 s0), t = c / PSE, p from Student's t with (2^m - 1)/3 degrees of freedom. Written by hand:
  neither SciPy nor statsmodels implements it.

Pareto chart: |t| of the largest ten terms as bars, with the two-sided 5 % critical value of
the method's t distribution as a line (like the published Figures 14-15).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
import statsmodels.api as sm
from matplotlib.figure import Figure
from scipy import stats

from parcelfit.doe.designs import LETTERS, Design
from parcelfit.errors import ParcelfitError


@dataclass(frozen=True)
class EffectAnalysis:
    """Effects of one response: a table (one row per term) and how significance was judged."""

    response: str
    table: pd.DataFrame  # term, factors, aliases, effect, coefficient, t, p_value, significant
    method: str
    critical_t: float
    alpha: float


def _term_name(letters: Sequence[str], names: Sequence[str], term: str) -> str:
    return ":".join(names[letters.index(c)] for c in term)


def lenth(contrasts: np.ndarray) -> tuple[float, float]:
    """Lenth's pseudo standard error of effect contrasts, and its degrees of freedom."""
    c = np.abs(np.asarray(contrasts, dtype=float))
    s0 = 1.5 * np.median(c)
    small = c[c < 2.5 * s0]
    pse = 1.5 * np.median(small) if small.size else s0
    return float(pse), len(c) / 3.0


def analyse_effects(
    design: Design,
    names: Sequence[str],
    response: np.ndarray,
    *,
    name: str = "response",
    interactions: bool | None = None,
    method: str = "auto",
    alpha: float = 0.05,
    centre: np.ndarray | None = None,
) -> EffectAnalysis:
    """Main (and two-factor interaction) effects of ``response`` on a coded design.

    ``interactions``: fit the two-factor interactions too (default: only for full factorials,
    where they are not aliased with main effects). ``method``: "pooled", "lenth", or "auto"
    (pooled when the model leaves at least 3 residual degrees of freedom, else Lenth).
    ``centre``: responses of centre runs (all factors at 0), added to the least-squares fit.
    """
    X = np.asarray(design.matrix, dtype=float)
    y = np.asarray(response, dtype=float)
    if centre is not None:  # centre runs join the least-squares fit (intercept and residual)
        X = np.vstack([X, np.zeros((len(centre), X.shape[1]))])
        y = np.concatenate([y, np.asarray(centre, dtype=float)])
    if X.shape[0] != y.shape[0] or len(names) != X.shape[1]:
        raise ParcelfitError(
            f"design has {X.shape} runs x factors, response {y.shape}, names {len(names)}"
        )
    if not np.all(np.isfinite(y)):
        raise ParcelfitError(
            f"response {name!r} has missing values (failed runs)",
            fix="rerun the failed runs or analyse the others with a smaller model",
        )
    letters = list(design.letters)
    full = not design.generators
    interactions = full if interactions is None else interactions
    terms = [(c,) for c in letters]
    if interactions:
        terms += list(itertools.combinations(letters, 2))
    cols = [np.prod([X[:, letters.index(c)] for c in t], axis=0) for t in terms]
    model = sm.OLS(y, sm.add_constant(np.column_stack(cols), has_constant="add")).fit()
    df_resid = round(model.df_resid)
    if method == "auto":
        method = "pooled" if df_resid >= 3 else "lenth"
    # effects below 1e-9 of the response's spread are floating-point dust of a noise-free
    # response, not effects: they count as exactly zero
    tiny = 1e-9 * float(np.max(np.abs(y - y.mean()))) if y.size else 0.0
    coef = np.where(np.abs(np.asarray(model.params[1:])) <= tiny, 0.0, np.asarray(model.params[1:]))
    if method == "pooled":
        if df_resid < 1:
            raise ParcelfitError(
                "the model leaves no residual degrees of freedom for pooled errors",
                fix="use method='lenth' or fewer terms",
            )
        t = _standardise(coef, np.asarray(model.bse[1:]), tiny)
        p = 2 * stats.t.sf(np.abs(t), df_resid)
        crit = float(stats.t.ppf(1 - alpha / 2, df_resid))
    elif method == "lenth":
        base = len(letters) - len(design.generators)
        contrasts = []
        Xf, yf = X[: len(design.matrix)], y[: len(design.matrix)]  # contrasts of the factorial runs
        for r in range(1, base + 1):
            for combo in itertools.combinations(range(base), r):
                contrasts.append(np.mean(np.prod(Xf[:, list(combo)], axis=1) * yf))
        c = np.asarray(contrasts)
        pse, dof = lenth(np.where(np.abs(c) <= tiny, 0.0, c))
        t = _standardise(coef, np.full_like(coef, pse), tiny)
        p = 2 * stats.t.sf(np.abs(t), dof)
        crit = float(stats.t.ppf(1 - alpha / 2, dof))
    else:
        raise ParcelfitError(f"unknown method {method!r}", fix="use pooled, lenth or auto")
    rows = []
    for term, b, tv, pv in zip(terms, coef, t, p, strict=True):
        label = "".join(term)
        aliases = (
            [a for a in design.aliases(label) if len(a) <= 2 and a != label] if design.words else []
        )
        rows.append(
            {
                "term": _term_name(letters, names, label),
                "factors": label,
                "aliases": ", ".join(_term_name(letters, names, a) for a in aliases),
                "effect": 2 * b,
                "coefficient": b,
                "t": tv,
                "p_value": pv,
                "significant": bool(pv < alpha),
            }
        )
    table = pd.DataFrame(rows).sort_values("t", key=np.abs, ascending=False, ignore_index=True)
    return EffectAnalysis(name, table, method, crit, alpha)


def _standardise(coef: np.ndarray, se: np.ndarray, tiny: float) -> np.ndarray:
    """coef / se; where the error is (numerically) zero, a zero effect has t = 0 and any other
    effect is infinitely larger than the error (a noise-free response)."""
    out = np.zeros_like(coef, dtype=float)
    exact = se <= tiny
    np.divide(coef, se, out=out, where=~exact)
    out[exact & (coef != 0)] = np.sign(coef[exact & (coef != 0)]) * np.inf
    return out


def pareto_chart(analysis: EffectAnalysis, top: int = 10) -> Figure:
    """Horizontal bars of |standardised effect| for the largest ``top`` terms, with the critical line."""
    tab = analysis.table.head(top).iloc[::-1]
    fig = Figure(figsize=(6.5, max(3.0, 0.35 * len(tab) + 1.4)), layout="constrained")
    ax = fig.subplots()
    colours = ["#c0392b" if s else "#7f8c8d" for s in tab["significant"]]
    size = np.abs(tab["t"].to_numpy(dtype=float))
    finite = size[np.isfinite(size) & (size < 1e6)]
    cap = max(float(finite.max()) if finite.size else 0.0, analysis.critical_t) * 1.5
    off_scale = ~np.isfinite(size) | (size >= 1e6)  # a noise-free response: no error to divide by
    size = np.where(off_scale, cap, size)
    ax.barh(tab["term"], size, color=colours)
    for y, flag in enumerate(off_scale):
        if flag:
            ax.text(cap, y, " off scale", va="center", fontsize=7)
    ax.axvline(analysis.critical_t, color="k", ls="--", lw=1)
    ax.text(analysis.critical_t, len(tab) - 0.4, f" {analysis.critical_t:.2f}", fontsize=8)
    ax.set_xlabel(f"standardised effect |t| ({analysis.method}; alpha = {analysis.alpha:g})")
    ax.set_title(f"Pareto chart: {analysis.response}")
    return fig


@dataclass(frozen=True)
class Selection:
    """Parameters recommended for calibration, best first, with the reasons."""

    parameters: list[str]
    reasons: dict[str, str]


def select_parameters(
    analyses: Sequence[EffectAnalysis], max_parameters: int = 4, only_significant: bool = True
) -> Selection:
    """Rank parameters by their largest |standardised effect| over all responses (main effects,
    or a share in an interaction); keep at most N, and only those with a significant effect
    unless ``only_significant`` is False (then the reasons say which effects are significant)."""
    score: dict[str, float] = {}
    why: dict[str, list[str]] = {}
    for a in analyses:
        for _, row in a.table.iterrows():
            if only_significant and not row["significant"]:
                continue
            for factor in row["term"].split(":"):
                score[factor] = max(score.get(factor, 0.0), abs(row["t"]))
                why.setdefault(factor, []).append(
                    f"{'main effect' if ':' not in row['term'] else 'interaction ' + row['term']} on "
                    f"{a.response}: effect {row['effect']:.3g}, |t| {abs(row['t']):.2f}, p {row['p_value']:.2g}"
                    + ("" if row["significant"] else " (not significant)")
                )
    # a parameter whose every effect is exactly zero does nothing here: never recommend it
    ranked = [f for f in sorted(score, key=lambda f: -score[f]) if score[f] > 0][:max_parameters]
    return Selection(ranked, {f: "; ".join(why[f]) for f in ranked})


__all__ = [
    "LETTERS",
    "EffectAnalysis",
    "Selection",
    "analyse_effects",
    "lenth",
    "pareto_chart",
    "select_parameters",
]
