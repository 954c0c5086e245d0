from dataclasses import replace

import numpy as np
import pytest

from parcelfit import ParcelfitError
from parcelfit.optimize import BatchBO, BOSettings, Dimension, Space


def test_space_round_trip_linear_and_log():
    space = Space([Dimension("mu", 0.3, 0.6), Dimension("k", 1e5, 1e6, log=True)])
    p = {"mu": 0.45, "k": 10**5.5}
    u = space.to_unit(p)
    assert u == pytest.approx([0.5, 0.5])
    back = space.from_unit(u)
    assert back["mu"] == pytest.approx(0.45) and back["k"] == pytest.approx(10**5.5)
    assert space.to_unit({"mu": 9.0, "k": 1.0}).tolist() == [1.0, 0.0]
    with pytest.raises(ParcelfitError, match="log scale needs low > 0"):
        Dimension("x", 0.0, 1.0, log=True)
    with pytest.raises(ParcelfitError, match="low < high"):
        Dimension("x", 1.0, 1.0)
    with pytest.raises(ParcelfitError, match="parameters missing"):
        space.to_unit({"mu": 0.4})
    assert Space.from_bounds({"a": (0, 1), "b": {"low": 1, "high": 10, "log": True}}).dims[1].log


def test_initial_design_is_a_latin_hypercube():
    bo = BatchBO(Space.from_bounds({"a": (0, 1), "b": (0, 1), "c": (0, 1)}), batch_size=4, seed=3)
    pts = np.array([[p["a"], p["b"], p["c"]] for _ in range(4) for p in bo.ask()])
    assert pts.shape == (16, 3)
    for j in range(3):
        assert sorted(np.floor(pts[:, j] * 16).astype(int).tolist()) == list(range(16))


def _quadratic(p):
    return (p["a"] - 0.3) ** 2 + (p["b"] - 0.7) ** 2 + 0.5 * (p["c"] - 0.5) ** 2


def _run(seed, n_batches, settings=None):
    bo = BatchBO(
        Space.from_bounds({"a": (0, 1), "b": (0, 1), "c": (0, 1)}),
        batch_size=4,
        seed=seed,
        settings=settings or BOSettings(n_samples=1000, n_restarts=1),
    )
    asked = []
    for _ in range(n_batches):
        batch = bo.ask()
        asked.append(batch)
        for p in batch:
            bo.tell(p, _quadratic(p))
    return bo, asked


@pytest.mark.slow
def test_same_seed_same_batches_and_batches_are_diverse():
    _, a = _run(5, 6)
    _, b = _run(5, 6)
    assert a == b
    _, c = _run(6, 6)
    assert a != c
    last = np.array([[p["a"], p["b"], p["c"]] for p in a[-1]])
    dists = np.linalg.norm(last[:, None] - last[None], axis=2)[np.triu_indices(4, 1)]
    assert dists.min() > 1e-3


@pytest.mark.slow
def test_converges_on_a_smooth_function_and_beats_its_initial_design():
    bo, _ = _run(1, 12)
    initial_best = min(o.cost for o in bo.observations[:16])
    params, cost = bo.best()
    assert cost < 0.01 < initial_best
    assert params["a"] == pytest.approx(0.3, abs=0.1) and params["b"] == pytest.approx(0.7, abs=0.1)


def test_pending_points_are_not_asked_twice():
    bo, _ = _run(2, 5)
    first, second = bo.ask(), bo.ask()
    u1 = np.array([bo.space.to_unit(p) for p in first])
    u2 = np.array([bo.space.to_unit(p) for p in second])
    assert np.min(np.linalg.norm(u1[:, None] - u2[None], axis=2)) > 1e-3


