import numpy as np
import pytest
import yaml

from parcelfit.runs import Run, TestCase, Trajectory, load_dataset
from parcelfit.sim.mujoco import load_rig
from parcelfit.study.store import Store, finished_count
from parcelfit.synth import TwinSettings, _placement, make_twin_dataset

# These tests check how twin datasets are made (scatter, determinism, cache), not the physics:
# a coarse step (about 1/1200 s, written as in a spec file) keeps them quick.
QUICK_STEP = 0.00083333


def test_twin_placements_scatter_like_the_rigs_hand_placement_unless_told_otherwise():
    # the model's ensemble draws its placements from the rig's start.scatter; a twin's "real"
    # runs must scatter alike, or the ensemble cost is not lowest at the truth
    rig = load_rig("E3")
    rng = np.random.default_rng(0)
    draws = np.array([_placement(rig, rng, TwinSettings()) for _ in range(4000)])
    u = rig.surface(rig.start.surface).unit()
    along = draws[:, 0] * u[0] + draws[:, 1] * u[1]
    across = -draws[:, 0] * u[1] + draws[:, 1] * u[0]
    # a standard normal clipped at 2.5 sd has sd 0.9887
    for values, sd in zip((along, across, draws[:, 2]), rig.start.scatter, strict=True):
        assert np.std(values) == pytest.approx(0.9887 * sd, rel=0.05)
        assert np.max(np.abs(values)) <= 2.5 * sd + 1e-12
        assert abs(np.mean(values)) < 0.1 * sd
    model = np.array([rig.placement(seed) for seed in range(4000)])
    assert np.std(model, axis=0) == pytest.approx(np.std(draws, axis=0), rel=0.08)
    # the twin's own stream: not the model's seeds (a twin must not replay the model's starts)
    assert not np.allclose(draws[:10], model[:10])
    jitter = TwinSettings(placement_sd=0.005, angle_sd=1.5)
    fixed = np.array([_placement(rig, rng, jitter) for _ in range(4000)])
    assert np.std(fixed, axis=0) == pytest.approx([0.005, 0.005, 1.5], rel=0.05)


QUICK = TwinSettings(runs=3, real_spacing=0.05, real_timestep=QUICK_STEP)
BW_TRUTH = {"BW": {"mu_d_BePa": 0.5}}


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    """Three twin runs of E1/BW/1 (seed 4): (folder, dataset path)."""
    folder = tmp_path_factory.mktemp("twin")
    path = make_twin_dataset(folder, [TestCase("E1", "BW", 1)], BW_TRUTH, settings=QUICK, seed=4)
    return folder, path


@pytest.mark.slow
@pytest.mark.mujoco
def test_twin_dataset_scatters_like_real_runs_and_keeps_the_truth(twin, tmp_path):
    folder, path = twin
    settings = QUICK
    ds = load_dataset(path)
    assert ds.synthetic and "SYNTHETIC" in ds.description
    runs = ds["E1/BW/1"].runs
    assert len(runs) == 3 and all(r.transit_time is not None for r in runs)
    starts = np.array([[r.trajectory.x[0], r.trajectory.y[0]] for r in runs])
    assert np.ptp(starts[:, 1]) > 1e-4  # placement jitter and tracking noise
    assert len({round(r.transit_time, 4) for r in runs}) == 3  # specimens and belt speeds differ
    truth = yaml.safe_load((folder / "truth.yaml").read_text())
    assert truth["synthetic"] and truth["truth"]["BW"]["mu_d_BePa"] == 0.5
    assert truth["settings"]["runs"] == 3 and truth["units"]["E_Pa"] == "N/mm^2"
    again = make_twin_dataset(
        tmp_path / "again",
        [TestCase("E1", "BW", 1)],
        BW_TRUTH,
        settings=settings,
        seed=4,
    )
    assert np.array_equal(
        load_dataset(again)["E1/BW/1"].runs[2].trajectory.xy, runs[2].trajectory.xy
    )


