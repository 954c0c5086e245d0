"""Screening over seeded placements (``placements: K`` in a screen file): every design row is
simulated at placement seeds 1..K and judged by the means of its runs' responses."""

from __future__ import annotations

import math
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from parcelfit.errors import ParcelfitError
from parcelfit.metrics import calibration_cost, select_reference
from parcelfit.runs import Run, TestCase, Trajectory, load_dataset
from parcelfit.sim.ensemble import rotation
from parcelfit.sim.protocol import SimResult, SimStatus
from parcelfit.study.screening import load_screen, run_screen
from parcelfit.study.store import Store

from . import fake_sim
from .fake_sim import AnalyticSimulator, write_reference_dataset
from .helpers import ROOT

GOLDEN = Path(__file__).parent / "data" / "screen-k1"
PROBE = "tests.test_screening_placements:make_probe"
DESIGN = {"mu_d_BePa": [0.3, 0.58], "mu_d_MePa": [0.15, 0.35], "E_Pa": [200, 1600]}


def expected(params, seed) -> tuple[Trajectory, float | None]:
    """The probe's run: the analytic run at placement ``seed``; at seed 3 a parcel with
    mu_d_MePa above 0.25 turns half a turn more (a spin), at seed 2 one with mu_d_BePa below
    0.4 crosses no second light barrier (no transit time)."""
    start = (0.0, 0.0, 0.0) if seed is None else fake_sim.placement(seed)
    traj, transit = fake_sim.trajectory(params, 1, placement=start)
    if seed == 3 and params["mu_d_MePa"] > 0.25:
        traj = Trajectory(
            t=traj.t, x=traj.x, y=traj.y, theta=traj.theta + math.pi * traj.t / traj.t[-1]
        )
    return traj, (None if seed == 2 and params["mu_d_BePa"] < 0.4 else transit)


class PlacementProbe(AnalyticSimulator):
    """Writes ``RUN_ID SEED`` to the file ``probe`` when a simulation starts, then runs
    `expected` (after the analytic simulator's delay)."""

    def __init__(self, probe: str, delay: float = 0.0, placement_seed: int | None = None):
        super().__init__(delay=delay, placement_seed=placement_seed)
        self.probe = probe

    def with_placement(self, seed: int | None) -> PlacementProbe:
        return PlacementProbe(self.probe, self.delay, seed)

    def run(self, params, case, run_id=None):
        with open(self.probe, "a") as fh:
            fh.write(f"{run_id} {self.placement_seed}\n")
        res = super().run(params, case, run_id)  # sleeps the delay
        traj, transit = expected(params, self.placement_seed)
        return SimResult(Run(run_id or "sim", case, traj, transit), SimStatus.OK, res.wall_time)


def make_probe() -> PlacementProbe:
    """Factory named in screen files: the probe file from SCREEN_PROBE."""
    return PlacementProbe(os.environ["SCREEN_PROBE"], float(os.environ.get("FAKE_SIM_DELAY", "0")))


class Unplaced:
    """A simulator that cannot place its runs (no ``with_placement``)."""

    def run(self, params, case, run_id=None):
        return AnalyticSimulator().run(params, case, run_id)


def make_unplaced() -> Unplaced:
    return Unplaced()


def _screen(tmp_path: Path, name: str = "screen.yaml", **change) -> Path:
    if not (tmp_path / "data").is_dir():
        write_reference_dataset(tmp_path / "data")
    doc = {
        "name": "placed",
        "simulator": {"backend": "python", "factory": PROBE},
        "reference": {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1},
        "parameters": DESIGN,
        "stages": ["full"],
        "placements": 3,
        "executor": "serial",
        **change,
    }
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _probed(probe: Path) -> list[tuple[str, str]]:
    return [tuple(line.split()) for line in probe.read_text().splitlines()]