def test_failures_are_penalised_not_fatal():
    bo = BatchBO(
        Space.from_bounds({"a": (0, 1), "b": (0, 1)}),
        batch_size=4,
        seed=0,
        settings=BOSettings(n_initial=8, n_samples=500, n_restarts=0),
    )
    for _i in range(4):
        for p in bo.ask():
            bo.tell(p, None if p["a"] > 0.8 else p["a"] + p["b"])
    assert all(o.cost is None or np.isfinite(o.cost) for o in bo.observations)
    assert any(o.cost is None for o in bo.observations)
    assert bo.best()[1] == min(o.cost for o in bo.observations if o.cost is not None)
    assert len(bo.ask()) == 4


def test_replaying_tells_gives_the_same_next_batch():
    bo, _asked = _run(9, 6)
    fresh = BatchBO(bo.space, batch_size=4, seed=9, settings=bo.settings)
    for o in bo.observations:  # as a resumed study replays its store
        fresh.tell(o.params, o.cost)
    assert fresh.ask() == bo.ask()


def test_the_order_in_which_results_arrive_does_not_change_the_next_batch():
    # parallel workers finish in any order; the next batch must depend only on what was told
    bo, _asked = _run(9, 6)
    shuffled = BatchBO(bo.space, batch_size=4, seed=9, settings=bo.settings)
    order = np.random.default_rng(1).permutation(len(bo.observations))
    assert list(order) != sorted(order)
    for i in order:
        o = bo.observations[i]
        shuffled.tell(o.params, o.cost)
    assert shuffled.ask() == bo.ask()
    assert shuffled.recommend() == bo.recommend()


def test_published_preset_is_method_section_7():
    s = BOSettings.published()
    assert (s.n_initial, s.nu, s.alpha, s.ucb_lambda, s.top_fraction) == (
        16,
        2.5,
        0.35**2,
        2.0,
        0.25,
    )
    assert (s.noise, s.transform, s.acquisition, s.polish, s.batch) == (
        "fixed",
        "none",
        "ucb",
        0,
        "kmeans",
    )
    assert (s.local_fraction, s.ard, s.recommend) == (0.0, False, "best_observed")
    assert not s.amplitude  # scikit-learn's Matern kernel alone, as the published surrogate
    bo, _ = _run(4, 6, BOSettings.published(n_samples=1000, n_restarts=0))
    assert len(bo.observations) == 24 and bo.best()[1] < min(o.cost for o in bo.observations[:16])
    with pytest.raises(ParcelfitError, match="invalid BO settings: batch 'penalty' is not one of"):
        BOSettings(batch="penalty")
    for bad in ({"noise_max": 1e-7}, {"amplitude_max": 1e-3}):  # bounds below their lower ones
        with pytest.raises(ParcelfitError, match=f"invalid BO settings: {next(iter(bad))} "):
            BOSettings(**bad)


def test_log_expected_improvement_is_accurate_far_into_the_tail():
    from scipy.stats import norm

    from parcelfit.optimize.bo import _log_h

    z = np.array([-30.0, -8.0, -6.5, -5.9, -1.0, 0.0, 2.0])
    direct = np.log(z * norm.cdf(z) + norm.pdf(z))
    finite = np.isfinite(direct) & (z > -20)
    assert _log_h(z)[finite] == pytest.approx(direct[finite], rel=1e-3)
    assert np.isfinite(_log_h(z)).all() and np.all(np.diff(_log_h(z)) > 0)


def test_fitted_noise_stays_within_its_bounds_and_small_on_a_smooth_function():
    from parcelfit.optimize.bo import NOISE_LOW

    settings = BOSettings(n_samples=500, n_restarts=0, polish=1)
    bo, _ = _run(1, 5, settings)
    gp = bo.surrogate()
    assert NOISE_LOW <= gp.alpha <= settings.noise_max == 0.35**2
    assert gp.alpha < 0.01  # a smooth quadratic: far below the published 0.35^2


