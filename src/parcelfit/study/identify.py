"""Which calibrated parameters the data determine, and to what interval (identifiability).

A calibration returns one parameter set; this module says which of its values the data actually
fix. It reads only the study's evaluations (parameters and costs) and one number from the real
runs, the acceptance threshold epsilon, and simulates nothing.

**Threshold.** A simulation at the true parameters is, at best, like more real runs: its cost
scores like theirs. So epsilon is what real runs score in the same cost function, at a high
quantile (`parcelfit.study.joint.threshold`): per case, the 95 % quantile (the next value up) of
equation 3 of every real run against the reference run for the published cost
(`parcelfit.metrics.cost.real_run_costs`; with ten real runs, the largest of the nine), or of
the ensemble cost of every set of K real runs (K the case's placements) against the other real
runs (`parcelfit.metrics.ensemble.ensemble_null_costs`), but at least the largest cost of one
real run against the others; for a joint study the weighted sum of the cases' thresholds.

**Surrogate.** A Gaussian process on the unit cube (`parcelfit.optimize.space`) models the log
cost of the finished evaluations (failed ones carry no cost and are left out):

    log c(u) ~ m + GP(0, k),  k = s^2 Matern_5/2(u, u'; l_1..l_d) + sigma_n^2 delta(u, u')

with one length scale per parameter (l_j in [0.05, 100]: features narrower than 5 % of the range
cannot be resolved by a few dozen evaluations; a parameter without effect gets a long one) and
the noise variance sigma_n^2 (the run-to-run scatter of the cost) fitted by marginal likelihood
(scikit-learn). The constant m, what the GP reverts to far from the evaluations, is the mean log
cost of a uniform design over the box (the study's initial Latin hypercube), not of all the
evaluations: the optimiser crowds its evaluations where the cost is low, and their mean would
make every unexplored region look good. The GP is fitted here, independently of the optimiser's
own surrogate, so the analysis does not change when the optimiser's settings do.

**Acceptance** (approximate Bayesian computation with a GP surrogate of the discrepancy, as in
BOLFI, Gutmann and Corander 2016, JMLR 17(125)): the probability that a simulation at u scores a
cost below epsilon,

    L(u) = Phi( (log epsilon - mu(u)) / sqrt(v(u) + sigma_n^2 + sigma_e^2) )

with mu, v the GP's predictive mean and variance of the latent log cost. sigma_e is the
standard error of the cost as an estimator, when the cost states one (the ensemble cost's `se`,
`parcelfit.metrics.ensemble`), relative to the cost (the median over the evaluations of
se / c): with the same placement seeds in every evaluation, the placements' error is the same
bias everywhere, which the GP cannot see as noise, so it is added here. Where the evaluations
are few, v is large and L stays well above zero: an unexplored region stays plausible.

**Plausible set.** The values the data cannot tell apart from the truth are

    S = { u : L(u) >= alpha },  alpha = 0.05,

i.e. a value is excluded only when the surrogate is 95 % sure that it costs more than the real
runs score. The threshold itself is generous (a simulation at the truth scores below it about 19
times in 20 as far as the real runs show, 9 in 10 where it is the largest of nine real runs'
costs: L(truth) ~ 0.9-0.95), and alpha = 0.05 keeps a wide margin below that. (Measured with the
threshold of 2026-12-03, the cases' largest single-run costs summed: on six calibrations of the
analytic test simulator, three hidden truths, the published and a joint ensemble setup, 40
evaluations, `benchmarks/bench_twin.py`, all 18 intervals contained the truth and none was
narrow enough to be called determined; with 10 evaluations, alpha = 0.2 gave intervals that
missed the truth.)
(Not the posterior mass of L: a low but non-zero L spread over a large unexplored volume would
outweigh a small region the data single out, and every interval would span its range.) S is
sampled by 8192 Sobol points and 16 random-walk chains uniform on S (seeded; started from
evaluated and Sobol points in S; Gaussian steps reflected at the cube's faces and accepted when
they stay in S; each parameter's step adapted during the first half of 2000 steps to the chains'
spread and about 30 % acceptance, then fixed; the second half kept). R-hat (Gelman-Rubin, split
chains) is stored per parameter; above 1.1 the report says the sample has not converged. If S is
empty (no parameter set reaches the real runs' scatter: the model cannot reproduce the data
within it), every parameter is undetermined. So is every parameter when S holds none of the
evaluated points (L(u_i) < alpha for every i): S is then a region between evaluations that
all cost more than the real runs score, which the surrogate's fitted length scales and noise
alone put there. Seen with 10 evaluations of the analytic test simulator
(`tests/test_bench_twin.py`): all ten cost 1.7-73 times the threshold, and the GP's valley
between two of them gave intervals 8-10 % of their ranges wide, one of them missing the truth.

**Intervals and verdicts.** Per parameter, the interval is the projection of S: the smallest
and largest value among the sample, in the parameter's own unit. With its width W and its
distances from the range's ends as shares of the range (high - low):

* **determined**: W <= 20 % of the range. The estimate is the interval's midpoint, so every
  value in the interval (the truth among them, when the model can reproduce the data) is within
  10 % of the range of it;
* **lower bound** / **upper bound**: not determined, and the interval leaves out at least 10 % of
  the range at one end only (the data rule out low, resp. high, values and nothing else);
* **narrowed**: not determined, and at least 10 % is left out at both ends;
* **undetermined**: less than 10 % is left out at either end: the data cannot tell the values
  apart, and no value is reported.

Correlations are the Pearson correlations of the sample of S on the unit cube; a correlation
near +-1 says that the data fix a combination of two parameters, not each.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, model_validator
from scipy.linalg import solve_triangular
from scipy.spatial.distance import cdist
from scipy.special import log_ndtr
from scipy.stats import qmc
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

from parcelfit.errors import ParcelfitError
from parcelfit.optimize.space import Space
from parcelfit.study.records import ArrayRecord, FloatArray

ALPHA = 0.05  # a value is excluded when the surrogate is 95 % sure it costs more than epsilon
N_SOBOL = 8192  # quasi-random points that seed and complete the sample of the plausible set
DETERMINED_WIDTH = 0.20  # widest interval (share of the range) called determined
EXCLUDED_END = 0.10  # share of the range an end must leave out to count as a bound
LENGTH_SCALE_BOUNDS = (0.05, 100.0)  # on the unit cube
N_CHAINS = 16
N_STEPS = 2000
N_KEEP_FOR_PLOT = 2000  # points of the plausible set stored for the pairwise plot
VERDICTS = ("determined", "lower bound", "upper bound", "narrowed", "undetermined")


class ParameterInterval(BaseModel):
    """One parameter's verdict: its range and interval [low, high] (SI), the median over the
    plausible set's sample, the verdict (one of `VERDICTS`) and R-hat of its chains."""

    model_config = ConfigDict(frozen=True)

    name: str
    low: float
    high: float
    interval: tuple[float, float]
    median: float
    verdict: str
    rhat: float

    @property
    def determined(self) -> bool:
        """True when the data fix the value (see the module docstring)."""
        return self.verdict == "determined"

    @property
    def estimate(self) -> float | None:
        """The value reported for a determined parameter (the interval's midpoint, SI); None
        for every other verdict: such a parameter has no value, only an interval."""
        return 0.5 * (self.interval[0] + self.interval[1]) if self.determined else None

    @property
    def width_share(self) -> float:
        """The interval's width as a share of the range."""
        return (self.interval[1] - self.interval[0]) / (self.high - self.low)

    def contains(self, value: float) -> bool:
        """True when ``value`` (SI) lies in the interval."""
        return self.interval[0] <= value <= self.interval[1]

    def to_json(self) -> dict[str, Any]:
        """The stored form (SI)."""
        return self.model_dump()

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> ParameterInterval:
        """Read the stored form."""
        return cls.model_validate(dict(doc))


