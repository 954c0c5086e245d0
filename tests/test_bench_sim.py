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