def test_the_fitted_noise_keeps_to_its_upper_bound():
    rng = np.random.default_rng(3)
    noisy = [
        ({"a": a, "b": b, "c": c}, _quadratic({"a": a, "b": b, "c": c}) + rng.normal(0, 0.3))
        for a, b, c in rng.random((30, 3))
    ]
    alphas = {}
    for bound in (0.35**2, 0.01):
        bo = BatchBO(
            Space.from_bounds({"a": (0, 1), "b": (0, 1), "c": (0, 1)}),
            seed=0,
            # the marginal likelihood alone with a fitted signal variance (the former default):
            # the noise prior of `prior: dim_scaled` holds the noise below both bounds here
            settings=BOSettings(
                n_restarts=0, transform="none", noise_max=bound, prior="none", amplitude=True
            ),
        )
        for p, cost in noisy:
            bo.tell(p, cost)
        alphas[bound] = bo.surrogate().alpha
    assert alphas[0.01] <= 0.01 + 1e-12 < alphas[0.35**2]  # the noise wants more than 0.01


def test_tpe_sampler_asks_batches_and_replays_its_history():
    from parcelfit.optimize.sampler import Sampler, make_sampler

    space = Space([Dimension("a", 0, 1), Dimension("b", 1e-3, 1.0, log=True)])

    def run():
        tpe = make_sampler("tpe", space, batch_size=4, seed=2)
        for _ in range(5):
            batch = tpe.ask()
            for p in batch:
                tpe.tell(p, None if p["a"] > 0.9 else (p["a"] - 0.3) ** 2 + np.log10(p["b"]) ** 2)
        return tpe, batch

    tpe, last = run()
    assert isinstance(tpe, Sampler) and tpe.n_told == 20
    assert run()[1] == last
    assert len({tuple(p.values()) for p in last}) == 4
    fresh = make_sampler("tpe", space, batch_size=4, seed=2)
    for p, c in tpe._told:  # as a resumed study replays its store
        fresh.tell(p, c)
    assert fresh.ask() == tpe.ask()
    assert tpe.best()[1] == min(c for _, c in tpe._told if c is not None)


@pytest.mark.slow
@pytest.mark.parametrize("sampler", ["published", "tpe"])
def test_a_study_file_chooses_its_optimizer(tmp_path, sampler):
    from parcelfit.study.calibration import Calibration
    from parcelfit.study.studyfile import load_study

    from .test_calibration import write_study

    opts = {"sampler": sampler} | ({} if sampler == "tpe" else {"n_samples": 500})
    study = load_study(
        write_study(tmp_path, optimizer=opts, budget=12, initial=8, executor={"kind": "serial"})
    )
    assert study.sampler == sampler
    first = Calibration(study, tmp_path / "out", figures=False).run()
    assert first.evaluations == 12 and first.best_cost is not None
    again = Calibration(
        study, tmp_path / "out", figures=False
    ).run()  # resumed from the store: nothing new
    assert (again.evaluations, again.best_params) == (12, first.best_params)


def test_the_sampler_is_an_object_chosen_once_from_the_registry(tmp_path):
    from parcelfit.optimize.bo import BatchBO
    from parcelfit.optimize.sampler import SAMPLERS, make_sampler
    from parcelfit.study.calibration import Calibration
    from parcelfit.study.studyfile import load_study

    from .test_calibration import write_study

    assert set(SAMPLERS) == {"gp", "published", "tpe", "optuna-gp", "botorch"}
    study = load_study(write_study(tmp_path, optimizer={"sampler": "published"}))
    made = study.new_sampler()
    assert isinstance(made, BatchBO) and made.settings == study.bo
    # the same batch as the name resolved by make_sampler, from the same seed and history
    named = make_sampler("published", study.space, batch_size=4, seed=study.seed, settings=study.bo)
    assert made.ask() == named.ask()
    own = make_sampler("tpe", study.space, batch_size=4, seed=1)
    calibration = Calibration(study, tmp_path / "out", sampler=own)
    assert calibration.bo is own  # an object given replaces the study file's
    assert isinstance(Calibration(study, tmp_path / "out").bo, BatchBO)
    with pytest.raises(
        ParcelfitError, match=r"unknown optimizer 'mango'.*gp, published, tpe, optuna-gp, botorch"
    ):
        make_sampler("mango", study.space)