class Identifiability(ArrayRecord):
    """What the evaluations say about each parameter (see the module docstring): the intervals,
    the correlation matrix of the plausible set (order of ``parameters``), a thinned sample of
    it in SI (``sample``: (m, d)), the threshold epsilon and where it came from, how many
    evaluations the surrogate learnt, its fitted noise standard deviation (of the log cost), the
    confidence ``level`` of an exclusion (1 - alpha), whether any parameter set reaches the
    real runs' scatter (``reached``), whether an evaluated one does (``supported``: without,
    the plausible set is the surrogate's extrapolation and nothing is determined) and the
    largest acceptance L seen."""

    parameters: tuple[ParameterInterval, ...]
    correlation: FloatArray
    sample: FloatArray
    threshold: float
    threshold_source: str
    evaluations: int
    noise_sd: float
    level: float = 1.0 - ALPHA
    reached: bool = True
    supported: bool = True
    best_acceptance: float = 1.0

    @property
    def names(self) -> list[str]:
        """Parameter names in order."""
        return [p.name for p in self.parameters]

    def by_verdict(self, verdict: str) -> list[str]:
        """Names of the parameters with this verdict."""
        return [p.name for p in self.parameters if p.verdict == verdict]

    @property
    def converged(self) -> bool:
        """True when every parameter's R-hat is at most 1.1."""
        return all(p.rhat <= 1.1 for p in self.parameters)

    def strongest_correlations(self, at_least: float = 0.5) -> list[tuple[str, str, float]]:
        """Pairs whose posterior correlation is at least ``at_least`` in magnitude, strongest
        first."""
        out = []
        for i in range(len(self.parameters)):
            for j in range(i + 1, len(self.parameters)):
                r = float(self.correlation[i, j])
                if abs(r) >= at_least:
                    out.append((self.parameters[i].name, self.parameters[j].name, r))
        return sorted(out, key=lambda t: -abs(t[2]))

    @model_validator(mode="before")
    @classmethod
    def _read_shapes(cls, doc: Any) -> Any:
        """The stored (nested list) correlation as (d, d) and sample as (m, d), also when empty;
        missing level, reached, supported, best_acceptance: the defaults."""
        if isinstance(doc, Mapping) and not isinstance(doc.get("sample"), np.ndarray):
            d = len(doc["parameters"])
            doc = {
                **doc,
                "correlation": np.asarray(doc["correlation"], float).reshape(d, d),
                "sample": np.asarray(doc["sample"], float).reshape(-1, d),
            }
        return doc


