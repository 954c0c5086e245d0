import numpy as np
import pandas as pd
import pytest

from parcelfit import ParcelfitError
from parcelfit.metrics import calibration_cost, select_reference, validate
from parcelfit.runs import TestCase, load_dataset, read_trajectory, write_trajectory

from .conftest import line_trajectory
from .fake_sim import trajectory, write_reference_dataset


def _write(tmp_path, frame, name="run.csv"):
    path = tmp_path / name
    frame.to_csv(path, index=False)
    return path


def _good(n=20):
    return line_trajectory(n).to_frame()


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_round_trip(tmp_path, suffix):
    tr = line_trajectory(30, turn=0.4)
    path = write_trajectory(tr, tmp_path / f"a{suffix}")
    back = read_trajectory(path)
    assert np.allclose(back.xy, tr.xy, rtol=1e-8, atol=0)
    assert np.allclose(back.theta, tr.theta, rtol=1e-8)
    assert not list(tmp_path.glob("*.tmp"))


def test_wrapped_heading_is_unwrapped_on_load(tmp_path):
    f = _good(6)
    f["theta"] = [3.0, 3.1, -3.1, -3.0, -2.9, -2.8]
    tr = read_trajectory(_write(tmp_path, f))
    assert np.all(np.diff(tr.theta) > 0)


@pytest.mark.parametrize(
    ("mutate", "pattern"),
    [
        (
            lambda f: f.drop(columns="theta"),
            r"run\.csv: missing column\(s\) \['theta'\].*Fix: name the columns",
        ),
        (lambda f: f.assign(z=0.0), r"unexpected column\(s\) \['z'\].*Fix: keep only"),
        (lambda f: f.head(2), "2 samples, at least 3 needed"),
        (
            lambda f: f.assign(x=f["x"].where(f.index != 4, np.nan)),
            r"data row 5: column 'x' has a missing",
        ),
        (lambda f: f.assign(y=f["y"].where(f.index != 2, np.inf)), r"data row 3: column 'y'"),
        (
            lambda f: f.assign(t=f["t"].astype(object).where(f.index != 1, "abc")),
            r"data row 2: column 't'",
        ),
        (
            lambda f: f.assign(t=f["t"].where(f.index != 6, f["t"][5])),
            r"data row 7: time does not increase",
        ),
        (
            lambda f: f.assign(x=f["x"] * 1000 + 300),
            r"column 'x': x spans .* if they are in millimetres",
        ),
        (lambda f: f.assign(t=f["t"] * 1e6), r"column 't'.*if it is in milliseconds"),
        (
            lambda f: f.assign(theta=np.linspace(30, 45, len(f))),
            r"column 'theta'.*if it is in degrees",
        ),
    ],
)
def test_bad_files_name_file_place_and_fix(tmp_path, mutate, pattern):
    path = _write(tmp_path, mutate(_good()))
    with pytest.raises(ParcelfitError, match=pattern) as info:
        read_trajectory(path)
    assert "Fix:" in str(info.value)


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(ParcelfitError, match="file not found"):
        read_trajectory(tmp_path / "none.csv")
    bad = tmp_path / "x.txt"
    bad.write_text("t,x\n")
    with pytest.raises(ParcelfitError, match="unknown file type"):
        read_trajectory(bad)
    broken = tmp_path / "b.parquet"
    broken.write_bytes(b"not parquet")
    with pytest.raises(ParcelfitError, match=r"b\.parquet: not a readable Parquet file \("):
        read_trajectory(broken)