def test_bad_optimizer_sections_name_file_key_and_fix(tmp_path):
    from parcelfit.study.studyfile import load_study

    from .test_calibration import write_study

    with pytest.raises(ParcelfitError, match=r"optimizer.*'mango'"):
        load_study(write_study(tmp_path, optimizer={"sampler": "mango"}))
    with pytest.raises(ParcelfitError, match=r"optimizer: unknown key 'n_samples'"):
        load_study(write_study(tmp_path, optimizer={"sampler": "tpe", "n_samples": 10}))
    # a text setting's bad value: the key and the values it takes, not the whole settings
    for key, bad, choices in (
        ("transform", "sqrt", "none, log, power, auto"),
        ("acquisition", "foo", "ucb, logei, lognei"),
        ("batch", "penalty", "believer, kmeans, joint"),
        ("prior", "flat", "none, dim_scaled"),
    ):
        with pytest.raises(ParcelfitError) as err:
            load_study(write_study(tmp_path, optimizer={key: bad}))
        text = str(err.value)
        assert f"optimizer.{key}: unknown {key} value '{bad}'" in text
        assert f"use one of {choices}" in text and "BOSettings(" not in text
    # settings that do not go together: the setting named, with what it must be
    with pytest.raises(ParcelfitError) as err:
        load_study(write_study(tmp_path, optimizer={"batch": "joint", "acquisition": "logei"}))
    assert "batch 'joint' must be believer or kmeans unless acquisition is lognei" in str(err.value)
    assert "optimiser settings" in str(err.value) and "BOSettings(" not in str(err.value)
    with pytest.raises(ParcelfitError, match=r"nei_samples 100 must be a power of 2"):
        load_study(write_study(tmp_path, optimizer={"nei_samples": 100}))


def test_fast_prediction_matches_scikit_learn():
    from parcelfit.optimize.bo import _predict

    for settings in (BOSettings(n_samples=500, n_restarts=0, polish=1), BOSettings.published()):
        bo, _ = _run(3, 5, settings)
        gp = bo._fit(np.random.default_rng(0), [np.array([0.5, 0.5, 0.5])])[0]
        U = np.random.default_rng(1).random((50, 3))
        mu, sd = _predict(gp, U)
        ref_mu, ref_sd = gp.predict(U, return_std=True)
        assert mu == pytest.approx(ref_mu, abs=1e-9) and sd == pytest.approx(ref_sd, abs=1e-7)


def _fitted(cost, settings, n=24, seed=0):
    bo = BatchBO(
        Space.from_bounds({"a": (0, 1), "b": (0, 1)}), batch_size=4, seed=seed, settings=settings
    )
    for p in bo.ask(n):
        bo.tell(p, cost(p))
    return bo, bo._fit(np.random.default_rng(0), [])


def test_auto_transform_warps_a_heavy_tailed_cost_and_leaves_a_smooth_one():
    # on the fit by marginal likelihood with a signal variance (the former default): the
    # default's fixed unit signal variance and priors make the warped Box-Cox fit of the smooth
    # bowl the likelier one too (docs/research/optimizer-benchmarks.md)
    settings = BOSettings(
        transform="auto", n_initial=24, n_restarts=0, prior="none", amplitude=True
    )
    for seed in (0, 1):
        _, heavy = _fitted(lambda p: np.exp(8 * p["a"]) + np.exp(6 * p["b"]), settings, seed=seed)
        _, smooth = _fitted(
            lambda p: (p["a"] - 0.3) ** 2 + (p["b"] - 0.6) ** 2, settings, seed=seed
        )
        assert (heavy.transform, smooth.transform) == ("power", "none")


