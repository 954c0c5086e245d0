import itertools

import numpy as np
import pandas as pd
import pytest
from statsmodels.formula.api import ols

from parcelfit import ParcelfitError
from parcelfit.doe import (
    analyse_effects,
    decode,
    fractional_factorial,
    full_factorial,
    latin_hypercube,
    lenth,
    pareto_chart,
    select_parameters,
)
from parcelfit.figures import save_figure


def test_full_factorial_is_balanced_and_orthogonal():
    d = full_factorial(4)
    assert d.matrix.shape == (16, 4) and d.resolution is None
    assert len({tuple(r) for r in d.matrix}) == 16
    assert np.array_equal(d.matrix.T @ d.matrix, 16 * np.eye(4))


def test_published_16_factor_resolution_iv_design_and_its_aliases():
    d = fractional_factorial(16, resolution=4)
    assert d.matrix.shape == (32, 16)
    assert d.resolution == 4 and len(d.words) == 2**11 - 1
    # every generator column is the product its word says, and all columns are orthogonal
    for letter, word in d.generators.items():
        j = d.letters.index(letter)
        assert np.array_equal(
            d.matrix[:, j], np.prod([d.matrix[:, d.letters.index(c)] for c in word], axis=0)
        )
    assert np.array_equal(d.matrix.T @ d.matrix, 32 * np.eye(16))
    # resolution IV: no main effect aliased with a main effect or a two-factor interaction
    for a in d.letters:
        assert all(len(alias) >= 3 for alias in d.aliases(a))
    # ... and two-factor interactions are aliased with each other (checked against the columns)
    for alias in d.aliases("AB"):
        if len(alias) == 2:
            prod = lambda t: np.prod([d.matrix[:, d.letters.index(c)] for c in t], axis=0)  # noqa: E731
            assert np.array_equal(prod("AB"), prod(alias))
    assert d.defining_relation().startswith("I = ABCF")


@pytest.mark.parametrize(
    ("k", "res", "runs"), [(5, 3, 8), (7, 4, 16), (8, 4, 16), (6, 5, 32), (8, 5, 64)]
)
def test_other_fractions_reach_their_resolution(k, res, runs):
    d = fractional_factorial(k, res)
    assert d.matrix.shape == (runs, k) and d.resolution >= res
    assert np.array_equal(d.matrix.T @ d.matrix, runs * np.eye(k))


def _y(design, rng, noise=0.2):
    x = design.matrix
    return 10 + 3 * x[:, 0] - 2 * x[:, 1] + 1.5 * x[:, 0] * x[:, 1] + rng.normal(0, noise, len(x))


def test_effects_match_statsmodels_formula_and_recover_the_true_terms():
    d = full_factorial(4)
    y = _y(d, np.random.default_rng(3))
    a = analyse_effects(d, ["A", "B", "C", "D"], y)
    assert a.method == "pooled"
    frame = pd.DataFrame({c: d.matrix[:, i] for i, c in enumerate("ABCD")} | {"y": y})
    ref = ols("y ~ (A + B + C + D) ** 2", data=frame).fit()
    row = a.table.set_index("term")
    assert row.loc["A", "effect"] == pytest.approx(2 * ref.params["A"])
    assert row.loc["A:B", "p_value"] == pytest.approx(ref.pvalues["A:B"])
    assert set(a.table.loc[a.table.significant, "term"]) == {"A", "B", "A:B"}


def test_false_positive_rate_is_about_alpha_and_power_is_full():
    d = full_factorial(4)
    rng = np.random.default_rng(0)
    hits = {"true": 0, "null": 0}
    n_null = 10 - 3
    for _ in range(200):
        tab = analyse_effects(d, ["A", "B", "C", "D"], _y(d, rng)).table
        sig = set(tab.loc[tab.significant, "term"])
        hits["true"] += len(sig & {"A", "B", "A:B"})
        hits["null"] += len(sig - {"A", "B", "A:B"})
    assert hits["true"] == 600
    assert 0.02 < hits["null"] / (200 * n_null) < 0.08