@pytest.mark.slow
@pytest.mark.mujoco
def test_synth_command_makes_the_dataset_from_a_spec(tmp_path):
    from typer.testing import CliRunner

    from parcelfit.cli import app

    spec = tmp_path / "spec.yaml"
    spec.write_text(
        "name: tiny\nseed: 2\ncases: [E1/BW/1]\ntruth: {BW: {mu_d_BePa: 0.5}}\n"
        "settings: {runs: 2, real_spacing: 0.05, real_timestep: 0.00083333}\n"
    )
    result = CliRunner().invoke(
        app, ["synth", str(spec), "--out", str(tmp_path / "out"), "--workers", "2"]
    )
    assert result.exit_code == 0, result.output
    ds = load_dataset(tmp_path / "out")
    assert ds.name == "tiny" and ds.synthetic and len(ds["E1/BW/1"].runs) == 2
    # the same runs whatever the number of processes
    again = make_twin_dataset(
        tmp_path / "serial",
        [TestCase("E1", "BW", 1)],
        {"BW": {"mu_d_BePa": 0.5}},
        settings=TwinSettings(runs=2, real_spacing=0.05, real_timestep=QUICK_STEP),
        seed=2,
        workers=1,
    )
    assert np.array_equal(
        load_dataset(again)["E1/BW/1"].runs[1].trajectory.xy, ds["E1/BW/1"].runs[1].trajectory.xy
    )


def test_synth_spec_errors_name_the_key(tmp_path):
    import pytest

    from parcelfit import ParcelfitError
    from parcelfit.synth import load_twin_spec

    spec = tmp_path / "spec.yaml"
    spec.write_text("cases: [E1/BW/1]\ntruth: {BW: {mu_d_BPa: 0.5}}\n")
    with pytest.raises(ParcelfitError, match="mu_d_BPa") as err:
        load_twin_spec(spec)
    assert "mu_d_BePa" in str(err.value) and "spec.yaml" in str(err.value)
    spec.write_text("cases: [E1-BW-1]\n")
    with pytest.raises(ParcelfitError, match=r"cases\[0\]"):
        load_twin_spec(spec)
    spec.write_text("cases: [E1/BW/1]\nsettings: {runz: 3}\n")
    with pytest.raises(ParcelfitError, match="runs"):
        load_twin_spec(spec)


def _noisy_run(job):
    """A twin run without physics whose samples use every digit (seeded noise on a straight
    ride along x at 1 m/s): (run, wall)."""
    rng = np.random.default_rng(job.seed)
    t = np.arange(90) / 60
    noise = rng.normal(0.0, 1e-3, (3, t.size))
    trajectory = Trajectory(t=t, x=t + noise[0], y=noise[1], theta=10 * noise[2])
    return Run(job.run_id, job.case, trajectory, 1.0 + rng.uniform(0.0, 0.1)), 0.1


def test_an_interrupted_twin_dataset_resumes_from_its_cache(tmp_path, monkeypatch):
    """The cache's bookkeeping, on twin runs without physics (`_noisy_run`)."""
    import parcelfit.synth as synth

    settings = QUICK
    real = _noisy_run
    calls = []

    def dies_on_the_third(job):
        calls.append(job.run_id)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(job)

    monkeypatch.setattr(synth, "_twin_run", dies_on_the_third)
    with pytest.raises(KeyboardInterrupt):
        make_twin_dataset(
            tmp_path / "d", [TestCase("E1", "BW", 1)], BW_TRUTH, settings=settings, seed=4
        )
    assert len(list((tmp_path / "d" / ".twin-runs").glob("*.csv"))) == 2
    # kept as a study keeps its evaluations: two finished rows in the twin's store
    assert finished_count(tmp_path / "d" / ".twin-runs" / "twin.sqlite", "twin") == 2
    calls.clear()
    monkeypatch.setattr(synth, "_twin_run", real)
    seen = []
    path = make_twin_dataset(
        tmp_path / "d",
        [TestCase("E1", "BW", 1)],
        BW_TRUTH,
        settings=settings,
        seed=4,
        progress=seen.append,
    )
    assert sum("from the cache" in e.message for e in seen) == 2 and len(seen) == 3
    assert [(e.job, e.done, e.total) for e in seen] == [("synth", k, 3) for k in (1, 2, 3)]
    assert not (tmp_path / "d" / ".twin-runs").exists()
    fresh = make_twin_dataset(  # the same dataset made in one go
        tmp_path / "fresh", [TestCase("E1", "BW", 1)], BW_TRUTH, settings=settings, seed=4
    )
    a, b = load_dataset(path)["E1/BW/1"].runs, load_dataset(fresh)["E1/BW/1"].runs
    assert all(
        np.allclose(x.trajectory.xy, y.trajectory.xy, atol=1e-9) for x, y in zip(a, b, strict=True)
    )


