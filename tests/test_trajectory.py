import numpy as np
import pytest

from parcelfit import ParcelfitError
from parcelfit.runs import Trajectory, unwrap_angle

from .conftest import line_trajectory


def test_arrays_are_read_only_floats():
    tr = Trajectory(t=[0, 1, 2], x=[0, 1, 2], y=[0, 0, 0], theta=[0, 0, 0])
    assert tr.t.dtype == float
    with pytest.raises(ValueError):
        tr.x[0] = 5.0


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"t": [0, 1], "x": [0, 1], "y": [0, 1], "theta": [0, 0]}, "at least 3 samples"),
        ({"t": [0, 1, 2], "x": [0, 1], "y": [0, 1, 2], "theta": [0, 0, 0]}, "differ in length"),
        (
            {"t": [0, 1, 1], "x": [0, 1, 2], "y": [0, 1, 2], "theta": [0, 0, 0]},
            "not strictly increasing at sample 2",
        ),
        (
            {"t": [0, 1, 2], "x": [0, np.nan, 2], "y": [0, 1, 2], "theta": [0, 0, 0]},
            "non-finite value",
        ),
        ({"t": [0, 1, 2], "x": [0, 1, 2], "y": [0, 1, 2], "theta": [0, 3.5, 0]}, "not unwrapped"),
    ],
)
def test_bad_trajectories_are_rejected(kwargs, message):
    with pytest.raises(ParcelfitError, match=message):
        Trajectory(**kwargs)


def test_unwrap_removes_two_pi_jumps():
    wrapped = np.array([3.0, -3.1, -2.9, 3.1])
    un = unwrap_angle(wrapped)
    assert np.all(np.abs(np.diff(un)) < np.pi)
    assert np.allclose(np.cos(un), np.cos(wrapped)) and np.allclose(np.sin(un), np.sin(wrapped))
    tr = Trajectory.from_arrays([0, 1, 2, 3], [0, 0, 0, 0], [0, 0, 0, 0], wrapped)
    assert tr.theta == pytest.approx([3.0, 2 * np.pi - 3.1, 2 * np.pi - 2.9, 3.1])


def test_relative_subtracts_initial_pose():
    tr = Trajectory(t=[0, 1, 2], x=[1.0, 2.0, 3.0], y=[0.5, 0.5, 0.7], theta=[0.3, 0.4, 0.6])
    rel = tr.relative()
    assert rel.x.tolist() == [0.0, 1.0, 2.0]
    assert rel.y == pytest.approx([0.0, 0.0, 0.2])
    assert rel.theta == pytest.approx([0.0, 0.1, 0.3])
    assert rel.t.tolist() == [0, 1, 2]


def test_resample_is_linear_on_a_uniform_grid():
    tr = Trajectory(t=[0.0, 0.1, 0.3], x=[0.0, 1.0, 3.0], y=[0.0, 0.0, 2.0], theta=[0.0, 0.1, 0.1])
    rs = tr.resample(20.0)
    assert rs.t == pytest.approx([0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3])
    assert rs.x == pytest.approx(10 * rs.t)
    assert rs.y == pytest.approx([0, 0, 0, 0.5, 1.0, 1.5, 2.0])
    assert rs.sample_rate() == pytest.approx(20.0)
    with pytest.raises(ParcelfitError, match="positive"):
        tr.resample(0)


@pytest.mark.parametrize("origin", [0.0, 37.25, 1000.0])
def test_resample_keeps_the_end_of_time_stamps_rounded_in_a_file(origin):
    # t = origin + k/60 s written with 9 significant digits (run files before they kept every
    # digit): the end may fall a little short of the last 60 Hz grid point, which stays
    t = origin + np.arange(90) / 60
    x = 0.6 * np.arange(90) / 60
    exact = Trajectory(t=t, x=x, y=np.zeros(90), theta=np.zeros(90))
    rounded = Trajectory(t=[float(f"{v:.9g}") for v in t], x=x, y=np.zeros(90), theta=np.zeros(90))
    assert len(exact.resample(60.0)) == len(rounded.resample(60.0)) == 90
    # off by the rounding of the time stamps only (5e-6 s at 1000 s, at 0.6 m/s)
    assert rounded.resample(60.0).x == pytest.approx(exact.resample(60.0).x, abs=1e-5)


