"""Maximum a posteriori GP hyperparameters with BoTorch's dimension-scaled priors.

`BOSettings(prior="dim_scaled")` fits the GP's hyperparameters theta (natural logs of the
signal variance, the length scales l_1..l_d and the noise variance sigma_n^2, scikit-learn's
``kernel.theta``) by maximising

    log p(y | theta) + sum_j log p(l_j) + log p(sigma_n^2)

instead of log p(y | theta) alone, with the priors BoTorch's ``SingleTaskGP`` uses since 0.12
(Hvarfner, Hellsten and Nardi 2024, "Vanilla Bayesian optimization performs great in high
dimensions"; ``botorch.models.utils.gpytorch_modules``), as densities of the values themselves:

    l_j        ~ LogNormal(mu_l = sqrt(2) + log(d) / 2, s_l^2 = 3)   (inputs in [0, 1]^d)
    sigma_n^2  ~ LogNormal(mu_n = -4, s_n^2 = 1)                      (standardised outputs)
    -log p(v)  = (log v - mu)^2 / (2 s^2) + log v + const,
    d(-log p) / d(log v) = (log v - mu) / s^2 + 1.

The length-scale prior's mode exp(mu_l - s_l^2) = 0.21 sqrt(d) grows with the dimension, so the
GP does not explain a few points by wiggles in every input. The signal variance has no prior:
the default has none (`amplitude: false`, as BoTorch, whose is fixed at 1), and with
`amplitude: true` it is fitted within its bounds by the likelihood alone.

Written by hand because scikit-learn's GP has no hyperparameter priors; its ``optimizer``
argument takes a callable, through which this adds the log prior and its gradient to the
objective it minimises (the negative log marginal likelihood and its gradient in theta).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.optimize import minimize
from sklearn.gaussian_process.kernels import Kernel

NOISE_PRIOR = (-4.0, 1.0)  # (mu, s) of log sigma_n^2


def length_scale_prior(d: int) -> tuple[float, float]:
    """(mu, s) of the normal prior of log l_j for ``d`` inputs in the unit cube."""
    return math.sqrt(2.0) + 0.5 * math.log(d), math.sqrt(3.0)


def prior_terms(kernel: Kernel, d: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per entry of ``kernel.theta``: whether it has a prior, and the prior's mu and s."""
    has, mu, s = [], [], []
    for h in kernel.hyperparameters:
        if h.fixed:
            continue
        prior = (
            length_scale_prior(d)
            if h.name.endswith("length_scale")
            else NOISE_PRIOR
            if h.name.endswith("noise_level")
            else None
        )
        m, sd = prior or (0.0, 1.0)  # placeholders where there is no prior (has: False)
        has += [prior is not None] * h.n_elements
        mu += [m] * h.n_elements
        s += [sd] * h.n_elements
    return np.array(has), np.array(mu), np.array(s)


def neg_log_prior(
    theta: np.ndarray, has: np.ndarray, mu: np.ndarray, s: np.ndarray
) -> tuple[float, np.ndarray]:
    """-log p of the log-normal priors at ``theta`` (natural logs of the values), up to a
    constant, and its gradient in theta."""
    z = (theta - mu) / s
    value = float(np.sum(np.where(has, 0.5 * z**2 + theta, 0.0)))
    grad = np.where(has, z / s + 1.0, 0.0)
    return value, grad


class MapOptimizer:
    """scikit-learn GP ``optimizer`` callable: L-BFGS-B on the negative log posterior of theta
    (negative log marginal likelihood plus ``neg_log_prior``), as its default optimizer runs on
    the likelihood alone; a class, not a closure, so a fitted GP stays picklable."""

    def __init__(self, kernel: Kernel, d: int) -> None:
        self.has, self.mu, self.s = prior_terms(kernel, d)

    def __call__(
        self,
        obj_func: Callable[..., tuple[float, np.ndarray]],
        initial_theta: np.ndarray,
        bounds: np.ndarray,
    ) -> tuple[np.ndarray, float]:
        def posterior(theta: np.ndarray) -> tuple[float, np.ndarray]:
            nll, grad = obj_func(theta, eval_gradient=True)
            prior, prior_grad = neg_log_prior(theta, self.has, self.mu, self.s)
            return nll + prior, grad + prior_grad

        res = minimize(posterior, initial_theta, method="L-BFGS-B", jac=True, bounds=bounds)
        return res.x, float(res.fun)