def test_one_placement_writes_todays_design_effects_and_selection(tmp_path):
    """Without the key (placements: 1) a screen writes what it wrote before placements existed:
    tests/data/screen-k1 holds the outputs of this screen from that code."""
    write_reference_dataset(tmp_path / "data")
    doc = {
        "name": "k1",
        "simulator": {"backend": "python", "factory": "tests.fake_sim:make"},
        "reference": {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1},
        "parameters": {**DESIGN, "nu_Pa": [0.2, 0.45]},
        "stages": ["fractional", "full"],
        "executor": "serial",
    }
    path = tmp_path / "screen.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    screen = load_screen(path)
    assert screen.placements == 1
    out = tmp_path / "out"
    stages, selection = run_screen(screen, out)
    for name in (
        "stage1-design.csv",
        "stage2-design.csv",
        "stage1-effects.csv",
        "stage2-effects.csv",
    ):
        pd.testing.assert_frame_equal(
            pd.read_csv(out / name), pd.read_csv(GOLDEN / name), check_exact=False, rtol=1e-10
        )
    assert selection == yaml.safe_load((GOLDEN / "selection.yaml").read_text())
    assert [s.ensemble_analyses for s in stages] == [[], []]
    assert sorted(p.name for p in out.glob("*.png")) == [
        f"stage{k}-pareto-{r}.png" for k in (1, 2) for r in ("dtw_theta", "dtw_xy")
    ]
    store = Store(out / "screen.sqlite", readonly=True)
    rows = store.evaluations("screen")
    store.close()
    assert {r.seed for r in rows} == {0} and [r.slot for r in rows] == list(range(8)) * 2
    assert sorted(p.name for p in (out / "runs").iterdir()) == [
        f"screen-{s:03d}-{i:02d}.csv" for s in (0, 1) for i in range(8)
    ]
    # an explicit placements: 1 is the same screen
    doc["placements"] = 1
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    assert load_screen(path) == screen
    # a store written before placements existed holds nominal runs: K = 3 is refused there
    con = sqlite3.connect(out / "screen.sqlite")
    with con:
        con.execute("DELETE FROM meta WHERE key = 'placements'")
    con.close()
    doc["placements"] = 3
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.raises(ParcelfitError, match="was run with placements: 1, now it would be run"):
        run_screen(load_screen(path), out)


