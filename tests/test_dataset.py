import numpy as np
import pytest
import yaml

from parcelfit import ParcelfitError
from parcelfit.data import example_dataset_path
from parcelfit.runs import Box, CaseData, Polygon, Run, TestCase, load_dataset, save_dataset

from .conftest import line_trajectory

CASE = ("E3", "KPBW", 1)


def _runs(n=3):
    return [(f"r{i}", line_trajectory(20, y0=0.01 * i), 1.0 + 0.1 * i) for i in range(n)]


def _edit(root, change):
    path = root / "dataset.yaml"
    doc = yaml.safe_load(path.read_text())
    change(doc)
    path.write_text(yaml.safe_dump(doc, sort_keys=False))


def test_loads_runs_grouped_by_test_case(make_dataset):
    root = make_dataset({CASE: _runs(3), ("E3", "PB", 2): [("p1", line_trajectory(), None)]})
    ds = load_dataset(root)
    assert ds.name == "test" and not ds.synthetic
    cd = ds["E3/KPBW/1"]
    assert [r.id for r in cd.runs] == ["r0", "r1", "r2"]
    assert cd.runs[1].transit_time == pytest.approx(1.1)
    assert cd.runs[2].trajectory.y[0] == pytest.approx(0.02)
    assert ds[TestCase("E3", "PB", 2)].runs[0].transit_time is None
    assert len(ds.runs()) == 4
    with pytest.raises(ParcelfitError, match="E1/KP/1 is not in dataset"):
        ds["E1/KP/1"]


@pytest.mark.parametrize(
    ("change", "pattern"),
    [
        (lambda d: d.update(nmae="x"), r"top level: unknown key 'nmae'.*did you mean 'name'"),
        (lambda d: d.pop("name"), r"missing required key 'name'"),
        (lambda d: d.update(test_cases=[]), r"test_cases must be a non-empty list"),
        (
            lambda d: d["test_cases"][0].update(speed_setting=0),
            r"test_cases\[0\]\.speed_setting: .*integer from 1 to 1000",
        ),
        (
            lambda d: d["test_cases"][0].update(rigg="E3"),
            r"test_cases\[0\]: unknown key 'rigg'.*did you mean 'rig'",
        ),
        (
            lambda d: d["test_cases"][0]["runs"][1].update(id="r0"),
            r"runs\[1\]\.id: duplicate run id 'r0'",
        ),
        (
            lambda d: d["test_cases"][0]["runs"][0].update(transit_time=-1),
            r"transit_time must be positive",
        ),
        (
            lambda d: d["test_cases"][0]["runs"][0].update(transit_time="fast"),
            r"transit_time: expected a number",
        ),
        (
            lambda d: d["test_cases"][0]["runs"][0].update(file="runs/nope.csv"),
            r"runs\[0\]\.file: .*not found",
        ),
        (
            lambda d: d["test_cases"].append(dict(d["test_cases"][0])),
            r"test case E3/KPBW/1 appears twice",
        ),
        (lambda d: d["test_cases"][0].update(margin=-0.1), r"margin: -0.1 is outside"),
        (
            lambda d: d["test_cases"][0].update(regions=[{"x": [1, 0]}]),
            r"regions\[0\]: expected x as \[min, max\]",
        ),
        (
            lambda d: d["test_cases"][0].update(regions=[{"polygon": [[0, 0], [1, 1]]}]),
            r"at least three",
        ),
        (lambda d: d["test_cases"][0].update(regions=[{"circle": 1}]), r"unknown region keys"),
    ],
)
def test_bad_dataset_yaml_names_key_and_fix(make_dataset, change, pattern):
    root = make_dataset({CASE: _runs(3)})
    _edit(root, change)
    with pytest.raises(ParcelfitError, match=pattern) as info:
        load_dataset(root)
    assert "dataset.yaml" in str(info.value)
    assert "Fix:" in str(info.value)


def test_malformed_yaml_reports_line(make_dataset):
    root = make_dataset({CASE: _runs(1)})
    (root / "dataset.yaml").write_text("name: x\ntest_cases: [\n  - rig: {\n")
    with pytest.raises(ParcelfitError, match=r"dataset.yaml: line \d+, column \d+: malformed YAML"):
        load_dataset(root)


def test_bad_trajectory_inside_dataset_names_the_run_file(make_dataset):
    root = make_dataset({CASE: _runs(2)})
    (root / "runs" / "r1.csv").write_text("t,x,y,theta\n0,0,0,0\n1,0,0,0\n1,0,0,0\n")
    with pytest.raises(ParcelfitError, match=r"r1\.csv: data row 3: time does not increase"):
        load_dataset(root)


def test_missing_folder(tmp_path):
    with pytest.raises(ParcelfitError, match=r"no dataset\.yaml here"):
        load_dataset(tmp_path)


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_save_and_load_round_trip(tmp_path, fmt):
    case = TestCase("E1", "BW", 2)
    runs = tuple(Run(f"a{i}", case, line_trajectory(15, turn=0.1 * i), 1.5 + i) for i in range(2))
    regions = (Box(xmin=0.1, xmax=0.9), Polygon(np.array([[0, 0], [1, 0], [1, 1.0]])))
    save_dataset(
        tmp_path, "rt", [CaseData(case, runs, regions, 0.01)], synthetic=True, file_format=fmt
    )
    ds = load_dataset(tmp_path / "dataset.yaml")
    cd = ds[case]
    assert ds.synthetic and ds.name == "rt"
    assert cd.regions[0] == Box(xmin=0.1, xmax=0.9)
    assert np.array_equal(cd.regions[1].vertices, regions[1].vertices)
    assert cd.margin == 0.01
    assert np.allclose(cd.runs[1].trajectory.theta, runs[1].trajectory.theta)


def test_bundled_example_is_labelled_synthetic():
    ds = load_dataset(example_dataset_path())
    assert ds.synthetic
    assert "SYNTHETIC" in ds.description
    assert len(ds.cases) == 16  # E3 KPBW, PB at settings 1-2; E1 four types at 1-3
    assert all(len(cd.runs) == 10 for cd in ds.cases.values())
