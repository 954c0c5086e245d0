"""The speed benchmark's account of what fidelity costs (benchmarks/bench_sim.py --explain):
every cheaper configuration it times builds a different scene from the type's default one and
names the note that measured it, and its per-window means are the steps' own."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from parcelfit.runs import TestCase
from parcelfit.sim.mujoco import MujocoSimulator, SceneOptions, SimOptions
from parcelfit.sim.mujoco.options import parse_scene_options

from .helpers import load_file_module

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    return load_file_module("benchmarks/bench_sim.py")


def test_every_type_with_a_target_says_what_its_fidelity_costs(bench) -> None:
    assert set(bench.FIDELITY) == set(bench.BUDGET)
    default_sim = MujocoSimulator(SimOptions(scene=SceneOptions()))
    for cons, choices in bench.FIDELITY.items():
        assert choices, cons
        default_xml = default_sim.scene({}, TestCase("E3", cons, 1)).xml
        for choice in choices:
            cheaper = SceneOptions(**parse_scene_options(choice.cheaper))
            xml = MujocoSimulator(SimOptions(scene=cheaper)).scene({}, TestCase("E3", cons, 1)).xml
            # the type's own default (e.g. KP/BW's 5 x 5 x 1 shell from its consignment file)
            # is not a cheaper configuration: the scene must change
            assert xml != default_xml, (cons, choice.cheaper)
            notes = re.findall(r"docs/research/[\w./-]+\.md", choice.why)
            assert notes and all((ROOT / n).is_file() for n in notes), (cons, choice.why)


def test_a_cheaper_configuration_that_is_the_type_default_is_caught(bench) -> None:
    # KP/BW's own shell: the same scene as its default, which the test above must refuse
    default = MujocoSimulator(SimOptions(scene=SceneOptions()))
    same = MujocoSimulator(
        SimOptions(scene=SceneOptions(**parse_scene_options(["shell_cells=5,5,1"])))
    )
    case = TestCase("E3", "KPBW", 1)
    assert same.scene({}, case).xml == default.scene({}, case).xml


def test_window_means_are_the_steps_own_means(bench) -> None:
    iterations = [1, 3, 5, 7, 9]
    contacts = [10, 10, 20, 20, 30]
    by_hand = [0, 1, 1, 0, 1]
    # 0.02 s windows of 0.01 s steps: two steps each, the last window one step
    rows = bench.window_means(iterations, contacts, by_hand, 0.01, 0.02)
    assert [(r[2], r[3], r[4], r[5]) for r in rows] == [
        (2, 2.0, 10.0, 1),
        (2, 6.0, 20.0, 1),
        (1, 9.0, 30.0, 1),
    ]
    assert [t for r in rows for t in r[:2]] == pytest.approx([0.0, 0.02, 0.02, 0.04, 0.04, 0.05])
    # a window shorter than a step is one step
    assert len(bench.window_means(iterations, contacts, by_hand, 0.01, 0.001)) == 5


@pytest.fixture(scope="module")
def machine():
    return load_file_module("benchmarks/machine_load.py")


def test_busy_seconds_count_the_busy_ticks_of_proc_stat(machine) -> None:
    # user nice system idle iowait irq softirq steal guest guest_nice
    line = "cpu  100 20 30 5000 40 5 6 7 50 0"
    assert machine.busy_seconds(line, 100.0) == pytest.approx((100 + 20 + 30 + 5 + 6 + 7) / 100.0)
    # an older kernel's shorter line: the missing fields count 0
    assert machine.busy_seconds("cpu 10 0 10 500", 10.0) == pytest.approx(2.0)
    with pytest.raises(ValueError, match="cpu line"):
        machine.busy_seconds("cpu0 1 2 3 4", 100.0)


def test_other_cores_subtract_this_process(machine) -> None:
    # 10 s of wall, all cores busy 13 CPU s, 10 of them this process's: 0.3 cores of other work
    assert machine.other_cores(13.0, 10.0, 10.0) == pytest.approx(0.3)
    # the kernel's ticks and the process's clock disagree by rounding: never below 0
    assert machine.other_cores(9.99, 10.0, 10.0) == 0.0
    assert machine.other_cores(5.0, 1.0, 0.0) == 0.0


def test_the_machine_line_warns_when_the_timing_lost_time_on_its_core(machine) -> None:
    limit, share = machine.OTHER_WORK_LIMIT, machine.OWN_SHARE_MIN
    assert (
        machine.report_machine("while timing X", 0.99, 0.05, 1)
        == "while timing X: this process 0.99 of a core, other work 0.05 cores"
    )
    # one busy process on the one core left free (2 cores, one benchmark process)
    assert "WARNING" not in machine.report_machine("t", 0.99, 1.0, 1)
    # other work beyond the free cores, just above and at the limit
    assert "WARNING" in machine.report_machine("t", 0.99, 1 + limit + 1e-6, 1)
    assert "WARNING" not in machine.report_machine("t", 0.99, 1 + limit, 1)
    assert "WARNING" in machine.report_machine("t", 0.99, limit + 1e-6, 0)
    # this process's own share of its core, just below and at the least allowed
    assert "WARNING" in machine.report_machine("t", share - 1e-6, 0.0, 1)
    assert "WARNING" not in machine.report_machine("t", share, 0.0, 1)
    # a multi-process run: no share of its own; other work not measurable
    line = machine.report_machine("t", None, None, 1)
    assert line == "t: other work not measured"


def test_the_processor_is_described_by_model_family_and_clock(machine) -> None:
    fields = {"model name": "AMD EPYC", "cpu family": "26", "model": "2", "cpu MHz": "2596.122"}
    assert machine.describe_processor(fields) == "AMD EPYC (family 26, model 2, 2596 MHz)"
    assert machine.describe_processor({"model name": "X"}) == "X"
    # an ARM core's /proc/cpuinfo names no model: the platform's word is taken instead
    assert machine.describe_processor({"CPU implementer": "0x41"}) == ""


def test_other_work_counts_the_busy_time_beside_this_process(machine, monkeypatch) -> None:
    busy = iter([100.0, 106.0])  # all cores' busy CPU s at the start and the end
    own = iter([1.0, 5.0])  # this process's CPU s
    clock = iter([50.0, 60.0])  # wall clock [s]
    monkeypatch.setattr(machine, "_read_busy", lambda: next(busy))
    monkeypatch.setattr(machine, "_own_cpu", lambda: next(own))
    monkeypatch.setattr(machine, "_clock", lambda: next(clock))
    # 6 busy CPU s in 10 s, 4 of them this process's: 0.2 cores of other work
    assert machine.Watch().cores() == pytest.approx(0.2)
    monkeypatch.setattr(machine, "_read_busy", lambda: None)
    monkeypatch.setattr(machine, "_own_cpu", lambda: 0.0)
    monkeypatch.setattr(machine, "_clock", lambda: 0.0)
    assert machine.Watch().cores() is None


def test_other_work_now_watches_while_this_process_waits(machine, monkeypatch) -> None:
    busy = iter([10.0, 11.5])
    clock = iter([0.0, 2.0])
    slept: list[float] = []
    monkeypatch.setattr(machine, "_read_busy", lambda: next(busy))
    monkeypatch.setattr(machine, "_own_cpu", lambda: 3.0)
    monkeypatch.setattr(machine, "_clock", lambda: next(clock))
    monkeypatch.setattr(machine, "_sleep", slept.append)
    # 1.5 busy CPU s in 2 s, none of them this process's
    assert machine.other_work_now(2.0) == pytest.approx(0.75)
    assert slept == [2.0]


def test_the_own_share_is_cpu_time_over_wall_time(machine, monkeypatch) -> None:
    own = iter([2.0, 2.9])
    clock = iter([0.0, 1.0])
    monkeypatch.setattr(machine, "_read_busy", lambda: 0.0)
    monkeypatch.setattr(machine, "_own_cpu", lambda: next(own))
    monkeypatch.setattr(machine, "_clock", lambda: next(clock))
    assert machine.Watch().own_share() == pytest.approx(0.9)


def test_installed_names_each_version_and_what_is_missing(machine) -> None:
    line = machine.installed(("numpy", "no-such-package-parcelfit"))
    import numpy

    assert line.startswith("Python ")
    assert f"numpy {numpy.__version__}" in line
    assert "no-such-package-parcelfit not installed" in line