@pytest.mark.parametrize(
    ("content", "message", "fix"),
    [
        (
            b"",
            "the file is empty (0 bytes)",
            "write the run's samples into it (columns t,x,y,theta), or name the right file",
        ),
        (
            b" \n\n",
            "the file is empty (3 bytes, all white space)",
            "write the run's samples into it (columns t,x,y,theta), or name the right file",
        ),
        (
            b"t,x,y,theta\n0,0,0,0\n0.1,caf\xe9,0,0\n",
            "not UTF-8 text (byte 27: b'\\xe9')",  # after 12 + 8 + 7 bytes
            "save the file as UTF-8 (CSV UTF-8)",
        ),
        (
            b't,x,y,theta\n0,0,0,"0\n',
            "malformed CSV (Error tokenizing data. C error: EOF inside string starting at row 1)",
            "write a header line t,x,y,theta and one line of numbers per sample",
        ),
    ],
)
def test_an_unreadable_run_file_says_what_is_wrong(tmp_path, content, message, fix):
    path = tmp_path / "run.csv"
    path.write_bytes(content)
    with pytest.raises(ParcelfitError) as err:
        read_trajectory(path)
    assert (err.value.file, err.value.message, err.value.fix) == (str(path), message, fix)


def test_a_csv_with_a_byte_order_mark_is_read(tmp_path):
    path = tmp_path / "run.csv"
    write_trajectory(line_trajectory(), path)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())  # as Excel's "CSV UTF-8" saves it
    assert read_trajectory(path).t[0] == line_trajectory().t[0]


def test_write_rejects_unknown_suffix(tmp_path):
    with pytest.raises(ParcelfitError, match=r"use \.csv or \.parquet"):
        write_trajectory(line_trajectory(), tmp_path / "a.json")


def test_parquet_schema_errors_too(tmp_path):
    path = tmp_path / "a.parquet"
    pd.DataFrame({"t": [0.0, 1.0, 2.0], "x": [0.0, 1, 2], "y": [0.0, 0, 0]}).to_parquet(path)
    with pytest.raises(ParcelfitError, match="missing column"):
        read_trajectory(path)


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_source_column_round_trips_and_is_written_only_when_present(tmp_path, suffix):
    tr = line_trajectory(6)
    src = ["detected", "filled", "filled", "detected", "detected", "detected"]
    flagged = type(tr)(t=tr.t, x=tr.x, y=tr.y, theta=tr.theta, source=src)
    back = read_trajectory(write_trajectory(flagged, tmp_path / f"f{suffix}"))
    assert back.source.tolist() == src
    assert back.filled.tolist() == [False, True, True, False, False, False]
    # a run without flags (simulated, or an old file) is written and read as before
    plain = write_trajectory(tr, tmp_path / f"p{suffix}")
    assert list(
        pd.read_csv(plain).columns if suffix == ".csv" else pd.read_parquet(plain).columns
    ) == [
        "t",
        "x",
        "y",
        "theta",
    ]
    old = read_trajectory(plain)
    assert old.source is None and not old.filled.any()


def test_old_csv_without_source_reads_and_a_bad_source_is_named(tmp_path):
    old = tmp_path / "old.csv"
    old.write_text("t,x,y,theta\n0,0,0,0\n0.1,0.01,0,0\n0.2,0.02,0,0.01\n")
    tr = read_trajectory(old)
    assert len(tr) == 3 and tr.source is None and not tr.filled.any()
    f = _good(5).assign(source=["detected", "filled", "interpolated", "detected", "detected"])
    with pytest.raises(
        ParcelfitError,
        match=r"data row 3: column 'source' has 'interpolated'.*Fix: write detected, fitted or filled",
    ):
        read_trajectory(_write(tmp_path, f))
    f = _good(5).assign(source=["detected", None, "filled", "detected", "detected"])
    with pytest.raises(ParcelfitError, match=r"data row 2: column 'source'"):
        read_trajectory(_write(tmp_path, f))


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_standard_deviation_columns_round_trip_with_empty_cells(tmp_path, suffix):
    tr = line_trajectory(5)
    pos_sd = np.array([1.5e-4, 1.2e-4, np.nan, 1.3e-4, 2.1e-4])
    head_sd = np.array([2e-3, 1e-3, np.nan, 1e-3, 3e-3])
    src = ["detected", "detected", "filled", "detected", "detected"]
    full = type(tr)(
        t=tr.t, x=tr.x, y=tr.y, theta=tr.theta, source=src, position_sd=pos_sd, heading_sd=head_sd
    )
    path = write_trajectory(full, tmp_path / f"sd{suffix}")
    if suffix == ".csv":
        assert path.read_text().splitlines()[0] == "t,x,y,theta,source,position_sd,heading_sd"
        assert path.read_text().splitlines()[3].endswith(",filled,,")  # empty where none
    back = read_trajectory(path)
    assert back.position_sd == pytest.approx(pos_sd, rel=1e-8, nan_ok=True)
    assert back.heading_sd == pytest.approx(head_sd, rel=1e-8, nan_ok=True)
    assert back.source.tolist() == src