def test_resample_does_not_reach_a_grid_point_the_run_ends_short_of():
    # the run ends a hundredth of an interval before t = 0.15 s: no sample there
    tr = Trajectory(t=[0.0, 0.1, 0.1495], x=[0.0, 1.0, 1.495], y=[0.0] * 3, theta=[0.0] * 3)
    assert tr.resample(20.0).t == pytest.approx([0.0, 0.05, 0.1])
    assert Trajectory(t=[0.0, 0.1, 0.15], x=[0.0, 1, 2], y=[0.0] * 3, theta=[0.0] * 3).resample(
        20.0
    ).t == pytest.approx([0.0, 0.05, 0.1, 0.15])


def test_select_and_frame_round_trip():
    tr = line_trajectory(10)
    sub = tr.select(tr.x > tr.x[4])
    assert len(sub) == 5
    with pytest.raises(ParcelfitError, match="only 2 samples remain"):
        tr.select(tr.x > tr.x[7])
    back = Trajectory.from_frame(tr.to_frame())
    assert np.array_equal(back.xy, tr.xy)


def test_source_flags_filled_samples_and_follows_select_and_relative():
    src = ["detected", "detected", "filled", "filled", "detected"]
    tr = Trajectory(
        t=[0, 1, 2, 3, 4], x=[0.0, 1, 2, 3, 4], y=[0.0] * 5, theta=[0.0] * 5, source=src
    )
    assert tr.filled.tolist() == [False, False, True, True, False]
    assert tr.relative().source.tolist() == src
    assert tr.select(np.array([0, 1, 1, 1, 1], bool)).filled.tolist() == [False, True, True, False]
    assert tr.resample(2.0).source is None  # resampled samples are neither
    back = Trajectory.from_frame(tr.to_frame())
    assert back.source.tolist() == src
    with pytest.raises(ParcelfitError, match="source of sample 1 is 'guessed'"):
        Trajectory(
            t=[0, 1, 2],
            x=[0, 1, 2],
            y=[0, 0, 0],
            theta=[0, 0, 0],
            source=["detected", "guessed", "filled"],
        )
    with pytest.raises(ParcelfitError, match="one source per sample"):
        Trajectory(t=[0, 1, 2], x=[0, 1, 2], y=[0, 0, 0], theta=[0, 0, 0], source=["detected"])


def test_without_source_every_sample_counts_as_measured():
    tr = line_trajectory(5)
    assert tr.source is None and tr.filled.tolist() == [False] * 5
    assert list(tr.to_frame().columns) == ["t", "x", "y", "theta"]


def test_standard_deviations_follow_select_and_relative_and_are_checked():
    kw = {"t": [0, 1, 2, 3], "x": [0.0, 1, 2, 3], "y": [0.0] * 4, "theta": [0.0] * 4}
    tr = Trajectory(
        **kw, position_sd=[2e-4, 1e-4, np.nan, 3e-4], heading_sd=[0.01, 0.02, np.nan, 0.03]
    )
    sub = tr.relative().select(np.array([0, 1, 1, 1], bool))
    assert sub.position_sd == pytest.approx([1e-4, np.nan, 3e-4], nan_ok=True)
    assert sub.heading_sd == pytest.approx([0.02, np.nan, 0.03], nan_ok=True)
    assert tr.resample(2.0).position_sd is None
    back = Trajectory.from_frame(tr.to_frame())
    assert back.heading_sd == pytest.approx(tr.heading_sd, nan_ok=True)
    assert line_trajectory(5).position_sd is None
    with pytest.raises(ParcelfitError, match=r"heading_sd of sample 1 is -0\.1"):
        Trajectory(**kw, heading_sd=[0.0, -0.1, 0.0, 0.0])
    with pytest.raises(ParcelfitError, match="position_sd of sample 3 is inf"):
        Trajectory(**kw, position_sd=[0.0, 0.0, 0.0, np.inf])