def test_lenth_by_hand_and_on_a_saturated_fraction():
    c = np.array([10.0, -8.0, 0.5, -0.3, 0.2, 0.1, -0.4])
    s0 = 1.5 * np.median(np.abs(c))  # 0.6
    pse = 1.5 * np.median([v for v in np.abs(c) if v < 2.5 * s0])
    assert lenth(c) == pytest.approx((pse, 7 / 3))
    d = fractional_factorial(7, 4)
    rng = np.random.default_rng(1)
    y = 2 * d.matrix[:, 0] - 1.5 * d.matrix[:, 3] + rng.normal(0, 0.05, 16)
    a = analyse_effects(d, list("ABCDEFG"), y, method="lenth")
    assert set(a.table.loc[a.table.significant, "term"]) == {"A", "D"}
    assert a.table.set_index("term").loc["A", "effect"] == pytest.approx(4, abs=0.1)


def test_selection_and_pareto_chart(tmp_path):
    d = full_factorial(4)
    a = analyse_effects(
        d, ["mu_B", "mu_M", "E", "k"], _y(d, np.random.default_rng(3)), name="DTW_xy"
    )
    sel = select_parameters([a], max_parameters=1)
    assert sel.parameters == ["mu_B"] and "main effect on DTW_xy" in sel.reasons["mu_B"]
    assert select_parameters([a]).parameters == ["mu_B", "mu_M"]
    inert = analyse_effects(
        d, ["mu_B", "mu_M", "E", "k"], np.where(d.matrix[:, 0] > 0, 2.0, 1.0), name="step"
    )
    assert select_parameters([inert], only_significant=False).parameters == [
        "mu_B"
    ]  # the others do nothing
    paths = save_figure(pareto_chart(a), tmp_path / "pareto")
    assert all(p.stat().st_size > 1000 for p in paths)


def test_bad_input_and_helpers():
    with pytest.raises(ParcelfitError, match="missing values"):
        analyse_effects(full_factorial(2), ["a", "b"], np.array([1.0, np.nan, 2.0, 3.0]))
    with pytest.raises(ParcelfitError, match="resolution must be 3, 4 or 5"):
        fractional_factorial(8, 6)
    decoded = decode(np.array([[-1, 1], [0, 0]]), [(0.3, 0.6), (100, 1000)])
    assert decoded == pytest.approx(np.array([[0.3, 1000], [0.45, 550]]))
    lhs = latin_hypercube(8, 3, seed=2)
    assert lhs.shape == (8, 3) and np.all(np.abs(lhs) <= 1)
    for j in range(3):
        assert sorted(np.floor((lhs[:, j] + 1) / 2 * 8).astype(int)) == list(range(8))
    assert list(itertools.islice(full_factorial(3).matrix[:, 0], 4)) == [-1, 1, -1, 1]


def test_centre_points_leave_effects_unchanged_and_join_the_fit():
    from parcelfit.doe import with_centre_points

    d = full_factorial(3)
    y = 5 + 2 * d.matrix[:, 0] + np.random.default_rng(2).normal(0, 0.1, 8)
    assert (
        with_centre_points(d.matrix, 3).shape == (11, 3)
        and not with_centre_points(d.matrix, 3)[8:].any()
    )
    plain = analyse_effects(d, ["a", "b", "c"], y, interactions=False)
    with_c = analyse_effects(
        d, ["a", "b", "c"], y, interactions=False, centre=np.array([5.0, 5.1, 4.9])
    )
    assert with_c.table.set_index("term").loc["a", "effect"] == pytest.approx(
        plain.table.set_index("term").loc["a", "effect"]
    )
    assert (
        with_c.table.set_index("term").loc["a", "p_value"]
        != plain.table.set_index("term").loc["a", "p_value"]
    )
