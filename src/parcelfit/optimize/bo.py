"""Batch Bayesian optimisation with ask/tell, minimising a cost (formulas: README.md here).

Two configurations of one `BatchBO` (`BOSettings`):

* the default, chosen on the held-out half of ``benchmarks/bench_bo_wide.py``: Latin hypercube
  of 16; GP (scikit-learn) with Matern 5/2 (no signal variance: the cost is standardised), one
  length scale per input and the noise variance within [1e-6, 0.35^2] of the standardised cost,
  fitted by maximum a posteriori with BoTorch's dimension-scaled priors (prior.py); the cost
  left as it is or Box-Cox transformed (lambda fitted, scikit-learn ``PowerTransformer``),
  whichever gives the costs the higher warped-GP likelihood; the acquisition log noisy expected improvement (expected
  improvement averaged over draws of the latent cost at the evaluated points, whose best is the
  incumbent; nei.py), maximised over Monte Carlo candidates and polished by
  L-BFGS-B from the best of them; the batch chosen by kriging believer (pick one point, believe
  it at its predicted mean, refit with the kernel fixed, pick the next); the recommendation is
  the evaluated point with the lowest GP mean cost;
* ``BOSettings.published()``, method.md section 7: the Matern 5/2 kernel alone with one length
  scale, noise 0.35^2, untransformed cost, UCB (lambda 2) on uniform Monte Carlo samples,
  k-means (k = batch size) on the best 25 % with the best-UCB sample of each cluster as the
  batch, recommendation the lowest observed cost.

Common to both: the GP models the standardised negative (transformed) cost; pending points
(asked, not yet told) enter as kriging-believer fantasies (``batch: joint``: as noisy EI's jointly
drawn pending points) so asking again does not repeat them;
failed evaluations are told with ``cost=None`` and kept with the worst finite cost seen so far
(the store keeps the raw failure); every random draw of ask() uses numpy's generator seeded with
(seed, number of observations, number of pending points), and noisy EI's draws with (seed,
number of points the GP was conditioned on, believed ones included; with ``batch: joint`` the
number of evaluated and of pending points), so the same history gives
the same batch, which is what makes a resumed study replay exactly.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from scipy.optimize import minimize
from scipy.stats import qmc
from sklearn.cluster import KMeans
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel
from sklearn.preprocessing import PowerTransformer
from threadpoolctl import threadpool_limits

from parcelfit.errors import ParcelfitError
from parcelfit.optimize.kernel import cross_kernel, posterior
from parcelfit.optimize.nei import NoisyEI
from parcelfit.optimize.nei import log_h as _log_h
from parcelfit.optimize.prior import MapOptimizer
from parcelfit.optimize.space import Space

TRANSFORMS = ("none", "log", "power", "auto")
SETTING_CHOICES: dict[str, tuple[str, ...]] = {
    "noise": ("fit", "fixed"),
    "transform": TRANSFORMS,
    "acquisition": ("ucb", "logei", "lognei"),
    "batch": ("believer", "kmeans", "joint"),
    "recommend": ("posterior_mean", "best_observed"),
    "incumbent": ("observed", "mean"),
    "prior": ("none", "dim_scaled"),
}
"""The text settings of `BOSettings` and the values each takes."""


@dataclass(frozen=True)
class BOSettings:
    """Settings of the batch BO. The defaults are the measured default (see the module docstring);
    `BOSettings.published()` gives the configuration of method.md section 7."""

    n_initial: int = field(default=16, metadata={"help": "Latin hypercube size [evaluations]"})
    ucb_lambda: float = field(default=2.0, metadata={"help": "exploration weight of UCB [-]"})
    n_samples: int = field(
        default=4000, metadata={"help": "Monte Carlo candidates of the acquisition per ask"}
    )
    top_fraction: float = field(
        default=0.25, metadata={"help": "share of candidates kept for clustering (batch: kmeans)"}
    )
    local_fraction: float = field(
        default=0.25, metadata={"help": "share of candidates drawn near the best observations"}
    )
    nu: float = field(default=2.5, metadata={"help": "Matern smoothness [-]"})
    alpha: float = field(
        default=0.35**2,
        metadata={"help": "noise variance on the standardised cost (noise: fixed)"},
    )
    noise: str = field(
        default="fit",
        metadata={
            "help": "fit: the noise variance by marginal likelihood in [1e-6, noise_max]; "
            "fixed: alpha"
        },
    )
    n_restarts: int = field(
        default=1, metadata={"help": "optimiser restarts of the GP's hyperparameters"}
    )
    noise_max: float = field(
        default=0.35**2,
        metadata={"help": "upper bound of the fitted noise variance (noise: fit)"},
    )
    amplitude_max: float = field(
        default=1e2,
        metadata={"help": "upper bound of the fitted signal variance (amplitude: true)"},
    )
    transform: str = field(
        default="auto",
        metadata={
            "help": "the costs' warping: none, log, power (Box-Cox, lambda fitted to the costs' "
            "marginal distribution) or auto (of none and power, the one whose warped GP explains "
            "the costs best)"
        },
    )
    acquisition: str = field(
        default="lognei",
        metadata={
            "help": "lognei (log noisy expected improvement: EI averaged over draws of the latent "
            "function at the evaluated points, nei.py), logei (log expected improvement over "
            "incumbent) or ucb"
        },
    )
    polish: int = field(
        default=2,
        metadata={"help": "L-BFGS-B polishing starts from the best candidates (0: sampled only)"},
    )
    batch: str = field(
        default="believer",
        metadata={
            "help": "believer (kriging believer, sequential), kmeans (published) or joint "
            "(acquisition lognei only: each point by noisy EI given the batch so far and the "
            "pending points, drawn jointly with the evaluated points; nothing is believed)"
        },
    )
    nei_samples: int = field(
        default=128,
        metadata={"help": "draws of the latent function (lognei), a power of 2 (Sobol)"},
    )
    ard: bool = field(
        default=True,
        metadata={"help": "one length scale per input (false: one shared length scale)"},
    )
    prior: str = field(
        default="dim_scaled",
        metadata={
            "help": "dim_scaled (maximum a posteriori with BoTorch's priors: log-normal on the "
            "length scales, LogNormal(sqrt 2 + log(d) / 2, 3), and on the noise variance, "
            "LogNormal(-4, 1); prior.py) or none (maximum marginal likelihood)"
        },
    )
    amplitude: bool = field(
        default=False,
        metadata={
            "help": "false: the Matern kernel alone on the standardised cost (as BoTorch's GP); "
            "true: a fitted signal variance (<= amplitude_max) times it"
        },
    )
    recommend: str = field(
        default="posterior_mean",
        metadata={
            "help": "the parameters reported: posterior_mean (the evaluated point with the "
            "lowest GP mean cost) or best_observed (published)"
        },
    )
    incumbent: str = field(
        default="mean",
        metadata={
            "help": "the incumbent of expected improvement (acquisition: logei): observed (the "
            "best observed cost) or mean (the lowest posterior mean at an evaluated point)"
        },
    )

    def __post_init__(self) -> None:
        for name, choices in SETTING_CHOICES.items():
            if getattr(self, name) not in choices:
                raise ParcelfitError(
                    f"invalid BO settings: {name} {getattr(self, name)!r} is not one of "
                    f"{', '.join(choices)}"
                )
        for name, ok, needs in (
            ("n_initial", self.n_initial >= 1, "at least 1"),
            ("n_samples", self.n_samples >= 10, "at least 10"),
            ("top_fraction", 0 < self.top_fraction <= 1, "above 0 and at most 1"),
            ("local_fraction", 0 <= self.local_fraction <= 1, "from 0 to 1"),
            ("alpha", self.alpha > 0, "above 0"),
            ("noise_max", self.noise_max > NOISE_LOW, f"above {NOISE_LOW:g}"),
            ("amplitude_max", self.amplitude_max > 1e-2, "above 0.01"),
            ("polish", self.polish >= 0, "0 or more"),
            (
                "nei_samples",
                self.nei_samples >= 2 and not self.nei_samples & (self.nei_samples - 1),
                "a power of 2 from 2",
            ),
            (
                "batch",
                self.batch != "joint" or self.acquisition == "lognei",
                "believer or kmeans unless acquisition is lognei",
            ),
        ):
            if not ok:
                raise ParcelfitError(
                    f"invalid BO settings: {name} {getattr(self, name)!r} must be {needs}"
                )

    @classmethod
    def published(cls, **overrides: Any) -> BOSettings:
        """The configuration of method.md section 7 (Latin hypercube 16, Matern 5/2, noise
        0.35^2, UCB by uniform Monte Carlo sampling, k-means on the top 25 %, best observed)."""
        base: dict[str, Any] = {
            "noise": "fixed",
            "alpha": 0.35**2,
            "transform": "none",
            "acquisition": "ucb",
            "polish": 0,
            "batch": "kmeans",
            "local_fraction": 0.0,
            "ard": False,
            "amplitude": False,
            "prior": "none",
            "recommend": "best_observed",
            "incumbent": "observed",
            "n_restarts": 3,
        }
        return cls(**{**base, **overrides})


class Fit(NamedTuple):
    """A GP fitted to the observations: it predicts y = -(z - mean) / std, z the cost after
    ``transform``; ``y_best`` is the incumbent of expected improvement."""

    gp: GaussianProcessRegressor
    mean: float
    std: float
    y_best: float
    transform: str


@dataclass
class Observation:
    """One told evaluation: unit-cube point, parameters and cost (None if it failed)."""

    u: np.ndarray
    params: dict[str, float]
    cost: float | None


def settle_told(u: np.ndarray, pending: list[np.ndarray], initial: list[np.ndarray]) -> None:
    """Remove a told point ``u`` (unit cube) from ``pending``, or, if it was told without being
    asked (replayed from a store), from the ``initial`` design queue; in place."""
    for queue in (pending, initial):
        for i, p in enumerate(queue):
            if np.allclose(p, u, atol=1e-12):
                del queue[i]
                return


@dataclass
class BatchBO:
    """Ask/tell batch Bayesian optimiser (see the module docstring). Minimises the cost."""

    space: Space
    batch_size: int = 4
    seed: int = 0
    settings: BOSettings = field(default_factory=BOSettings)

    def __post_init__(self) -> None:
        if isinstance(self.space, Mapping):
            self.space = Space.from_bounds(self.space)  # type: ignore[arg-type]
        if self.batch_size < 1:
            raise ParcelfitError(f"batch size must be >= 1, got {self.batch_size}")
        lhs = qmc.LatinHypercube(
            d=len(self.space), scramble=True, seed=np.random.default_rng([self.seed, 0xA11])
        )
        self._initial = list(lhs.random(self.settings.n_initial))
        self.observations: list[Observation] = []
        self.pending: list[np.ndarray] = []
        self._nei: tuple[GaussianProcessRegressor, NoisyEI] | None = None

    # -- public API -------------------------------------------------------------------------
    def ask(self, n: int | None = None) -> list[dict[str, float]]:
        """The next ``n`` parameter sets to evaluate (default: the batch size)."""
        n = self.batch_size if n is None else n
        out: list[np.ndarray] = []
        while self._initial and len(out) < n:
            out.append(self._initial.pop(0))
        if len(out) < n:
            # one BLAS thread: the matrices are small (n x n for n evaluations), and on a machine
            # busy with simulations threaded BLAS spins and makes a 200 x 200 Cholesky 1000x slower
            with threadpool_limits(1):
                out += self._suggest(n - len(out), extra_pending=out)
        self.pending += out
        return [self.space.from_unit(u) for u in out]

    def tell(self, params: Mapping[str, float], cost: float | None) -> None:
        """Report the cost of an evaluated parameter set (None or non-finite: failed)."""
        u = self.space.to_unit(params)
        settle_told(u, self.pending, self._initial)
        ok = cost is not None and math.isfinite(cost)
        self.observations.append(Observation(u, dict(params), float(cost) if ok else None))

    @property
    def n_told(self) -> int:
        """How many evaluations were told."""
        return len(self.observations)

    def best(self) -> tuple[dict[str, float], float] | None:
        """The evaluated parameters with the lowest cost, and that cost (None before any success)."""
        ok = [o for o in self.observations if o.cost is not None]
        if not ok:
            return None
        b = min(ok, key=lambda o: o.cost)  # type: ignore[arg-type, return-value]
        return dict(b.params), float(b.cost)  # type: ignore[arg-type]

    def recommend(self) -> tuple[dict[str, float], float] | None:
        """The parameters to report and validate, with their observed cost.

        "best_observed" (the published choice) takes the lowest observed cost. The cost of a
        parcel simulation is rough: a small parameter change moves it by run-to-run amounts, so
        the single lowest value is partly luck. "posterior_mean" (default) takes, among the
        evaluated points, the one whose GP mean cost is lowest: the surrogate averages over
        neighbouring evaluations, a standard recommendation for noisy objectives.
        """
        best = self.best()
        if best is None or self.settings.recommend == "best_observed":
            return best
        with threadpool_limits(1):
            fitted = self._fit(np.random.default_rng([self.seed, len(self.observations)]), [])
        if fitted is None:
            return best
        gp = fitted[0]
        ok = sorted((o for o in self.observations if o.cost is not None), key=lambda o: tuple(o.u))
        y = gp.predict(np.array([o.u for o in ok]))
        pick = ok[int(np.argmax(y))]  # y is the standardised negative cost
        return dict(pick.params), float(pick.cost)  # type: ignore[arg-type]

    def surrogate(self) -> GaussianProcessRegressor | None:
        """The GP fitted to the observations (None before two successes); predicts standardised -cost."""
        fitted = self._fit(np.random.default_rng([self.seed, len(self.observations)]), [])
        return None if fitted is None else fitted[0]

    # -- internals ---------------------------------------------------------------------------
    def _training_data(self) -> tuple[np.ndarray, np.ndarray] | None:
        ok = [o.cost for o in self.observations if o.cost is not None]
        if len(ok) < 2:
            return None
        worst = max(ok)
        # A canonical order (by position in the unit cube, then cost): the fit depends on the set
        # of observations, not on the order in which parallel workers happened to finish or a
        # resumed study replayed them. Summation order changes the GP's fit in its last digits,
        # and a rough objective amplifies that into a different next batch.
        obs = sorted(
            self.observations,
            key=lambda o: (tuple(o.u), math.inf if o.cost is None else o.cost),
        )
        X = np.array([o.u for o in obs])
        c = np.array([o.cost if o.cost is not None else worst for o in obs])
        return X, c

    def _transformed(self, c: np.ndarray, kind: str) -> tuple[np.ndarray, float]:
        """The cost after the output transform ``kind`` ("none", "log" or "power"), before
        standardising, and sum_i log |dz/dc| at the costs (the transform's Jacobian)."""
        if kind not in ("none", "log", "power"):
            raise ValueError(f"not a single transform: {kind!r}")
        if kind == "none" or np.ptp(c) <= 0:
            return c, 0.0
        shifted = c - c.min() + 0.01 * float(np.ptp(c))
        log_shifted = np.log(shifted)
        if kind == "power":
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                pt = PowerTransformer(method="box-cox", standardize=False)
                out = pt.fit_transform(shifted[:, None])[:, 0]
            if np.all(np.isfinite(out)) and np.ptp(out) > 0:
                lam = float(pt.lambdas_[0])  # dz/dc = s^(lambda - 1)
                return out, float((lam - 1.0) * log_shifted.sum())
        return log_shifted, float(-log_shifted.sum())  # log: dz/dc = 1 / s

    def _fit(self, rng: np.random.Generator, fantasies: Sequence[np.ndarray]) -> Fit | None:
        """The GP on the observations (``fantasies``: pending points, believed at their mean).

        With ``transform: auto`` a GP is fitted for each of "none" and "power", and the one with
        the higher likelihood of the costs themselves wins: the log marginal likelihood of the
        standardised transformed y plus the log Jacobian sum_i log |dy_i/dc_i| (a warped GP's
        likelihood). Box-Cox alone picks lambda from the costs' histogram; this compares the
        transforms by how well a smooth GP explains the costs over the inputs.
        """
        data = self._training_data()
        if data is None:
            return None
        X, c = data
        s = self.settings
        state = int(rng.integers(2**31 - 1))
        kinds = ("none", "power") if s.transform == "auto" else (s.transform,)
        best: tuple[float, GaussianProcessRegressor, float, float, np.ndarray, str] | None = None
        for kind in kinds:
            z, log_jac = self._transformed(c, kind)
            mean, std = float(z.mean()), float(z.std())
            scale = std if std > 0 else 1.0
            y = -(z - mean) / scale
            gp = self._fit_gp(X, y, state)
            score = float(gp.log_marginal_likelihood_value_) + log_jac - len(y) * math.log(scale)
            if best is None or score > best[0]:
                best = (score, gp, mean, std, y, kind)
        assert best is not None
        _, gp, mean, std, y, kind = best
        if s.noise == "fit":
            # predict the latent cost: the fitted noise becomes alpha, the kernel stays fixed
            gp = _conditioned(gp.kernel_.k1, gp.kernel_.k2.noise_level, X, y)
        y_best = float(y.max())
        if s.incumbent == "mean":
            y_best = float(gp.predict(X).max())
        if fantasies:
            # kriging believer: pending points count as observed at the predicted mean, with
            # the fitted kernel kept fixed, so they lower the uncertainty around themselves
            F = np.asarray(fantasies)
            believed = gp.predict(F)
            gp = _conditioned(
                gp.kernel_, gp.alpha, np.vstack([X, F]), np.concatenate([y, believed])
            )
            y_best = max(y_best, float(believed.max()))
        return Fit(gp, mean, std, y_best, kind)

    def _fit_gp(self, X: np.ndarray, y: np.ndarray, state: int) -> GaussianProcessRegressor:
        """scikit-learn's GP with the hyperparameters maximising the marginal likelihood."""
        s = self.settings
        kernel: Any = Matern(
            length_scale=np.full(X.shape[1], 0.3) if s.ard else 0.3,
            length_scale_bounds=(1e-2, 1e2),
            nu=s.nu,
        )
        if s.amplitude:
            kernel = ConstantKernel(1.0, (1e-2, s.amplitude_max)) * kernel
        if s.noise == "fit":
            kernel = kernel + WhiteKernel(min(0.01, s.noise_max), (NOISE_LOW, s.noise_max))
        gp = GaussianProcessRegressor(
            kernel=kernel,
            alpha=s.alpha if s.noise == "fixed" else 1e-10,
            optimizer="fmin_l_bfgs_b" if s.prior == "none" else MapOptimizer(kernel, X.shape[1]),
            normalize_y=False,
            n_restarts_optimizer=s.n_restarts,
            random_state=state,
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            return gp.fit(X, y)

    def _candidates(self, rng: np.random.Generator, d: int) -> np.ndarray:
        n_local = int(self.settings.local_fraction * self.settings.n_samples)
        uniform = rng.random((self.settings.n_samples - n_local, d))
        ok = sorted(
            (o for o in self.observations if o.cost is not None),
            key=lambda o: (o.cost, tuple(o.u)),  # type: ignore[arg-type, return-value]
        )[:5]
        if not ok or n_local == 0:
            return np.vstack([uniform, rng.random((n_local, d))])
        centres = np.array([o.u for o in ok])[rng.integers(len(ok), size=n_local)]
        scales = np.where(rng.random((n_local, 1)) < 0.5, 0.1, 0.02)
        local = np.clip(centres + scales * rng.standard_normal((n_local, d)), 0.0, 1.0)
        return np.vstack([uniform, local])

    def _acquisition(
        self, gp: GaussianProcessRegressor, y_best: float, U: np.ndarray
    ) -> np.ndarray:
        """UCB, log EI or log NEI of the standardised negative cost at the rows of U (higher is
        better); log NEI ignores ``y_best`` (its incumbent is drawn with the latent function)."""
        if self.settings.acquisition == "lognei":
            if self._nei is None or self._nei[0] is not gp:  # one NoisyEI per fitted GP
                seed = int(np.random.default_rng([self.seed, len(gp.X_train_)]).integers(2**31))
                self._nei = (gp, NoisyEI(gp, seed, None, self.settings.nei_samples))
            return self._nei[1](U)
        mu, sigma = _predict(gp, U)
        if self.settings.acquisition == "ucb":
            return mu + self.settings.ucb_lambda * sigma
        sigma = np.maximum(sigma, 1e-12)
        return np.log(sigma) + _log_h((mu - y_best) / sigma)

    def _polish(self, gp: GaussianProcessRegressor, y_best: float, u0: np.ndarray) -> np.ndarray:
        """L-BFGS-B from u0 on the acquisition (finite-difference gradient); u0 if not better."""

        def negative(u: np.ndarray) -> float:
            return -float(self._acquisition(gp, y_best, u[None])[0])

        res = minimize(
            negative,
            u0,
            method="L-BFGS-B",
            bounds=[(0.0, 1.0)] * len(u0),
            options={"maxiter": 15, "eps": 1e-6},
        )
        return np.clip(res.x, 0.0, 1.0) if res.fun < negative(u0) else u0

    def _best_point(
        self, gp: GaussianProcessRegressor, y_best: float, cand: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The acquisition's maximiser: best candidates, polished; and the candidates' values."""
        a = self._acquisition(gp, y_best, cand)
        starts = np.argsort(-a)[: max(1, self.settings.polish)]
        if self.settings.polish == 0:
            return cand[starts[0]], a
        polished = [self._polish(gp, y_best, cand[i]) for i in starts]
        values = self._acquisition(gp, y_best, np.array(polished))
        return polished[int(np.argmax(values))], a

    def _suggest(self, n: int, extra_pending: Sequence[np.ndarray]) -> list[np.ndarray]:
        rng = np.random.default_rng(
            [self.seed, len(self.observations), len(self.pending) + len(extra_pending)]
        )
        joint = self.settings.batch == "joint"
        pending = [*self.pending, *extra_pending]
        fitted = self._fit(rng, [] if joint else pending)
        d = len(self.space)
        if fitted is None:  # fewer than two successes: keep exploring with random points
            return list(rng.random((n, d)))
        gp, y_best = fitted.gp, fitted.y_best
        cand = self._candidates(rng, d)
        if joint:  # pending points drawn with the evaluated ones, not believed (nei.py)
            picks: list[np.ndarray] = []
            for _ in range(n):
                B = np.array([*pending, *picks]) if pending or picks else None
                seed = np.random.default_rng(
                    [self.seed, len(gp.X_train_), len(pending) + len(picks)]
                )
                self._nei = (
                    gp,
                    NoisyEI(gp, int(seed.integers(2**31)), B, self.settings.nei_samples),
                )
                u, _ = self._best_point(gp, y_best, cand)
                picks.append(u)
            return picks
        if self.settings.batch == "believer" or n == 1:
            batch: list[np.ndarray] = []
            X, y = gp.X_train_, gp.y_train_
            for k in range(n):
                u, _ = self._best_point(gp, y_best, cand)
                batch.append(u)
                if k < n - 1:  # believe the pick at its predicted mean, then pick the next
                    believed = float(gp.predict(u[None])[0])
                    X, y = np.vstack([X, u]), np.append(y, believed)
                    gp = _conditioned(gp.kernel_, gp.alpha, X, y)
                    y_best = max(y_best, believed)  # the incumbent includes what is believed
            return batch
        acq = self._acquisition(gp, y_best, cand)
        keep = max(n, math.ceil(self.settings.top_fraction * len(cand)))
        top = np.argsort(-acq)[:keep]
        km = KMeans(n_clusters=n, n_init=4, random_state=int(rng.integers(2**31 - 1))).fit(
            cand[top]
        )
        batch = []
        for k in range(n):
            members = top[km.labels_ == k]
            u = cand[members[np.argmax(acq[members])]]
            # polish > 0: each cluster's best sample is a start of L-BFGS-B (published: 0)
            batch.append(self._polish(gp, y_best, u) if self.settings.polish else u)
        return batch


NOISE_LOW = 1e-6  # lower bound of the fitted noise variance (standardised cost)


def _conditioned(kernel: Any, alpha: Any, X: np.ndarray, y: np.ndarray) -> GaussianProcessRegressor:
    """A GP with a fixed kernel and noise conditioned on (X, y): no hyperparameter fit."""
    gp = GaussianProcessRegressor(kernel=kernel, alpha=alpha, optimizer=None)
    if np.ndim(alpha) > 0:  # sklearn stores an array alpha per training point; keep a scalar
        gp.alpha = float(np.ravel(alpha)[0])
    return gp.fit(X, y)


def _predict(gp: GaussianProcessRegressor, U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Posterior mean and sd at the rows of U, as ``gp.predict(U, return_std=True)``, with the
    fast kernel of `kernel.py` (the many one-point calls of the L-BFGS-B polish)."""
    mu, var, _ = posterior(gp, U, cross_kernel(gp, U, gp.X_train_))
    return mu, np.sqrt(np.maximum(var, 0.0))
