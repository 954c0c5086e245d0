from math import comb

import numpy as np
import pytest

from parcelfit import ParcelfitError
from parcelfit.analysis import transit_statistics
from parcelfit.runs import load_dataset
from parcelfit.stats import compare_transit_times, significance_stars

from .conftest import line_trajectory

A = [1.0 + 0.1 * i for i in range(10)]
B = [a + 2.0 for a in A]  # completely above A
C = [a + 0.05 for a in A]  # interleaved with A


def _dataset(make_dataset, families=(("E1", 1),)):
    cases = {}
    for rig, setting in families:
        for name, times in (("A", A), ("B", B), ("C", C)):
            cases[(rig, name, setting)] = [
                (f"{rig}-{name}-{setting}-{i}", line_trajectory(5), t) for i, t in enumerate(times)
            ]
    return load_dataset(make_dataset(cases))


def test_mann_whitney_and_bh_by_hand(make_dataset):
    table = compare_transit_times(_dataset(make_dataset))
    ab = table[(table.type_a == "A") & (table.type_b == "B")].iloc[0]
    # complete separation, n = m = 10: U = 0, exact two-sided p = 2 / C(20, 10)
    assert ab.u_statistic == 0
    assert ab.method == "exact"
    assert ab.p_value == pytest.approx(2 / comb(20, 10), rel=1e-9)
    ac = table[(table.type_a == "A") & (table.type_b == "C")].iloc[0]
    # C_i = A_i + 0.05 lies below A_j for j > i: A > C in sum_{i} (9 - i) = 45 pairs
    assert ac.u_statistic == 45
    # Benjamini-Hochberg by hand over the family's three p-values
    p = table.p_value.to_numpy()
    order = np.argsort(p)
    m = len(p)
    adj_sorted = np.minimum.accumulate((p[order] * m / np.arange(1, m + 1))[::-1])[::-1]
    expected = np.empty(m)
    expected[order] = np.minimum(adj_sorted, 1)
    assert table.p_adjusted.to_numpy() == pytest.approx(expected)
    assert table.significant.tolist() == (expected < 0.05).tolist()
    assert set(table.columns) >= {"median_a_s", "median_b_s", "n_a", "n_b"}


def test_families_adjust_separately_or_together(make_dataset):
    ds = _dataset(make_dataset, families=(("E1", 1), ("E3", 2)))
    per = compare_transit_times(ds)
    together = compare_transit_times(ds, family="all")
    assert len(per) == 6
    assert np.allclose(per.p_value, together.p_value)
    # six tests adjusted together give larger (or equal) adjusted p than three per family
    assert np.all(together.p_adjusted.to_numpy() >= per.p_adjusted.to_numpy() - 1e-15)
    with pytest.raises(ParcelfitError, match="unknown family"):
        compare_transit_times(ds, family="x")
    with pytest.raises(ParcelfitError, match="alpha"):
        compare_transit_times(ds, alpha=1.5)


def test_stars():
    assert [significance_stars(p) for p in (0.0001, 0.005, 0.04, 0.2)] == ["***", "**", "*", "n.s."]


def test_outputs_are_written(make_dataset, tmp_path):
    result = transit_statistics(_dataset(make_dataset), tmp_path / "out")
    names = sorted(p.name for p in result.files)
    assert names == [
        "transit_time_tests.csv",
        "transit_times.csv",
        "transit_times.png",
        "transit_times.svg",
    ]
    assert (tmp_path / "out" / "transit_times.png").read_bytes()[:4] == b"\x89PNG"
    assert b"<svg" in (tmp_path / "out" / "transit_times.svg").read_bytes()[:500]


def test_ties_use_the_tie_corrected_normal_approximation(make_dataset):
    from scipy.stats import mannwhitneyu

    a, b = [1.0, 1.1, 1.1, 1.3, 1.4], [1.1, 1.5, 1.6, 1.7, 1.8]
    cases = {
        ("E1", n, 1): [(f"{n}{i}", line_trajectory(5), t) for i, t in enumerate(ts)]
        for n, ts in (("A", a), ("B", b))
    }
    row = compare_transit_times(load_dataset(make_dataset(cases))).iloc[0]
    assert row.method == "asymptotic"
    assert row.p_value == pytest.approx(mannwhitneyu(a, b, method="asymptotic").pvalue, rel=1e-12)
