"""The speed benchmark's account of what fidelity costs (benchmarks/bench_sim.py --explain):
every cheaper configuration it times is a valid scene that differs from the default, and every
type with a target has one."""

from __future__ import annotations

import re
from dataclasses import asdict
from pathlib import Path

import pytest

from parcelfit.sim.mujoco import SceneOptions
from parcelfit.sim.mujoco.options import parse_scene_options

from .helpers import load_file_module

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    return load_file_module("benchmarks/bench_sim.py")


def test_every_type_with_a_target_says_what_its_fidelity_costs(bench) -> None:
    assert set(bench.FIDELITY) == set(bench.BUDGET)
    for cons, choices in bench.FIDELITY.items():
        assert choices, cons
        for options, why in choices:
            cheaper = SceneOptions(**parse_scene_options(options))
            changed = {k for k, v in asdict(cheaper).items() if v != asdict(SceneOptions())[k]}
            assert changed == set(parse_scene_options(options)), (cons, options)
            notes = re.findall(r"docs/research/[\w./-]+\.md", why)
            assert notes and all((ROOT / n).is_file() for n in notes), (cons, why)
