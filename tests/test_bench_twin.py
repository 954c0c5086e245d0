"""The twin benchmark's plumbing (benchmarks/bench_twin.py) on the analytic test simulator:
three hidden truths, the published and a joint ensemble setup, a tiny budget."""

import pytest

from parcelfit.sim.params import CATALOGUE

from .fake_sim import write_reference_dataset
from .helpers import load_file_module

SPECS = {p.name: p for p in CATALOGUE}


def _bench():
    return load_file_module("benchmarks/bench_twin.py")


@pytest.mark.slow
def test_the_twin_benchmark_runs_end_to_end_on_the_fake_simulator(tmp_path):
    bench = _bench()
    parameters = {"mu_d_BePa": [0.3, 0.55], "mu_d_MePa": [0.15, 0.35], "E_Pa": [200, 1600]}
    truths = {
        f"truth{k + 1}": bench.truth_values(f, parameters)
        for k, f in enumerate([(0.7, 0.3, 0.5), (0.3, 0.6, 0.7), (0.5, 0.8, 0.3)])
    }

    def make_dataset(folder, truth, seed):
        si = {n: SPECS[n].to_si(v) for n, v in truth.items()}
        write_reference_dataset(folder, rigs=("R", "Q"), truth=si, seed=seed)
        return folder

    setups = [
        bench.Setup(
            "published",
            {
                "reference": {"dataset": "{dataset}", "rig": "R", "speed_setting": 1},
                "validation": {"speed_setting": 2, "every": 1},
            },
        ),
        bench.Setup(
            "joint",
            {
                "cases": [
                    {"dataset": "{dataset}", "rig": "R", "speed_setting": 1},
                    {"rig": "Q", "speed_setting": 1},
                ],
                "validation": {"every": 1, "cases": [{"rig": "R", "speed_setting": 2}]},
                "transfer": [{"rig": "Q", "speed_setting": 2}],
                "cost": {"kind": "ensemble", "placements": 2},
            },
        ),
    ]
    rows = bench.run(
        truths,
        setups,
        make_dataset,
        {"backend": "python", "factory": "tests.fake_sim:make", "consignment": "P"},
        parameters,
        tmp_path,
        to_si=lambda n, v: SPECS[n].to_si(v),
        extra={
            "initial": 8,
            "batch_size": 2,
            "budget": 10,
            "optimizer": {"n_samples": 500, "n_restarts": 0},
            "executor": "serial",
        },
        figures=False,
        say=lambda _: None,
    )
    assert [(r.truth, r.setup) for r in rows] == [
        (t, s) for t in truths for s in ("published", "joint")
    ]
    for r in rows:
        assert r.evaluations == 10 and r.parameters == 3 and r.minutes > 0
        # honest intervals: every interval holds the truth, every determined value is close
        assert r.covered == 3, r.details
        assert r.determined_within == r.determined, r.details
    joint = [r for r in rows if r.setup == "joint"]
    assert all(r.transfer.endswith("/1") for r in joint)
    assert all(r.simulations >= 10 * 2 * 2 for r in joint)  # 2 cases x 2 placements each
    text = (tmp_path / "results.md").read_text()
    assert text.count("| truth | setup |") == 1 and text.count("| joint |") == 3


def test_the_benchmark_reads_the_parameters_to_calibrate_and_refuses_bad_ones():
    bench = _bench()
    assert bench.parse_ranges(["t_Pa=0.2:1", "E_Pa=200:1600"]) == {
        "t_Pa": [0.2, 1.0],
        "E_Pa": [200.0, 1600.0],
    }
    for bad, says in (
        ("t_Pa=0.2", "NAME=LOW:HIGH"),
        ("x_Pa=1:2", "not a catalogue parameter"),
        ("t_Pa=1:0.2", "LOW must be below HIGH"),
    ):
        with pytest.raises(SystemExit, match=says):
            bench.parse_ranges([bad])


def test_a_rig_s_own_time_step_is_read_as_a_fraction_and_bad_ones_are_refused():
    import argparse

    bench = _bench()
    assert bench._rig_step("E1=1/4800") == ("E1", 1 / 4800)
    assert bench._rig_step("E2a=0.0002") == ("E2a", 0.0002)
    for bad in ("E1", "=1/4800", "E1=fast", "E1=1/0"):
        with pytest.raises(argparse.ArgumentTypeError):
            bench._rig_step(bad)


def test_the_joint_setups_give_e1_its_own_placements_when_asked(tmp_path):
    bench = _bench()
    same = {s.name: s for s in bench.mujoco_setups(4, 60)}
    assert set(same) == {"published", "joint", "joint-adjusted"}
    assert all("placements" not in c for c in same["joint"].keys["cases"])
    own = {s.name: s for s in bench.mujoco_setups(4, 60, e1_placements=2)}
    assert set(own) == {"published", "joint-e1x2", "joint-adjusted-e1x2"}
    # --setups names the kind, whatever suffix the name carries
    assert {n: s.kind for n, s in own.items()} == {
        "published": "published",
        "joint-e1x2": "joint",
        "joint-adjusted-e1x2": "joint-adjusted",
    }
    assert all(s.kind == n for n, s in same.items())
    for name in ("joint-e1x2", "joint-adjusted-e1x2"):
        e3, e1 = own[name].keys["cases"]
        assert (e3.get("placements"), e1["rig"], e1["placements"]) == (None, "E1", 2)
        assert own[name].keys["cost"]["placements"] == 4
    # the study file it writes reads back with E1's own placements
    from parcelfit.study.joint import simulations_per_evaluation
    from parcelfit.study.studyfile import load_study

    write_reference_dataset(tmp_path / "data", rigs=("E3", "E1"))
    path = bench.write_study_file(
        tmp_path,
        own["joint-adjusted-e1x2"],
        {"backend": "python", "factory": "tests.fake_sim:make", "consignment": "KPBW"},
        {"mu_d_BePa": [0.3, 0.6]},
        tmp_path / "data",
        seed=1,
    )
    study = load_study(path)
    assert [c.placements for c in study.cases] == [None, 2]
    assert simulations_per_evaluation(study) == 4 + 2


def test_the_benchmark_counts_each_case_s_own_placements(tmp_path):
    import yaml

    from parcelfit.study.calibration import Calibration
    from parcelfit.study.studyfile import load_study

    bench = _bench()
    write_reference_dataset(tmp_path / "data", rigs=("R", "Q"))
    doc = {
        "name": "own",
        "simulator": {"backend": "python", "factory": "tests.fake_sim:make", "consignment": "P"},
        "parameters": {"mu_d_BePa": [0.3, 0.55], "mu_d_MePa": [0.15, 0.35], "E_Pa": [200, 1600]},
        "cases": [
            {"dataset": "data", "rig": "R", "speed_setting": 1},
            {"rig": "Q", "speed_setting": 1, "placements": 1},
        ],
        "cost": {"kind": "ensemble", "placements": 3},
        "initial": 4,
        "batch_size": 2,
        "budget": 4,
        "optimizer": {"n_samples": 200, "n_restarts": 0},
        "executor": "serial",
    }
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(doc))
    Calibration(load_study(path), tmp_path / "out", figures=False).run()
    truth = {"mu_d_BePa": 0.4, "mu_d_MePa": 0.25, "E_Pa": 8e8}
    a = bench.assess(tmp_path / "out", truth)
    assert a["evaluations"] == 4 and a["fit_simulations"] == 4 * (3 + 1)
    assert a["simulations"] >= a["fit_simulations"]