def test_auto_transform_compares_likelihoods_of_the_costs_including_the_jacobian():
    # the chosen transform's warped-GP likelihood is the higher one, computed by hand here
    def cost(p):
        return np.exp(8 * p["a"]) + p["b"]

    bo, fit = _fitted(cost, BOSettings(transform="auto", n_initial=24, n_restarts=0))
    X, c = bo._training_data()
    scores = {}
    for kind in ("none", "power"):
        z, log_jac = bo._transformed(c, kind)
        y = -(z - z.mean()) / z.std()
        gp = bo._fit_gp(X, y, 0)
        scores[kind] = gp.log_marginal_likelihood_value_ + log_jac - len(y) * np.log(z.std())
    assert fit.transform == max(scores, key=scores.get)
    # the Jacobian of log is -sum log s: check it against a numerical derivative
    z, log_jac = bo._transformed(c, "log")
    h = 1e-7
    bumped = [bo._transformed(np.r_[c[:i], c[i] + h, c[i + 1 :]], "log")[0][i] for i in (3, 7)]
    numeric = [np.log(abs((b - z[i]) / h)) for b, i in zip(bumped, (3, 7), strict=True)]
    shifted = c - c.min() + 0.01 * np.ptp(c)
    assert numeric == pytest.approx(list(-np.log(shifted[[3, 7]])), abs=1e-4)
    assert log_jac == pytest.approx(-np.log(shifted).sum())


def test_mean_incumbent_is_the_best_posterior_mean_at_an_evaluated_point():
    def cost(p):
        return (p["a"] - 0.3) ** 2 + 0.05 * np.sin(40 * p["b"])

    settings = BOSettings(incumbent="mean", n_initial=24, n_restarts=0, transform="none")
    _, fit = _fitted(cost, settings)
    assert fit.y_best == pytest.approx(float(fit.gp.predict(fit.gp.X_train_).max()), abs=1e-12)
    settings = BOSettings(incumbent="observed", n_initial=24, n_restarts=0, transform="none")
    _, observed = _fitted(cost, settings)
    assert observed.y_best == pytest.approx(float(observed.gp.y_train_.max()), abs=1e-12)


def test_published_gp_is_a_plain_matern_with_the_fixed_noise():
    from sklearn.gaussian_process.kernels import Matern

    _, fit = _fitted(_quadratic_2d, BOSettings.published(n_restarts=0))
    assert isinstance(fit.gp.kernel_, Matern) and fit.gp.kernel_.nu == 2.5
    assert np.ndim(fit.gp.kernel_.length_scale) == 0  # one shared length scale
    assert fit.gp.alpha == pytest.approx(0.35**2) and fit.transform == "none"


def _quadratic_2d(p):
    return (p["a"] - 0.3) ** 2 + (p["b"] - 0.7) ** 2


def test_polish_moves_kmeans_picks_uphill_on_the_acquisition():
    base = BOSettings.published(n_samples=300, n_restarts=0)
    rough, _ = _run(4, 5, base)
    polished, _ = _run(4, 5, BOSettings.published(n_samples=300, n_restarts=0, polish=1))
    u0 = np.array([rough.space.to_unit(p) for p in rough.ask()])
    u1 = np.array([polished.space.to_unit(p) for p in polished.ask()])
    assert not np.allclose(u0, u1)  # polish acts on the k-means batch too
    fit = polished._fit(np.random.default_rng(0), [])
    start = np.array([rough.space.to_unit(p) for p in rough.ask()])
    after = np.array([polished._polish(fit.gp, fit.y_best, u) for u in start])
    a0 = polished._acquisition(fit.gp, fit.y_best, start)
    a1 = polished._acquisition(fit.gp, fit.y_best, after)
    assert np.all(a1 >= a0)