@pytest.mark.slow
def test_three_placements_simulate_every_row_at_seeds_1_to_3_and_average(tmp_path, monkeypatch):
    probe = tmp_path / "probe"
    monkeypatch.setenv("SCREEN_PROBE", str(probe))
    path = _screen(tmp_path, executor={"kind": "serial"})  # no worker processes to start
    events = []
    out = tmp_path / "out"
    (stage,), selection = run_screen(load_screen(path), out, progress=events.append)
    # 8 rows x 3 placements, each seed reaching the simulator with its run
    runs = _probed(probe)
    assert sorted(runs) == sorted(
        (f"screen-000-{i:02d}-p{s}", str(s)) for i in range(8) for s in (1, 2, 3)
    )
    assert sorted(p.name for p in (out / "runs").iterdir()) == sorted(
        f"{run_id}.csv" for run_id, _ in runs
    )
    store = Store(out / "screen.sqlite", readonly=True)
    rows = store.evaluations("screen")
    store.close()
    assert [(r.slot, r.seed) for r in rows] == [
        (i * 3 + s - 1, s) for i in range(8) for s in (1, 2, 3)
    ]
    assert all(r.status == "ok" for r in rows)
    # the design: a row's responses are the means over its placements
    design = pd.read_csv(out / "stage1-design.csv")
    assert list(design.columns) == [
        *DESIGN,
        "status",
        "dtw_xy",
        "dtw_theta",
        "transit_time",
        "transits",
        "spin_share",
        "median_rotation",
        "placements_ok",
    ]
    reference = select_reference(load_dataset(tmp_path / "data")[TestCase("R", "P", 1)])
    for _, row in design.iterrows():
        params = {n: row[n] for n in DESIGN}
        params["E_Pa"] *= 1e6  # catalogue units (N/mm^2) to Pa
        made = [expected(params, s) for s in (1, 2, 3)]
        costs = [calibration_cost(traj, reference) for traj, _ in made]
        transits = [t for _, t in made if t is not None]
        turns = [rotation(traj) for traj, _ in made]
        assert row["status"] == "ok" and row["placements_ok"] == 3
        assert row["dtw_xy"] == pytest.approx(np.mean([c.dtw_xy for c in costs]), rel=1e-12)
        assert row["dtw_theta"] == pytest.approx(np.mean([c.dtw_theta for c in costs]), rel=1e-12)
        assert row["transit_time"] == pytest.approx(np.mean(transits), rel=1e-12)
        assert row["transits"] == (2 if params["mu_d_BePa"] < 0.4 else 3)
        assert row["spin_share"] == pytest.approx(1 / 3 if params["mu_d_MePa"] > 0.25 else 0)
        assert row["median_rotation"] == pytest.approx(np.median(turns), rel=1e-12)
    # selection on the DTW responses; spin share and median rotation analysed beside them
    assert [a.response for a in stage.analyses] == ["dtw_xy", "dtw_theta"]
    assert [a.response for a in stage.ensemble_analyses] == [
        "spin_share",
        "median_rotation",
        "transit_time",
    ]
    spin = stage.ensemble_analyses[0].table.iloc[0]
    assert spin["term"] == "mu_d_MePa" and spin["effect"] == pytest.approx(1 / 3)
    # the mean transit time's main effects: the difference of the rows' means, high minus low
    transit = stage.ensemble_analyses[2].table.set_index("term")
    for name in DESIGN:
        high = design[name] == design[name].max()
        want = design.loc[high, "transit_time"].mean() - design.loc[~high, "transit_time"].mean()
        assert transit.loc[name, "effect"] == pytest.approx(want, rel=1e-9, abs=1e-12)
    effects = pd.read_csv(out / "stage1-effects.csv")
    assert list(dict.fromkeys(effects["response"])) == [
        "dtw_xy",
        "dtw_theta",
        "spin_share",
        "median_rotation",
        "transit_time",
    ]
    assert (out / "stage1-pareto-spin_share.png").is_file()
    assert not any(
        "spin_share" in why or "rotation" in why for why in selection["reasons"].values()
    )
    # progress: simulations counted one by one, each naming its row and placement
    counted = [e for e in events if e.done is not None]
    assert [(e.done, e.total) for e in counted] == [(k, 24) for k in range(1, 25)]
    assert all(" of 8 at placement " in e.message for e in counted)
    assert any(
        "8 runs x 3 placements = 24 simulations, 24 to simulate" in e.message for e in events
    )


