"""Maximum a posteriori GP hyperparameters (`parcelfit.optimize.prior`, `prior: dim_scaled`)."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

from parcelfit.errors import ParcelfitError
from parcelfit.optimize.bo import BatchBO, BOSettings
from parcelfit.optimize.prior import (
    MapOptimizer,
    length_scale_prior,
    neg_log_prior,
    prior_terms,
)


def _kernel(d: int):
    return ConstantKernel(1.0, (1e-2, 1e2)) * Matern(
        np.full(d, 0.3), (1e-2, 1e2), nu=2.5
    ) + WhiteKernel(0.01, (1e-6, 0.35**2))


def test_prior_terms_cover_length_scales_and_noise_only():
    has, mu, s = prior_terms(_kernel(3), 3)
    # theta: log amplitude, three log length scales, log noise
    assert has.tolist() == [False, True, True, True, True]
    m, sd = length_scale_prior(3)
    assert m == pytest.approx(math.sqrt(2) + 0.5 * math.log(3))
    assert sd == pytest.approx(math.sqrt(3))
    np.testing.assert_allclose(mu[1:4], m)
    assert (mu[4], s[4]) == (-4.0, 1.0)


def test_neg_log_prior_is_the_lognormal_density_and_its_gradient():
    from scipy.stats import lognorm

    has, mu, s = prior_terms(_kernel(2), 2)
    theta = np.array([0.3, -1.0, 0.5, -3.0])
    value, grad = neg_log_prior(theta, has, mu, s)
    # -log of the log-normal densities of the values, up to a constant
    exact = -sum(
        lognorm.logpdf(math.exp(t), s=sd, scale=math.exp(m))
        for t, m, sd, on in zip(theta, mu, s, has, strict=True)
        if on
    )
    const = sum(
        0.5 * math.log(2 * math.pi) + math.log(sd) for sd, on in zip(s, has, strict=True) if on
    )
    assert value + const == pytest.approx(exact, rel=1e-12)
    eps = 1e-6
    for i in range(len(theta)):
        step = np.zeros_like(theta)
        step[i] = eps
        fd = (neg_log_prior(theta + step, has, mu, s)[0] - value) / eps
        assert grad[i] == pytest.approx(fd, abs=1e-5)
    assert grad[0] == 0.0  # no prior on the signal variance


def _data(n: int, d: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    X = rng.random((n, d))
    y = np.sin(6 * X[:, 0]) + 0.1 * rng.standard_normal(n)
    return X, (y - y.mean()) / y.std()


def test_map_fit_maximises_the_posterior_not_the_likelihood():
    X, y = _data(12, 4)
    ml = GaussianProcessRegressor(_kernel(4), random_state=0).fit(X, y)
    opt = MapOptimizer(_kernel(4), 4)
    mp = GaussianProcessRegressor(_kernel(4), optimizer=opt, random_state=0).fit(X, y)

    def log_posterior(gp):
        theta = gp.kernel_.theta
        return gp.log_marginal_likelihood(theta) - neg_log_prior(theta, opt.has, opt.mu, opt.s)[0]

    # each fit is best by its own objective
    assert log_posterior(mp) >= log_posterior(ml) - 1e-6
    assert ml.log_marginal_likelihood_value_ >= mp.log_marginal_likelihood_value_ - 1e-6
    # the inputs the data do not use: the likelihood alone sends a length scale to its bound
    # and the noise to zero; the prior keeps them within a few of its scales of its mode
    assert ml.kernel_.k1.k2.length_scale.max() == pytest.approx(100.0)
    ls = mp.kernel_.k1.k2.length_scale
    assert np.all(ls[1:] > 0.4) and np.all(ls < 20.0)
    assert ml.kernel_.k2.noise_level < 1e-5 < 1e-3 < mp.kernel_.k2.noise_level
    pickle.loads(pickle.dumps(mp))  # the optimizer is a class, the fitted GP stays picklable


def test_bo_with_prior_runs_and_is_deterministic():
    def run():
        bo = BatchBO(
            {"a": (0.0, 1.0), "b": (0.0, 1.0)},
            batch_size=2,
            seed=3,
            settings=BOSettings(prior="dim_scaled", n_initial=6),
        )
        for _ in range(5):
            for p in bo.ask():
                bo.tell(p, (p["a"] - 0.3) ** 2 + (p["b"] - 0.7) ** 2)
        return bo.recommend()

    first, second = run(), run()
    assert first == second
    params, _ = first
    assert abs(params["a"] - 0.3) < 0.15 and abs(params["b"] - 0.7) < 0.15


def test_unknown_prior_is_refused():
    with pytest.raises(ParcelfitError):
        BOSettings(prior="gamma")