# the GP fit these tests of noisy EI's arithmetic were built on (the former default): maximum
# marginal likelihood with a fitted signal variance; the default's noise prior keeps the fitted
# noise of a noise-free cost near 0.0066 instead of 1e-6 (docs/research/optimizer-benchmarks.md)
_MARGINAL_LIKELIHOOD = {"prior": "none", "amplitude": True}


def _noisy_cost(p):
    # a bowl with noise seeded by the point: what the parcel cost's run-to-run scatter looks like
    rng = np.random.default_rng(abs(hash((round(p["a"], 12), round(p["b"], 12)))) % 2**32)
    return (p["a"] - 0.3) ** 2 + (p["b"] - 0.7) ** 2 + float(rng.normal(0, 0.03))


def test_noisy_ei_is_the_monte_carlo_mean_of_the_improvement_over_the_drawn_incumbent():
    from parcelfit.optimize.nei import NoisyEI

    settings = BOSettings(acquisition="lognei", n_initial=24, n_restarts=0, transform="none")
    settings = replace(settings, **_MARGINAL_LIKELIHOOD)
    _, fit = _fitted(_noisy_cost, settings)
    gp = fit.gp
    assert gp.alpha > 1e-4  # the noise was fitted, so the incumbent is uncertain
    U = np.array([[0.3, 0.7], [0.5, 0.5], [0.9, 0.1]])
    nei = NoisyEI(gp, seed=3)
    # brute force: joint draws of the latent function at every evaluated point and at U
    X = gp.X_train_
    draws = gp.sample_y(np.vstack([X, U]), n_samples=40000, random_state=1)
    best = draws[: len(X)].max(axis=0)
    brute = np.maximum(draws[len(X) :] - best[None, :], 0.0).mean(axis=1)
    assert np.exp(nei(U)) == pytest.approx(brute, rel=0.08, abs=1e-4)
    assert np.array_equal(nei(U), NoisyEI(gp, seed=3)(U))  # the draws are seeded
    # near the evaluated points and anywhere, wherever the improvement is not negligible
    rng = np.random.default_rng(5)
    V = np.vstack([X + 0.02 * rng.standard_normal(X.shape), rng.random((200, 2))]).clip(0, 1)
    draws = gp.sample_y(np.vstack([X, V]), n_samples=40000, random_state=2)
    brute = np.maximum(draws[len(X) :] - draws[: len(X)].max(axis=0)[None, :], 0.0).mean(axis=1)
    big = brute > 1e-3
    assert big.sum() >= 10
    assert np.exp(nei(V[big])) == pytest.approx(brute[big], rel=0.25)  # 128 draws: +-20 %
    # at a baseline point the latent value never beats its own draw's incumbent: NEI ~ 0 there
    assert np.exp(nei(nei.P)).max() < 1e-2 * np.exp(nei(V)).max()


def test_noisy_ei_with_pending_points_is_the_monte_carlo_gain_of_the_whole_batch():
    from parcelfit.optimize.nei import NoisyEI

    settings = BOSettings(acquisition="lognei", n_initial=24, n_restarts=0, transform="none")
    settings = replace(settings, **_MARGINAL_LIKELIHOOD)
    _, fit = _fitted(_noisy_cost, settings)
    gp = fit.gp
    X = gp.X_train_
    B = np.array([[0.32, 0.68], [0.6, 0.4]])  # chosen earlier in the batch, not yet observed
    U = np.array([[0.3, 0.7], [0.5, 0.5], [0.9, 0.1], [0.33, 0.67]])
    nei = NoisyEI(gp, seed=3, pending=B)
    # brute force: the batch's gain E[max(f(x), f_B, y*) - y*] over joint draws at X, B and U,
    # less B's own gain E[max(f_B, y*) - y*]
    draws = gp.sample_y(np.vstack([X, B, U]), n_samples=40000, random_state=1)
    best = draws[: len(X)].max(axis=0)
    batch = np.maximum(draws[len(X) : len(X) + 2].max(axis=0), best)
    brute = (np.maximum(draws[len(X) + 2 :], batch[None, :]) - best[None, :]).mean(axis=1)
    # the acquisition is what x adds to B's own gain, which does not depend on x
    added = np.exp(nei(U))
    brute_added = brute - (batch - best).mean()
    assert brute_added[[0, 3]].min() > 5e-4 and brute_added[[1, 2]].max() < 1e-4
    assert added[[0, 3]] == pytest.approx(brute_added[[0, 3]], rel=0.25)  # 128 draws
    assert np.abs(added[[1, 2]]).max() < 1e-4
    # next to a point of B a candidate adds a ninth of what it would alone
    alone = np.exp(NoisyEI(gp, seed=3)(U))
    assert alone[3] == alone.max() and added[3] < 0.2 * alone[3]
    assert np.array_equal(nei(U), NoisyEI(gp, seed=3, pending=B)(U))  # seeded