@pytest.mark.slow
def test_a_killed_screen_resumes_without_simulating_its_stored_runs_again(tmp_path, monkeypatch):
    probe = tmp_path / "probe"
    path = _screen(tmp_path, parameters={n: DESIGN[n] for n in ("mu_d_BePa", "mu_d_MePa")})
    out = tmp_path / "out"
    env = {**os.environ, "SCREEN_PROBE": str(probe), "FAKE_SIM_DELAY": "0.3"}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    cmd = [sys.executable, "-m", "parcelfit", "screen", str(path), "--out", str(out)]
    proc = subprocess.Popen(
        cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    try:
        deadline = time.time() + 120
        while time.time() < deadline and len(_probed(probe) if probe.exists() else []) < 5:
            time.sleep(0.01)
        os.kill(proc.pid, signal.SIGKILL)  # 4 simulations finished, the fifth running
    finally:
        proc.kill()
        proc.wait()
    before = [run_id for run_id, _ in _probed(probe)]
    assert len(before) == 5
    store = Store(out / "screen.sqlite", readonly=True)
    stored = {r.slot: r.status for r in store.evaluations("screen")}
    store.close()
    assert len(stored) == 12 and sorted(stored.values()).count("ok") == 4  # 4 rows x 3 placements
    monkeypatch.setenv("SCREEN_PROBE", str(probe))
    run_screen(load_screen(path), out)
    again = [run_id for run_id, _ in _probed(probe)[5:]]
    assert len(again) == 8 and not set(again) & set(before[:4])  # the 4 stored are kept
    assert before[4] in again  # the one killed while running is run again
    design = pd.read_csv(out / "stage1-design.csv")
    assert len(design) == 4 and (design["status"] == "ok").all()
    # a rerun with other placements is refused, naming both
    with pytest.raises(ParcelfitError) as err:
        run_screen(load_screen(_screen(tmp_path, "two.yaml", placements=2)), out)
    assert err.value.message == (
        "the screen was run with placements: 3, now it would be run with placements: 2"
    )
    assert err.value.file == str(out / "screen.sqlite")
    assert len(_probed(probe)) == 13  # nothing simulated


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (0, "0 is out of range"),
        (51, "51 is out of range"),
        (2.5, "expected a whole number, got 2.5"),
        ("three", "expected a whole number, got 'three'"),
    ],
)
def test_bad_placements_are_refused_naming_the_key(tmp_path, value, message):
    path = _screen(tmp_path, placements=value)
    with pytest.raises(ParcelfitError) as err:
        load_screen(path)
    assert (err.value.file, err.value.where, err.value.message) == (
        str(path),
        "placements",
        message,
    )


def test_a_simulator_without_seeded_placements_is_refused(tmp_path):
    path = _screen(
        tmp_path,
        simulator={"backend": "python", "factory": "tests.test_screening_placements:make_unplaced"},
    )
    with pytest.raises(ParcelfitError) as err:
        run_screen(load_screen(path), tmp_path / "out")
    assert (err.value.file, err.value.where) == (str(path), "placements")
    assert err.value.message.startswith("the Unplaced simulator has no seeded placements")
    store = Store(tmp_path / "out" / "screen.sqlite", readonly=True)
    assert store.evaluations("screen") == []  # nothing simulated
    store.close()


def test_a_study_ensemble_refuses_such_a_simulator_under_its_own_key(tmp_path):
    from parcelfit.study.joint import check_placements
    from parcelfit.study.studyfile import load_study

    from .helpers import write_study

    study = load_study(write_study(tmp_path, cost={"kind": "ensemble", "placements": 3}))
    with pytest.raises(ParcelfitError) as err:
        check_placements(study, Unplaced())
    assert (err.value.where, err.value.file) == ("cost.placements", str(study.path))
    check_placements(study, AnalyticSimulator())  # one that can place its runs


def test_the_screen_command_shows_the_ensemble_responses_beside_the_selection(
    tmp_path, monkeypatch
):
    from typer.testing import CliRunner

    from parcelfit.cli import app

    monkeypatch.setenv("SCREEN_PROBE", str(tmp_path / "probe"))
    two = {n: DESIGN[n] for n in ("mu_d_BePa", "mu_d_MePa")}
    path = _screen(tmp_path, parameters=two, placements=2)
    store = Store(tmp_path / "o" / "screen.sqlite")  # a screen with 5 stopped before simulating:
    store.set_meta("placements", 5)  # the folder takes another number
    store.close()
    result = CliRunner().invoke(app, ["screen", str(path), "--out", str(tmp_path / "o")])
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    assert "spin_share" in text and "median_rotation" in text
    assert "the selection is made on dtw_xy and dtw_theta" in text
    assert len(_probed(tmp_path / "probe")) == 4 * 2


def test_the_ensemble_example_is_the_published_protocol_over_five_placements():
    screen = load_screen(ROOT / "examples" / "e3-kpbw" / "screen-ensemble.yaml")
    assert screen.case == TestCase("E3", "KPBW", 2) and screen.placements == 5
    assert len(screen.parameters) == 16 and screen.stages == ("fractional", "full")
    assert screen.resolution == 4 and screen.dataset.name == "twin"