def _straight_run(job):
    """A twin run without physics (the parcel rides straight along x at 1 m/s): (run, wall)."""
    t = np.linspace(0.0, 1.0, 11)
    trajectory = Trajectory(t=t, x=t, y=0.0 * t, theta=0.0 * t)
    return Run(job.run_id, job.case, trajectory, 1.0 + job.seed.spawn_key[0] / 100), 0.1


def test_runs_kept_by_an_earlier_version_as_files_are_taken_over(tmp_path, monkeypatch):
    """An interrupted generation whose runs an earlier parcelfit kept as a CSV and a JSON per
    run (no store) resumes without simulating them again."""
    import parcelfit.synth as synth

    calls = []

    def dies_on_the_third(job):
        calls.append(job.run_id)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return _straight_run(job)

    monkeypatch.setattr(synth, "_twin_run", dies_on_the_third)
    case = TestCase("E1", "BW", 1)
    with pytest.raises(KeyboardInterrupt):
        make_twin_dataset(tmp_path / "d", [case], BW_TRUTH, settings=QUICK, seed=4)
    kept = tmp_path / "d" / ".twin-runs"
    store = Store(kept / "twin.sqlite")
    rows = store.evaluations("twin")
    store.close()
    assert [(r.slot, r.status) for r in rows] == [(0, "ok"), (1, "ok")]
    for r in rows:  # the earlier form: RUNID-KEY.csv beside RUNID-KEY.json, no store
        (kept / r.run_file).with_suffix(".json").write_text(f'{{"transit_time": {r.transit_time}}}')
    for f in kept.glob("twin.sqlite*"):
        f.unlink()
    calls.clear()
    monkeypatch.setattr(
        synth, "_twin_run", lambda job: calls.append(job.run_id) or _straight_run(job)
    )
    seen = []
    path = make_twin_dataset(
        tmp_path / "d", [case], BW_TRUTH, settings=QUICK, seed=4, progress=seen.append
    )
    assert calls == ["E1-BW-1-03"]
    assert [e.message.split(": ")[1] for e in seen[:2]] == [
        "from the cache (1/3)",
        "from the cache (2/3)",
    ]
    runs = load_dataset(path)["E1/BW/1"].runs
    assert [r.transit_time for r in runs] == pytest.approx([1.0, 1.01, 1.02], abs=1e-12)
    assert not kept.exists()