class Advice(BaseModel):
    """Which candidate case responds most to the undetermined parameters: per case the change
    Delta_k (`parcelfit.study.joint`) per parameter, and the best case (None if none could be
    simulated)."""

    model_config = ConfigDict(frozen=True)

    changes: dict[str, dict[str, float]]  # case label -> parameter -> Delta
    best: str | None = None
    parameters: Annotated[tuple[str, ...], BeforeValidator(lambda v: v or ())] = ()
    # the calibrated set simulated (SI)
    params: Annotated[dict[str, float], BeforeValidator(lambda v: v or {})] = {}

    def to_json(self) -> dict[str, Any]:
        """The stored form."""
        return self.model_dump()

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> Advice:
        """Read the stored form (missing parameters or params: none)."""
        return cls.model_validate(dict(doc))


def verdict(low: float, high: float, interval: tuple[float, float]) -> str:
    """The verdict of an interval [a, b] within the range [low, high] (module docstring)."""
    w = high - low
    a, b = interval
    if (b - a) <= DETERMINED_WIDTH * w:
        return "determined"
    cut_low = (a - low) >= EXCLUDED_END * w
    cut_high = (high - b) >= EXCLUDED_END * w
    if cut_low and cut_high:
        return "narrowed"
    if cut_low:
        return "lower bound"
    if cut_high:
        return "upper bound"
    return "undetermined"


