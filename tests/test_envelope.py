import math

import numpy as np
import pytest

from parcelfit import ParcelfitError
from parcelfit.metrics import select_reference, validate
from parcelfit.metrics.envelope import envelope_check
from parcelfit.runs import CaseData, Run, TestCase, Trajectory

CASE = TestCase("E3", "PB", 1)


def _traj(drift, turn, kink=0.0, n=60):
    """x = 0.6 t, y = drift t^2, bending away after t = 0.5 s by kink (t - 0.5)^2; theta = turn t."""
    t = np.arange(n) / 60
    return Trajectory(
        t=t, x=0.6 * t, y=drift * t**2 - kink * np.maximum(0, t - 0.5) ** 2, theta=turn * t
    )


@pytest.fixture
def real():
    runs = tuple(
        Run(f"r{i}", CASE, _traj(d, w), tt)
        for i, (d, w, tt) in enumerate(
            zip([0.0, 0.05, 0.10, 0.15], [0.0, 0.1, 0.2, 0.3], [1.0, 1.1, 1.2, 1.3], strict=True)
        )
    )
    return select_reference(CaseData(CASE, runs))


def test_a_typical_run_is_inside_the_band(real):
    v = validate(_traj(0.07, 0.15), 1.15, real)
    assert v.passed and v.strict_passed
    assert v.envelope.inside_y == 1.0 and v.envelope.worst_y == 0.0


def test_published_criteria_pass_a_drifting_run_the_envelope_catches(real):
    v = validate(_traj(0.07, 0.15, kink=0.6), 1.15, real)
    assert v.passed  # mean DTW distance below the largest real mean, transit time in range
    assert v.xy.simulated_mean < v.xy.largest_real_mean
    assert not v.envelope.passed and not v.strict_passed
    assert v.envelope.inside_y < 0.95 and v.envelope.worst_y > 0.05  # leaves the band by > 5 cm


def test_band_by_hand_and_tolerances():
    reals = [_traj(0.0, 0.0), _traj(0.1, 0.0)]
    # 2 mm below the lowest real run everywhere: inside with the 3 mm tolerance, outside without
    t = np.arange(60) / 60
    low = Trajectory(t=t, x=0.6 * t, y=np.full(60, -0.002), theta=np.zeros(60))
    assert envelope_check(low, reals).passed
    strict = envelope_check(low, reals, tol_xy=0.0)
    assert not strict.passed and strict.worst_y == pytest.approx(0.002)
    turned = Trajectory(t=t, x=0.6 * t, y=np.zeros(60), theta=np.full(60, math.radians(2)))
    check = envelope_check(turned, reals)
    assert check.inside_theta < 0.05 and check.worst_theta == pytest.approx(math.radians(1))
    with pytest.raises(ParcelfitError, match="at least two real runs"):
        envelope_check(low, reals[:1])