@pytest.mark.parametrize(
    ("column", "values", "pattern"),
    [
        (
            "position_sd",
            [1e-4, "abc", 1e-4, 1e-4, 1e-4],
            r"data row 2: column 'position_sd' has 'abc'",
        ),
        ("heading_sd", [1e-3, 1e-3, 1e-3, -1e-3, 1e-3], r"data row 4: column 'heading_sd'"),
    ],
)
def test_bad_standard_deviations_are_named(tmp_path, column, values, pattern):
    f = _good(5).assign(**{column: values})
    with pytest.raises(ParcelfitError, match=pattern + r".*Fix: a standard deviation"):
        read_trajectory(_write(tmp_path, f))


def _compare_sim_with_real(tmp_path, write):
    """The fake simulator's run (60 Hz, t = k/60 s up to 89/60 s) in memory and as ``write``
    stores and `read_trajectory` reads it back, each compared with four real runs."""
    real = select_reference(
        load_dataset(write_reference_dataset(tmp_path / "real", 4))[TestCase("R", "P", 1)]
    )
    sim, transit = trajectory({"mu_d_BePa": 0.45, "mu_d_MePa": 0.25}, 1)
    back = read_trajectory(write(sim))
    runs = (sim, back)
    prepared = [real.comparison.prepare(r) for r in runs]
    costs = [calibration_cost(r, real) for r in runs]
    verdicts = [validate(r, transit, real) for r in runs]
    return runs, prepared, costs, verdicts


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_a_run_read_back_from_its_file_compares_as_the_run_in_memory(tmp_path, suffix):
    # a CSV with 9 significant digits read t = 89/60 s back as 1.48333333 s: the 60 Hz
    # resampling lost the last sample and the DTW cost moved by about 4 %
    (sim, back), (a, b), (ca, cb), (va, vb) = _compare_sim_with_real(
        tmp_path, lambda tr: write_trajectory(tr, tmp_path / f"sim{suffix}")
    )
    for c in ("t", "x", "y", "theta"):  # the file keeps every digit
        np.testing.assert_allclose(getattr(back, c), getattr(sim, c), rtol=1e-15, atol=0)
    assert len(b) == len(a) == len(sim)
    np.testing.assert_allclose(b.xy, a.xy, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(b.theta, a.theta, rtol=1e-14, atol=1e-15)
    assert cb.value == pytest.approx(ca.value, rel=1e-12)
    assert (cb.dtw_xy, cb.dtw_theta) == pytest.approx((ca.dtw_xy, ca.dtw_theta), rel=1e-12)
    assert vb.passed == va.passed and vb.strict_passed == va.strict_passed
    assert vb.xy.simulated_mean == pytest.approx(va.xy.simulated_mean, rel=1e-12)
    assert vb.theta.simulated_mean == pytest.approx(va.theta.simulated_mean, rel=1e-12)


def test_a_run_file_with_nine_digits_keeps_its_last_sample(tmp_path):
    # run files written before every digit was kept (9 significant digits) still resample to
    # the samples of the run in memory; their values differ in the 9th digit only
    def old_writer(tr):
        path = tmp_path / "old.csv"
        tr.to_frame().to_csv(path, index=False, float_format="%.9g")
        return path

    (sim, back), (a, b), (ca, cb), (va, vb) = _compare_sim_with_real(tmp_path, old_writer)
    assert back.t[-1] != sim.t[-1]  # rounded in the file
    assert len(b) == len(a) == len(sim)
    np.testing.assert_allclose(b.xy, a.xy, rtol=0, atol=1e-8)
    assert cb.value == pytest.approx(ca.value, rel=1e-6)
    assert vb.xy.simulated_mean == pytest.approx(va.xy.simulated_mean, rel=1e-6)