def test_a_joint_batch_needs_noisy_ei_and_draws_a_power_of_two():
    with pytest.raises(ParcelfitError, match="invalid BO settings"):
        BOSettings(acquisition="logei", batch="joint")
    with pytest.raises(ParcelfitError, match="invalid BO settings"):
        BOSettings(nei_samples=100)  # Sobol draws: a power of 2


def test_more_noisy_ei_draws_come_closer_to_the_exact_expectation():
    from parcelfit.optimize.nei import NoisyEI

    settings = BOSettings(acquisition="lognei", n_initial=24, n_restarts=0, transform="none")
    settings = replace(settings, **_MARGINAL_LIKELIHOOD)
    _, fit = _fitted(_noisy_cost, settings)
    gp = fit.gp
    U = np.random.default_rng(4).random((300, 2))
    exact = NoisyEI(gp, seed=0, n_samples=8192)(U)  # log NEI
    big = exact > exact.max() - np.log(1000.0)  # where the improvement is not negligible
    assert big.sum() >= 20
    errors = []
    for n in (32, 512):
        err = [
            np.median(np.abs(NoisyEI(gp, seed=s, n_samples=n)(U[big]) - exact[big])) for s in (1, 2)
        ]
        errors.append(np.mean(err))
    assert errors[1] < 0.3 * errors[0] and errors[1] < 0.03  # measured 0.10 and 0.016


def test_noisy_ei_becomes_ei_over_the_best_observation_when_there_is_no_noise():
    from parcelfit.optimize.nei import NoisyEI, log_h

    settings = BOSettings(
        acquisition="lognei", n_initial=8, n_restarts=0, transform="none", **_MARGINAL_LIKELIHOOD
    )
    _, fit = _fitted(_quadratic_2d, settings, n=8)
    gp = fit.gp
    assert gp.alpha < 1e-4
    U = np.random.default_rng(0).random((50, 2))
    mu, sd = gp.predict(U, return_std=True)
    log_ei = np.log(sd) + log_h((mu - gp.y_train_.max()) / sd)
    close = log_ei > np.log(1e-4)  # where the improvement is not negligible
    assert close.sum() > 10
    assert NoisyEI(gp, seed=0)(U)[close] == pytest.approx(log_ei[close], abs=0.05)


@pytest.mark.parametrize("batch", ["believer", "joint"])
def test_a_lognei_study_asks_distinct_points_and_replays_exactly(batch):
    settings = BOSettings(acquisition="lognei", n_samples=500, n_restarts=0, polish=1, batch=batch)
    bo, asked = _run(2, 6, settings)
    _, asked_again = _run(2, 6, settings)
    assert asked == asked_again
    last = np.array([[p["a"], p["b"], p["c"]] for p in asked[-1]])
    assert min(np.linalg.norm(last[i] - last[j]) for i in range(4) for j in range(i)) > 1e-3
    assert bo.best()[1] < min(o.cost for o in bo.observations[:16])