def test_the_twins_real_runs_take_their_own_time_step(tmp_path, monkeypatch):
    """``real_timestep`` reaches the scene of every twin run (default None: the model's own
    step on the rig, on E1 1/4800 s around BW's rigid content, 1/2400 s around PB's soft one,
    half the defaults elsewhere, which the dataset's description says),
    ``real_soft_timestep`` overrides it around a soft content only, and a spec outside
    [1e-5, 0.01] s is refused naming the key."""
    import pytest

    import parcelfit.synth as synth
    from parcelfit.sim.mujoco import load_consignment, load_rig

    seen = []

    class Recording:
        def __init__(self, options, rigs, consignments):
            soft = consignments[0].content_kind == "soft"
            seen.append(options.scene.step_for(soft=soft, rig=load_rig("E1")))

        def run(self, params, case, run_id=None):
            raise RuntimeError("stop here")

    monkeypatch.setattr(synth, "mujoco_simulator", Recording)
    for settings, consignment, step in (
        (TwinSettings(), "BW", 1 / 4800),
        (TwinSettings(), "PB", 1 / 2400),
        (TwinSettings(real_timestep=1 / 4800), "BW", 1 / 4800),
        (TwinSettings(real_timestep=1 / 4800), "PB", 1 / 4800),
        (TwinSettings(real_soft_timestep=1 / 2400), "BW", 1 / 4800),
        (TwinSettings(real_timestep=1 / 4800, real_soft_timestep=1 / 2400), "BW", 1 / 4800),
        (TwinSettings(real_timestep=1 / 4800, real_soft_timestep=1 / 2400), "PB", 1 / 2400),
    ):
        job = synth.TwinJob(
            "r1",
            TestCase("E1", consignment, 1),
            load_rig("E1"),
            load_consignment(consignment),
            {},
            settings,
            np.random.SeedSequence(1),
        )
        with pytest.raises(RuntimeError, match="stop here"):
            synth._twin_run(job)
        assert seen[-1] == pytest.approx(step, rel=1e-12)
    e1, e3 = load_rig("E1"), load_rig("E3")
    assert "divided by 2 on E1" in synth._refined_rigs(TwinSettings(), [e1, e3])
    assert synth._refined_rigs(TwinSettings(), [e3]) == ""
    both = TwinSettings(real_timestep=1 / 4800, real_soft_timestep=1 / 2400)
    assert synth._refined_rigs(both, [e1]) == ""
    _check_setting(tmp_path, "E1/BW/1", "real_timestep", 0.00041667, 0.1)
    _check_setting(tmp_path, "E1/BW/1", "real_soft_timestep", 0.00041667, -1)


def test_the_twins_real_runs_take_their_own_content_mesh(tmp_path, monkeypatch):
    """``real_content_spacing`` and ``real_ccd_tolerance`` reach the scene of every twin run
    (default None: the model's own), and a spec out of range is refused naming the key."""
    import pytest

    import parcelfit.synth as synth
    from parcelfit.sim.mujoco import SceneOptions, load_consignment, load_rig

    seen = []

    class Recording:
        def __init__(self, options, rigs, consignments):
            seen.append((options.scene.soft_spacing, options.scene.ccd_tolerance))

        def run(self, params, case, run_id=None):
            raise RuntimeError("stop here")

    monkeypatch.setattr(synth, "mujoco_simulator", Recording)
    for settings, expected in (
        (TwinSettings(), (SceneOptions().soft_spacing, None)),
        (TwinSettings(real_content_spacing=0.03, real_ccd_tolerance=1e-6), (0.03, 1e-6)),
    ):
        job = synth.TwinJob(
            "r1",
            TestCase("E3", "PB", 1),
            load_rig("E3"),
            load_consignment("PB"),
            {},
            settings,
            np.random.SeedSequence(1),
        )
        with pytest.raises(RuntimeError, match="stop here"):
            synth._twin_run(job)
        assert seen[-1] == expected
    _check_setting(tmp_path, "E3/PB/1", "real_content_spacing", 0.06, 0.5)
    _check_setting(tmp_path, "E3/PB/1", "real_ccd_tolerance", 1e-6, 0.5)


def _check_setting(tmp_path, case: str, key: str, good: float, bad: float) -> None:
    """A twin spec's ``settings.<key>`` reads back as written when ``good`` and is refused
    naming the key when ``bad``."""
    import pytest

    import parcelfit.synth as synth
    from parcelfit import ParcelfitError

    spec = tmp_path / "spec.yaml"
    spec.write_text(f"cases: [{case}]\nsettings: {{{key}: {good}}}\n")
    assert getattr(synth.load_twin_spec(spec).settings, key) == good
    spec.write_text(f"cases: [{case}]\nsettings: {{{key}: {bad}}}\n")
    with pytest.raises(ParcelfitError, match=key):
        synth.load_twin_spec(spec)
