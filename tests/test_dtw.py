import numpy as np
import pytest

from parcelfit import ParcelfitError
from parcelfit.metrics import cross_dtw, dtw_distance, pairwise_dtw

from .helpers import reference_dtw


def test_hand_computed_small_case():
    # local distances |a_i - b_j|: [[0,2],[1,1],[2,0]]; g = [[0,2],[1,2],[3,1]]
    assert dtw_distance([0, 1, 2], [0, 2]) == 1.0
    assert dtw_distance([0, 1, 2], [0, 2], normalized=True) == pytest.approx(1 / 5)
    assert dtw_distance([1, 2, 3], [1, 2, 3]) == 0.0
    # a single pair of points: only the start cell
    assert dtw_distance([[0.0, 0.0]], [[3.0, 4.0]]) == 5.0


@pytest.mark.parametrize("dims", [1, 2, 3])
@pytest.mark.parametrize("lengths", [(40, 40), (57, 31), (12, 90), (200, 180)])
def test_matches_dtw_python(dims, lengths):
    rng = np.random.default_rng(sum(lengths) * dims)
    a = rng.normal(size=(lengths[0], dims)).cumsum(axis=0)
    b = rng.normal(size=(lengths[1], dims)).cumsum(axis=0)
    if dims == 1:
        a, b = a[:, 0], b[:, 0]
    assert dtw_distance(a, b) == pytest.approx(reference_dtw(a, b), rel=1e-9)
    assert dtw_distance(b, a) == pytest.approx(dtw_distance(a, b), rel=1e-12)


@pytest.mark.parametrize("window", [0, 3, 10, 60])
def test_sakoe_chiba_window_matches_dtw_python(window):
    rng = np.random.default_rng(window)
    a = rng.normal(size=(70, 2)).cumsum(axis=0)
    b = rng.normal(size=(70 - min(window, 5), 2)).cumsum(axis=0)
    assert dtw_distance(a, b, window=window) == pytest.approx(reference_dtw(a, b, window), rel=1e-9)
    assert dtw_distance(a, b, window=window) >= dtw_distance(a, b)


def test_window_too_narrow_and_bad_input():
    with pytest.raises(ParcelfitError, match="at least \\|n - m\\| = 5"):
        dtw_distance(np.zeros(10), np.zeros(15), window=4)
    with pytest.raises(ParcelfitError, match="whole number"):
        dtw_distance(np.zeros(3), np.zeros(3), window=-1)
    with pytest.raises(ParcelfitError, match="different dimensions"):
        dtw_distance(np.zeros((3, 2)), np.zeros((3, 1)))
    with pytest.raises(ParcelfitError, match="NaN or inf"):
        dtw_distance([0.0, np.nan], [0.0, 1.0])
    with pytest.raises(ParcelfitError, match="non-empty"):
        dtw_distance([], [1.0])
    with pytest.raises(ParcelfitError, match="window of at least"):
        pairwise_dtw([np.zeros(3), np.zeros(9)], window=2)


def test_pairwise_and_cross_equal_single_pairs():
    rng = np.random.default_rng(7)
    series = [rng.normal(size=(n, 2)).cumsum(axis=0) for n in (30, 45, 38, 50, 41)]
    mat = pairwise_dtw(series)
    assert np.array_equal(mat, mat.T)
    assert np.all(np.diag(mat) == 0)
    for i in range(5):
        for j in range(i + 1, 5):
            assert mat[i, j] == pytest.approx(reference_dtw(series[i], series[j]), rel=1e-9)
    cross = cross_dtw(series[:2], series[2:])
    assert cross.shape == (2, 3)
    assert cross[1, 2] == pytest.approx(mat[1, 4], rel=1e-12)
    assert pairwise_dtw(series[:1]).shape == (1, 1)


def test_random_sweep_with_windows_matches_dtw_python():
    rng = np.random.default_rng(1)
    for _ in range(200):
        n, m = (int(v) for v in rng.integers(1, 40, 2))
        k = int(rng.integers(1, 4))
        w = int(rng.integers(-1, 8))
        a, b = rng.normal(size=(n, k)), rng.normal(size=(m, k))
        window = None if w < 0 else w
        try:
            expected = reference_dtw(a, b, window)
        except ValueError:  # dtw-python: no path fits the window
            with pytest.raises(ParcelfitError, match="no warping path"):
                dtw_distance(a, b, window=window)
            continue
        assert dtw_distance(a, b, window=window) == pytest.approx(expected, rel=1e-12, abs=1e-300)
