"""Which calibrated parameters the data determine, and to what interval (identifiability).

A calibration returns one parameter set; this module says which of its values the data actually
fix. It reads only the study's evaluations (parameters and costs) and one number from the real
runs, the acceptance threshold epsilon, and simulates nothing.

**Threshold.** A simulation at the true parameters is, at best, like one more real run: its cost
scores like a real run's. So epsilon is the largest cost a real run scores in the same
cost function (`parcelfit.metrics.ensemble.real_run_costs`: for the published cost, equation 3
of every real run against the reference run; for the ensemble cost, the ensemble cost of every
real run against the other real runs; for a joint study the weighted sum of the cases'
thresholds, which is conservative: the sum of the largest values is at least the largest sum).

**Surrogate.** A Gaussian process on the unit cube (`parcelfit.optimize.space`) models the log
cost of the finished evaluations (failed ones carry no cost and are left out):

    log c(u) ~ GP(m, k),  k = s^2 Matern_5/2(u, u'; l_1..l_d) + sigma_n^2 delta(u, u')

with one length scale per parameter (l_j in [0.05, 100]: features narrower than 5 % of the range
cannot be resolved by a few dozen evaluations; a parameter without effect gets a long one) and
the noise variance sigma_n^2 (the run-to-run scatter of the cost) fitted by marginal likelihood
(scikit-learn). It is fitted here, independently of the optimiser's own surrogate, so the
analysis does not change when the optimiser's settings do.

**Likelihood** (approximate Bayesian computation with a GP surrogate of the discrepancy, as in
BOLFI, Gutmann and Corander 2016, JMLR 17(125)): the probability that a simulation at u scores a
cost below epsilon,

    L(u) = Phi( (log epsilon - mu(u)) / sqrt(v(u) + sigma_n^2) )

with mu, v the GP's predictive mean and variance of the latent log cost. Where the evaluations
are few, v is large and L stays near 1/2: an unexplored region stays plausible.

**Posterior sample.** Prior uniform on the unit cube (log-uniform for log-scaled parameters);
posterior p(u) ~ L(u). Sixteen random-walk Metropolis chains (seeded, started from the 16 points
of highest L among 4096 Sobol points; Gaussian steps reflected at the cube's faces, so the
proposal stays symmetric; the step of each parameter is adapted during the first half to
the chains' spread and about 30 % acceptance, and then fixed), 2000 steps
each, the second half kept. R-hat (Gelman-Rubin, split chains) is stored per parameter; above
1.1 the report says the sample has not converged.

**Intervals and verdicts.** Per parameter, the interval is the central 99 % of the posterior
sample, [q_0.005, q_0.995], in the parameter's own unit. With its width W and its distances
from the range's ends as shares of the range (high - low):

* **determined**: W <= 20 % of the range. The estimate is the interval's midpoint, so every
  value in the interval (the truth among them) is within 10 % of the range of it;
* **lower bound** / **upper bound**: not determined, and the interval leaves out at least 10 % of
  the range at one end only (the data rule out low, resp. high, values and nothing else);
* **narrowed**: not determined, and at least 10 % is left out at both ends;
* **undetermined**: less than 10 % is left out at either end: the data cannot tell the values
  apart, and no value is reported.

Correlations are the Pearson correlations of the posterior sample on the unit cube; a
correlation near +-1 says that the data fix a combination of two parameters, not each.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from scipy.linalg import solve_triangular
from scipy.spatial.distance import cdist
from scipy.special import log_ndtr
from scipy.stats import qmc
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

from parcelfit.errors import ParcelfitError
from parcelfit.optimize.space import Space

LEVEL = 0.99  # central posterior mass of the reported interval
DETERMINED_WIDTH = 0.20  # widest interval (share of the range) called determined
EXCLUDED_END = 0.10  # share of the range an end must leave out to count as a bound
LENGTH_SCALE_BOUNDS = (0.05, 100.0)  # on the unit cube
N_CHAINS = 16
N_STEPS = 2000
N_KEEP_FOR_PLOT = 2000  # posterior points stored for the pairwise plot
VERDICTS = ("determined", "lower bound", "upper bound", "narrowed", "undetermined")


@dataclass(frozen=True)
class ParameterInterval:
    """One parameter's verdict: its range and interval [low, high] (SI), the posterior median,
    the verdict (one of `VERDICTS`) and R-hat of its chains."""

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
        return {
            "name": self.name,
            "low": self.low,
            "high": self.high,
            "interval": list(self.interval),
            "median": self.median,
            "verdict": self.verdict,
            "rhat": self.rhat,
        }

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> ParameterInterval:
        """Read the stored form."""
        lo, hi = doc["interval"]
        return cls(
            str(doc["name"]),
            float(doc["low"]),
            float(doc["high"]),
            (float(lo), float(hi)),
            float(doc["median"]),
            str(doc["verdict"]),
            float(doc["rhat"]),
        )


@dataclass(frozen=True, eq=False)
class Identifiability:
    """What the evaluations say about each parameter (see the module docstring): the intervals,
    the posterior correlation matrix (order of ``parameters``), a thinned posterior sample in
    SI (``sample``: (m, d)), the threshold epsilon and where it came from, how many evaluations
    the surrogate learnt, its fitted noise standard deviation (of the log cost) and the
    posterior's effective sample size (summed over parameters' chains, smallest)."""

    parameters: tuple[ParameterInterval, ...]
    correlation: np.ndarray
    sample: np.ndarray
    threshold: float
    threshold_source: str
    evaluations: int
    noise_sd: float
    level: float = LEVEL

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

    def to_json(self) -> dict[str, Any]:
        """The stored form (SI)."""
        return {
            "parameters": [p.to_json() for p in self.parameters],
            "correlation": np.asarray(self.correlation, float).tolist(),
            "sample": np.asarray(self.sample, float).tolist(),
            "threshold": self.threshold,
            "threshold_source": self.threshold_source,
            "evaluations": self.evaluations,
            "noise_sd": self.noise_sd,
            "level": self.level,
        }

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> Identifiability:
        """Read the stored form."""
        d = len(doc["parameters"])
        return cls(
            tuple(ParameterInterval.from_json(p) for p in doc["parameters"]),
            np.asarray(doc["correlation"], float).reshape(d, d),
            np.asarray(doc["sample"], float).reshape(-1, d),
            float(doc["threshold"]),
            str(doc["threshold_source"]),
            int(doc["evaluations"]),
            float(doc["noise_sd"]),
            float(doc.get("level", LEVEL)),
        )


@dataclass(frozen=True)
class Advice:
    """Which candidate case responds most to the undetermined parameters: per case the change
    Delta_k (`parcelfit.study.joint`) per parameter, and the best case (None if none could be
    simulated)."""

    changes: dict[str, dict[str, float]]  # case label -> parameter -> Delta
    best: str | None
    parameters: tuple[str, ...]
    params: dict[str, float] = field(default_factory=dict)  # the calibrated set simulated (SI)

    def to_json(self) -> dict[str, Any]:
        """The stored form."""
        return {
            "changes": self.changes,
            "best": self.best,
            "parameters": list(self.parameters),
            "params": dict(self.params),
        }

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> Advice:
        """Read the stored form."""
        return cls(
            {str(c): {str(p): float(v) for p, v in d.items()} for c, d in doc["changes"].items()},
            doc.get("best"),
            tuple(doc.get("parameters") or ()),
            {str(k): float(v) for k, v in (doc.get("params") or {}).items()},
        )


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


def fit_log_cost_gp(U: np.ndarray, cost: np.ndarray, seed: int = 0) -> LogCostGP:
    """The GP of the module docstring fitted to points ``U`` (n, d) of the unit cube and their
    costs (> 0, dimensionless)."""
    d = U.shape[1]
    kernel = ConstantKernel(1.0, (1e-3, 1e3)) * Matern(
        length_scale=np.full(d, 0.3), length_scale_bounds=LENGTH_SCALE_BOUNDS, nu=2.5
    ) + WhiteKernel(0.05, (1e-6, 10.0))
    gp = GaussianProcessRegressor(kernel=kernel, n_restarts_optimizer=1, random_state=seed)
    z = np.log(cost)
    mean, scale = float(z.mean()), float(z.std()) or 1.0
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


def posterior_sample(
    model: LogCostGP,
    log_eps: float,
    d: int,
    *,
    seed: int = 0,
    n_chains: int = N_CHAINS,
    n_steps: int = N_STEPS,
) -> tuple[np.ndarray, np.ndarray]:
    """Random-walk Metropolis on the unit cube (module docstring); returns the kept sample
    (n_chains * n_steps / 2, d) and R-hat per dimension."""
    rng = np.random.default_rng([seed, 0x1D])
    sobol = qmc.Sobol(d, scramble=True, seed=rng).random(4096)
    ll0 = _log_likelihood(model, sobol, log_eps)
    u = sobol[np.argsort(-ll0, kind="stable")[:n_chains]].copy()
    ll = _log_likelihood(model, u, log_eps)
    scale = np.full(d, 0.1)  # per-parameter step: factor * spread of the chains
    factor = 1.0
    burn = n_steps // 2
    kept = np.empty((n_chains, n_steps - burn, d))
    accepted = 0
    for k in range(n_steps):
        prop = _reflect(u + factor * scale * rng.standard_normal(u.shape))
        llp = _log_likelihood(model, prop, log_eps)
        take = np.log(rng.random(n_chains)) < llp - ll
        u[take], ll[take] = prop[take], llp[take]
        accepted += int(take.sum())
        if k < burn and (k + 1) % 50 == 0:  # adapt: about 30 % acceptance, steps as wide as
            rate = accepted / (50 * n_chains)  # the chains' spread along each parameter
            factor = float(np.clip(factor * math.exp(rate - 0.3), 0.05, 3.0))
            scale = np.clip(2.38 / math.sqrt(d) * u.std(axis=0), 1e-3, 0.5)
            accepted = 0
        if k >= burn:
            kept[:, k - burn] = u
    return kept.reshape(-1, d), _rhat(kept)


def identify(
    space: Space,
    points: Sequence[Mapping[str, float]],
    costs: Sequence[float | None],
    threshold: float,
    *,
    threshold_source: str = "",
    seed: int = 0,
    level: float = LEVEL,
    n_steps: int = N_STEPS,
) -> Identifiability:
    """The identifiability of every parameter of ``space`` from evaluated ``points`` (SI) and
    their ``costs`` (dimensionless; None: failed) given the acceptance ``threshold`` epsilon
    (the largest cost a real run scores; module docstring). Seeded: the same inputs give the
    same result."""
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
    model = fit_log_cost_gp(U, cost, seed)
    d = len(space)
    sample_u, rhat = posterior_sample(model, math.log(threshold), d, seed=seed, n_steps=n_steps)
    values = np.array([list(space.from_unit(u).values()) for u in sample_u])
    tail = (1.0 - level) / 2
    params = []
    for j, dim in enumerate(space.dims):
        lo, hi = np.quantile(values[:, j], [tail, 1 - tail])
        interval = (float(lo), float(hi))
        params.append(
            ParameterInterval(
                dim.name,
                dim.low,
                dim.high,
                interval,
                float(np.median(values[:, j])),
                verdict(dim.low, dim.high, interval),
                float(rhat[j]),
            )
        )
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.atleast_2d(np.corrcoef(sample_u, rowvar=False))
    corr = np.where(np.isfinite(corr), corr, 0.0)
    np.fill_diagonal(corr, 1.0)
    thin = np.random.default_rng([seed, 0x7A]).permutation(len(values))[:N_KEEP_FOR_PLOT]
    return Identifiability(
        tuple(params),
        corr,
        values[np.sort(thin)],
        float(threshold),
        threshold_source,
        len(ok),
        math.sqrt(model.noise_var),
        level,
    )


__all__ = [
    "DETERMINED_WIDTH",
    "EXCLUDED_END",
    "LEVEL",
    "VERDICTS",
    "Advice",
    "Identifiability",
    "LogCostGP",
    "ParameterInterval",
    "fit_log_cost_gp",
    "identify",
    "posterior_sample",
    "verdict",
]
