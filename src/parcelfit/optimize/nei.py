"""Noisy expected improvement (log NEI) for `BatchBO` (``acquisition: lognei``).

Expected improvement needs an incumbent y*, the best value of the latent function so far. With
noisy observations y* is not known: the best observed y is inflated by the noise, and the
highest posterior mean at an evaluated point (the default's ``incumbent: mean``) ignores that
the incumbent itself is uncertain. Noisy EI (Letham, Karrer, Ottoni, Bakshy 2019, "Constrained
Bayesian optimization with noisy experiments"; BoTorch's qNoisyExpectedImprovement) integrates
expected improvement over the joint posterior of the latent function at the evaluated points
P and the candidate x:

    NEI(x) = E_{f_P} [ EI(x | f_P) ],   EI(x | f_P) = s h((m - y*) / s),  y* = max_i f_P,i

where, given a draw f_P of the latent function at P, f(x) is normal with

    m = mu(x) + S_xP S_PP^-1 (f_P - mu_P),   s^2 = sigma^2(x) - S_xP S_PP^-1 S_Px,

mu and S the GP's posterior mean and covariance, and h(z) = z Phi(z) + phi(z). The expectation
is a sample average over ``N_SAMPLES`` (or ``n_samples``) scrambled-Sobol normal draws z_s of f_P = mu_P + C z_s
(C C^T = S_PP, C lower triangular), fixed for one fitted GP so that the acquisition is a smooth
deterministic function of x (sample average approximation). With C^-1 (f_P - mu_P) = z_s and
W = (C^-1 S_Px)^T, the conditional mean is m_s = mu(x) + W z_s and s^2 = sigma^2(x) - |W|^2, so
one triangular solve per candidate serves all draws. The log is taken stably:
log NEI = logsumexp_s(log s + log h(z_s)) - log N, with the tail-stable `log_h` below (also the
default's log EI).

P is pruned as BoTorch prunes its baseline: draws of the latent function at all evaluated
points are taken first, and P keeps the points that are the maximum in at least one draw (at
most ``MAX_BASELINE``, the most frequent first). The per-draw incumbent stays the maximum over
all evaluated points; f(x) is conditioned on the draw at P only. When P holds every winner
(unless more than ``MAX_BASELINE`` points win a draw) the incumbent depends on f_P alone, so the
estimate is unbiased, though not equal draw by draw to conditioning on every point.

Pending points (``batch: joint``). A batch is chosen one point at a time; the points B already
chosen (this batch's, and those asked before but not yet told) are not observed, so their
latent values are drawn jointly with the evaluated points' from the same posterior (no
believed values enter the GP). With b_s = max_j f_B,j and y*_s the draw's incumbent, the
candidate adds to the batch what it improves beyond both:

    qNEI(x | B) = E_s [ (b_s - y*_s)^+ ] + E_s [ EI(x | f_{P u B}; max(y*_s, b_s)) ],

the value of the batch B u {x} (max(f(x), b, y*) - y*) averaged over the draws, as BoTorch's
qNoisyExpectedImprovement is with pending points, with the expectation over f(x) in closed
form. The first term does not depend on x (the same draws for every candidate), so the
acquisition is the second alone: what x adds to the batch. Kept, the constant would flatten
log qNEI wherever x adds little, and the L-BFGS-B polish would stop at its first step. f(x) is
conditioned on the draws at P and at every point of B (B is never pruned), so a candidate near
a point of B gains little where that point's draw is already high.

Written here rather than taken from BoTorch because the default sampler's GP is scikit-learn's
(the `botorch` sampler uses BoTorch's own qLogNEI with its own GP); the posterior covariances are
formed from the fitted scikit-learn GP's kernel and Cholesky factor.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from scipy.linalg import cholesky, solve_triangular
from scipy.special import erfcx, ndtr, ndtri
from scipy.stats import qmc
from sklearn.gaussian_process import GaussianProcessRegressor

from parcelfit.optimize.kernel import cross_kernel, posterior, prior_variance

N_SAMPLES = 128  # draws of the latent function at the baseline (a power of 2 for Sobol)
MAX_BASELINE = 32  # evaluated points kept as the baseline after pruning
JITTER = 1e-9  # added to the baseline covariance's diagonal, relative to the signal variance
SQRT_2PI = math.sqrt(2.0 * math.pi)


def log_h(z: np.ndarray) -> np.ndarray:
    """log(z Phi(z) + phi(z)), the log of expected improvement over sigma, stable for z << 0.

    Written here because SciPy has log Phi (log_ndtr) but not this function. For z < -1,
    with Phi(z) = erfc(|z| / sqrt 2) / 2 = exp(-z^2 / 2) erfcx(|z| / sqrt 2) / 2,
    h(z) = phi(z) (1 - |z| sqrt(pi / 2) erfcx(|z| / sqrt 2)), so
    log h(z) = log phi(z) + log1mexp(log |z| + log erfcx(|z| / sqrt 2) + log(pi / 2) / 2), where
    log1mexp(a) = log(1 - e^a) for a < 0 (BoTorch's form): accurate and smooth across its range
    (an asymptotic series below z = -6 used before was 1 % off at the switch, and jumped there).
    """
    z = np.asarray(z, dtype=float)
    out = np.empty_like(z)
    far = z < -1.0
    zn = z[~far]
    out[~far] = np.log(zn * ndtr(zn) + np.exp(-0.5 * zn**2) / SQRT_2PI)
    a = -z[far]
    inner = np.log(a) + np.log(erfcx(a / math.sqrt(2.0))) + 0.5 * math.log(math.pi / 2.0)
    log1mexp = np.where(inner > -math.log(2.0), np.log(-np.expm1(inner)), np.log1p(-np.exp(inner)))
    out[far] = -0.5 * a**2 - math.log(SQRT_2PI) + log1mexp
    return out


class NoisyEI:
    """log NEI of one fitted GP (predicting the standardised negative cost), at any points.

    ``seed`` fixes the draws; built once per fitted GP and evaluated many times (the Monte Carlo
    candidates and the L-BFGS-B polish)."""

    def __init__(
        self,
        gp: GaussianProcessRegressor,
        seed: int,
        pending: np.ndarray | None = None,
        n_samples: int = N_SAMPLES,
    ) -> None:
        self.gp = gp
        X = np.asarray(gp.X_train_)
        n = len(X)
        B = np.empty((0, X.shape[1])) if pending is None else np.asarray(pending, dtype=float)
        scale = float(prior_variance(gp, X[:1])[0]) or 1.0
        # the posterior covariance at the evaluated and pending points, k(Z, Z) - V^T V with
        # Z = [X; B] and V = L^-1 k(X, Z)
        Z = np.vstack([X, B])
        K_XZ = cross_kernel(gp, X, Z)
        V_Z = solve_triangular(gp.L_, K_XZ, lower=True, check_finite=False)
        cov_all = cross_kernel(gp, Z, Z) - V_Z.T @ V_Z
        draws_all = _normal_draws(len(Z), seed, n_samples)
        chol_all, jitter = _cholesky(cov_all, JITTER * scale)
        mu_all = gp.predict(Z)
        f_all = mu_all[None, :] + draws_all @ chol_all.T  # (S, n + |B|) latent draws
        winners, counts = np.unique(np.argmax(f_all[:, :n], axis=1), return_counts=True)
        keep = winners[np.argsort(-counts, kind="stable")][:MAX_BASELINE]
        keep = np.concatenate([np.sort(keep), np.arange(n, len(Z))])  # B is never pruned
        self.P = Z[keep]
        # the baseline's block with the jitter the draws were made with: C C^T is then exactly
        # the covariance of the draws f_P, so that z_s below is standard normal
        self.chol, _ = _cholesky(cov_all[np.ix_(keep, keep)], jitter)
        # z_s = C^-1 (f_P - mu_P) for the baseline's own draws (a sub-vector of the joint draws)
        self.z = solve_triangular(
            self.chol, (f_all[:, keep] - mu_all[keep]).T, lower=True, check_finite=False
        )  # (|P|, S)
        # (S,) each draw's incumbent: the best of the evaluated points and of B
        self.best = f_all.max(axis=1)
        self._L_cross = solve_triangular(
            gp.L_, cross_kernel(gp, X, self.P), lower=True, check_finite=False
        )  # L^-1 k(X, P), for the posterior cross-covariance
        self._XP = np.vstack([X, self.P])

    def __call__(self, U: np.ndarray) -> np.ndarray:
        """log NEI at the rows of U (unit cube); higher is better."""
        gp = self.gp
        X = gp.X_train_
        K = cross_kernel(gp, U, self._XP)  # k(U, X) and k(U, P) in one call
        K_UX, K_UP = K[:, : len(X)], K[:, len(X) :]
        mu, var, V = posterior(gp, U, K_UX)  # V: (n, m)
        cross = K_UP - V.T @ self._L_cross  # S_UP, (m, |P|)
        W = solve_triangular(self.chol, cross.T, lower=True, check_finite=False).T  # (m, |P|)
        cond_var = np.maximum(var - np.einsum("ij,ij->i", W, W), 1e-24)
        s = np.sqrt(cond_var)[:, None]
        m = mu[:, None] + W @ self.z  # (m, S) conditional means
        log_ei = np.log(s) + log_h((m - self.best[None, :]) / s)
        # log mean exp over the draws, by hand: scipy's logsumexp costs more in its argument
        # checks than the sum itself on the polish's one-point calls
        top = log_ei.max(axis=1)
        return top + np.log(np.exp(log_ei - top[:, None]).mean(axis=1))


def _normal_draws(dim: int, seed: int, n: int = N_SAMPLES) -> np.ndarray:
    """``n`` x ``dim`` standard normal draws by scrambled Sobol points (seeded)."""
    sobol = qmc.Sobol(d=dim, scramble=True, seed=np.random.default_rng([seed, 0x4E1]))
    u = sobol.random(n)
    return ndtri(np.clip(u, 1e-10, 1 - 1e-10))


def _cholesky(cov: np.ndarray, jitter: float) -> tuple[np.ndarray, float]:
    """The lower Cholesky factor of ``cov`` + j I and the j used: ``jitter``, raised tenfold
    until the factorisation works (posterior covariances at nearby evaluated points are near
    singular); after eight tries the diagonal alone, with a warning."""
    eye = np.eye(len(cov))
    for k in range(8):
        j = jitter * 10**k
        try:
            return cholesky(cov + j * eye, lower=True, check_finite=False), j
        except np.linalg.LinAlgError:
            continue
    warnings.warn(
        "noisy EI: the posterior covariance at the evaluated points would not factorise; "
        "its correlations are dropped",
        RuntimeWarning,
        stacklevel=2,
    )
    return np.diag(np.sqrt(np.maximum(np.diag(cov), 0.0) + j)), j