@dataclass(frozen=True, eq=False)
class LogCostGP:
    """The fitted GP of the log cost: the regressor (on the standardised log cost), the
    standardisation (mean, sd) and the noise variance sigma_n^2 of the log cost."""

    gp: GaussianProcessRegressor
    mean: float
    scale: float
    noise_var: float

    def predict(self, U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and latent variance (without the noise) of the log cost at the rows of ``U``."""
        # the GP's own prediction, written out (Matern 5/2 with ARD) because the sampler calls
        # it thousands of times and scikit-learn's predict costs most of its time in overhead
        gp = self.gp
        amp = float(gp.kernel_.k1.k1.constant_value)
        ls = np.asarray(gp.kernel_.k1.k2.length_scale, float)
        r = cdist(np.atleast_2d(U) / ls, gp.X_train_ / ls)
        s5 = math.sqrt(5.0) * r
        k = amp * (1.0 + s5 + s5**2 / 3.0) * np.exp(-s5)
        mu = k @ gp.alpha_
        var = np.maximum(amp - np.einsum("ij,ij->i", k @ self._k_inv, k), 0.0)
        return self.mean + mu * self.scale, var * self.scale**2

    @cached_property
    def _k_inv(self) -> np.ndarray:
        """The inverse of the training covariance (noise included), from its Cholesky factor."""
        l_inv = solve_triangular(self.gp.L_, np.eye(len(self.gp.L_)), lower=True)
        return l_inv.T @ l_inv


def fit_log_cost_gp(
    U: np.ndarray, cost: np.ndarray, seed: int = 0, prior_mean: float | None = None
) -> LogCostGP:
    """The GP of the module docstring fitted to points ``U`` (n, d) of the unit cube and their
    costs (> 0, dimensionless); ``prior_mean`` is the log cost it reverts to far from the
    evaluations (default: the mean of their log costs)."""
    d = U.shape[1]
    kernel = ConstantKernel(1.0, (1e-3, 1e3)) * Matern(
        length_scale=np.full(d, 0.3), length_scale_bounds=LENGTH_SCALE_BOUNDS, nu=2.5
    ) + WhiteKernel(0.05, (1e-6, 10.0))
    gp = GaussianProcessRegressor(kernel=kernel, n_restarts_optimizer=1, random_state=seed)
    z = np.log(cost)
    mean = float(z.mean()) if prior_mean is None else float(prior_mean)
    scale = float(np.sqrt(np.mean((z - mean) ** 2))) or 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        gp.fit(U, (z - mean) / scale)
    return LogCostGP(gp, mean, scale, float(gp.kernel_.k2.noise_level) * scale**2)


def _log_likelihood(model: LogCostGP, U: np.ndarray, log_eps: float) -> np.ndarray:
    """log L(u) of the module docstring at the rows of ``U``."""
    mu, var = model.predict(U)
    return log_ndtr((log_eps - mu) / np.sqrt(var + model.noise_var))


def _reflect(u: np.ndarray) -> np.ndarray:
    """Fold points back into the unit cube (mirror at the faces)."""
    u = np.mod(u, 2.0)
    return np.where(u > 1.0, 2.0 - u, u)


def _rhat(chains: np.ndarray) -> np.ndarray:
    """Split-chain Gelman-Rubin R-hat per dimension of ``chains`` (m, n, d)."""
    n = chains.shape[1]
    half = n // 2
    split = np.concatenate([chains[:, :half], chains[:, half : 2 * half]], axis=0)
    means = split.mean(axis=1)
    within = split.var(axis=1, ddof=1).mean(axis=0)
    between = half * means.var(axis=0, ddof=1)
    var = (half - 1) / half * within + between / half
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.sqrt(var / within)
    return np.where(within > 0, r, 1.0)


def plausible_sample(
    model: LogCostGP,
    log_eps: float,
    d: int,
    *,
    alpha: float = ALPHA,
    seed: int = 0,
    starts: np.ndarray | None = None,
    n_chains: int = N_CHAINS,
    n_steps: int = N_STEPS,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Points of the plausible set S = {u : L(u) >= alpha} on the unit cube (module docstring):
    the Sobol points in S and the kept states of random-walk chains uniform on S, started from
    ``starts`` (rows of the unit cube, e.g. the evaluated points) and Sobol points in S. Returns
    the points (m, d; empty when S is), R-hat of the chains per dimension and the largest L
    seen."""
    rng = np.random.default_rng([seed, 0x1D])
    log_alpha = math.log(alpha)
    sobol = qmc.Sobol(d, scramble=True, seed=rng).random(N_SOBOL)
    cand = sobol if starts is None or not len(starts) else np.vstack([starts, sobol])
    ll0 = _log_likelihood(model, cand, log_eps)
    best = float(np.exp(ll0.max()))
    inside = cand[ll0 >= log_alpha]
    if not len(inside):
        return np.empty((0, d)), np.ones(d), best
    u = inside[rng.choice(len(inside), n_chains, replace=len(inside) < n_chains)].copy()
    scale = np.full(d, 0.1)  # per-parameter step: factor * spread of the chains
    factor = 1.0
    burn = n_steps // 2
    kept = np.empty((n_chains, n_steps - burn, d))
    accepted = 0
    for k in range(n_steps):
        prop = _reflect(u + factor * scale * rng.standard_normal(u.shape))
        take = _log_likelihood(model, prop, log_eps) >= log_alpha  # uniform on S
        u[take] = prop[take]
        accepted += int(take.sum())
        if k < burn and (k + 1) % 50 == 0:  # adapt: about 30 % acceptance, steps as wide as
            rate = accepted / (50 * n_chains)  # the chains' spread along each parameter
            factor = float(np.clip(factor * math.exp(rate - 0.3), 0.05, 3.0))
            scale = np.clip(2.38 / math.sqrt(d) * u.std(axis=0), 1e-3, 0.5)
            accepted = 0
        if k >= burn:
            kept[:, k - burn] = u
    sobol_in = sobol[_log_likelihood(model, sobol, log_eps) >= log_alpha]
    return np.vstack([kept.reshape(-1, d), sobol_in]), _rhat(kept), best


def identify(
    space: Space,
    points: Sequence[Mapping[str, float]],
    costs: Sequence[float | None],
    threshold: float,
    *,
    threshold_source: str = "",
    typical_cost: float | None = None,
    cost_sd: Sequence[float | None] | None = None,
    seed: int = 0,
    alpha: float = ALPHA,
    n_steps: int = N_STEPS,
) -> Identifiability:
    """The identifiability of every parameter of ``space`` from evaluated ``points`` (SI) and
    their ``costs`` (dimensionless; None: failed) given the acceptance ``threshold`` epsilon
    (what real runs score, `parcelfit.study.joint.threshold`) and the ``typical_cost`` of the parameter box (the
    geometric mean of a uniform design's costs, e.g. the initial Latin hypercube; default: of
    all the evaluations) and ``cost_sd``, the standard error of each cost as an estimator (None
    where not known); module docstring. Seeded: the same inputs give the same result."""
    if not math.isfinite(threshold) or threshold <= 0:
        raise ParcelfitError(
            f"the acceptance threshold must be a positive cost, got {threshold}",
            fix="the real runs of the test case must differ (a zero threshold means they are "
            "identical)",
        )
    ok = [
        (p, c)
        for p, c in zip(points, costs, strict=True)
        if c is not None and math.isfinite(c) and c >= 0
    ]
    if len(ok) < 3:
        raise ParcelfitError(
            f"{len(ok)} successful evaluations: too few to say what the data determine",
            fix="run more evaluations",
        )
    U = np.array([space.to_unit(p) for p, _ in ok])
    floor = max(1e-12, 1e-6 * threshold)
    cost = np.maximum(np.array([c for _, c in ok], float), floor)
    prior = None if typical_cost is None else math.log(max(typical_cost, floor))
    model = fit_log_cost_gp(U, cost, seed, prior_mean=prior)
    rel = [
        (sd / c) ** 2
        for sd, c in zip(cost_sd or (), costs, strict=False)
        if sd is not None and c is not None and c > 0 and math.isfinite(sd)
    ]
    if rel:  # the estimator's own error (module docstring), added to the noise
        model = replace(model, noise_var=model.noise_var + float(np.median(rel)))
    d = len(space)
    sample_u, rhat, best = plausible_sample(
        model, math.log(threshold), d, alpha=alpha, seed=seed, starts=U, n_steps=n_steps
    )
    reached = len(sample_u) > 0
    # an evaluation in S: a plausible set no evaluation lies in is the surrogate's extrapolation
    # alone (a valley between evaluations that all cost more than the real runs score)
    supported = bool(np.any(_log_likelihood(model, U, math.log(threshold)) >= math.log(alpha)))
    if not (reached and supported):  # no value can be told from another
        sample_u = np.random.default_rng([seed, 0x5A]).random((N_KEEP_FOR_PLOT, d))
    values = np.array([list(space.from_unit(u).values()) for u in sample_u])
    params = []
    for j, dim in enumerate(space.dims):
        interval = (
            (float(values[:, j].min()), float(values[:, j].max()))
            if reached and supported
            else (dim.low, dim.high)
        )
        params.append(
            ParameterInterval(
                name=dim.name,
                low=dim.low,
                high=dim.high,
                interval=interval,
                median=float(np.median(values[:, j])),
                verdict=verdict(dim.low, dim.high, interval),
                rhat=float(rhat[j]),
            )
        )
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.atleast_2d(np.corrcoef(sample_u, rowvar=False))
    corr = np.where(np.isfinite(corr), corr, 0.0)
    np.fill_diagonal(corr, 1.0)
    thin = np.random.default_rng([seed, 0x7A]).permutation(len(values))[:N_KEEP_FOR_PLOT]
    return Identifiability(
        parameters=tuple(params),
        correlation=corr,
        sample=values[np.sort(thin)],
        threshold=float(threshold),
        threshold_source=threshold_source,
        evaluations=len(ok),
        noise_sd=math.sqrt(model.noise_var),
        level=1.0 - alpha,
        reached=reached,
        supported=supported,
        best_acceptance=best,
    )


__all__ = [
    "ALPHA",
    "DETERMINED_WIDTH",
    "EXCLUDED_END",
    "VERDICTS",
    "Advice",
    "Identifiability",
    "LogCostGP",
    "ParameterInterval",
    "fit_log_cost_gp",
    "identify",
    "plausible_sample",
    "verdict",
]
