"""A screen's stored responses and written tables stay what they were when its evaluation loop
moved onto `parcelfit.study.loop` (tests/data/screen-loop holds them from the earlier code):
one nominal placement with centre points, and two placements with a transit-less seed (its
effects table since gained the mean transit time's rows, appended to the earlier code's)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
import yaml

from parcelfit.study.screening import load_screen, run_screen
from parcelfit.study.store import Store

from .fake_sim import write_reference_dataset

GOLDEN = Path(__file__).parent / "data" / "screen-loop"
DESIGN = {"mu_d_BePa": [0.3, 0.58], "mu_d_MePa": [0.15, 0.35], "E_Pa": [200, 1600]}
CASES = {
    "k1": {
        "simulator": {"backend": "python", "factory": "tests.fake_sim:make"},
        "parameters": {**DESIGN, "nu_Pa": [0.2, 0.45]},
        "stages": ["fractional", "full"],
        "centre_points": 1,
    },
    "k2": {
        "simulator": {"backend": "python", "factory": "tests.test_screening_placements:make_probe"},
        "parameters": DESIGN,
        "stages": ["full"],
        "placements": 2,
    },
}
TABLES = ("stage1-design.csv", "stage1-effects.csv")


def stored(out: Path) -> list[dict[str, Any]]:
    """The store's screen rows, as compared: what identifies them and their responses."""
    store = Store(out / "screen.sqlite", readonly=True)
    rows = store.evaluations("screen")
    store.close()
    return [
        {
            "iteration": r.iteration,
            "slot": r.slot,
            "seed": r.seed,
            "status": r.status,
            "params": r.params,
            "dtw_xy": r.dtw_xy,
            "dtw_theta": r.dtw_theta,
            "transit_time": r.transit_time,
            "run_file": r.run_file,
        }
        for r in rows
    ]


def run(tmp_path: Path, case: str, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Run the screen ``case`` serially in ``tmp_path``; its output folder."""
    monkeypatch.setenv("SCREEN_PROBE", str(tmp_path / "probe"))
    write_reference_dataset(tmp_path / "data")
    doc = {
        "name": case,
        "reference": {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1},
        "executor": "serial",
        **CASES[case],
    }
    path = tmp_path / "screen.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    run_screen(load_screen(path), tmp_path / "out")
    return tmp_path / "out"


def _close(got: Any, want: Any) -> bool:
    if isinstance(want, float) and isinstance(got, float):
        return math.isclose(got, want, rel_tol=1e-12, abs_tol=1e-15)
    if isinstance(want, dict) and isinstance(got, dict):
        return got.keys() == want.keys() and all(_close(got[k], want[k]) for k in want)
    return got == want


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_screen_stores_and_writes_what_it_did(tmp_path, monkeypatch, case):
    out = run(tmp_path, case, monkeypatch)
    want = json.loads((GOLDEN / case / "stored.json").read_text())
    got = stored(out)
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        assert _close(g, w), (g, w)
    for name in TABLES + (("stage2-design.csv", "stage2-effects.csv") if case == "k1" else ()):
        pd.testing.assert_frame_equal(
            pd.read_csv(out / name),
            pd.read_csv(GOLDEN / case / name),
            check_exact=False,
            rtol=1e-10,
        )
    assert (out / "selection.yaml").read_text() == (GOLDEN / case / "selection.yaml").read_text()


def test_a_fixed_design_asks_its_rows_in_order_and_is_done_when_all_are_told():
    from parcelfit.study.loop import FixedDesign

    design = FixedDesign([{"a": float(i)} for i in range(5)])
    assert design.ask(2) == [{"a": 0.0}, {"a": 1.0}]
    assert design.ask() == [{"a": 2.0}, {"a": 3.0}, {"a": 4.0}] and design.ask() == []
    for i in range(4):
        design.tell({"a": float(i)}, None if i == 1 else 1.0)
    assert not design.done and design.n_told == 4
    design.tell({"a": 4.0}, 2.0)
    assert design.done
