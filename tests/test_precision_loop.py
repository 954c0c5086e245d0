"""A precision check's stored runs and table stay what they were when its simulations moved
onto the study loop (`parcelfit.study.loop`): tests/data/precision-loop holds them from the
earlier code, for the two-rig study of tests/test_precision.py at two placements."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest

from parcelfit.study.precision_check import PrecisionCheck, run_precision_check
from parcelfit.study.store import Store

from .test_precision import _two_rig_study

GOLDEN = Path(__file__).parent / "data" / "precision-loop" / "check.json"


def recorded(check: PrecisionCheck, out: Path) -> dict[str, Any]:
    """What is compared: the stored runs (in the order asked) and the check's precisions."""
    store = Store(out / "precision.sqlite", readonly=True)
    rows = store.evaluations("precision")
    store.close()
    return {
        "stored": [
            {
                "iteration": r.iteration,
                "slot": r.slot,
                "seed": r.seed,
                "setting": r.speed_setting,
                "status": r.status,
                "params": r.params,
                "transit_time": r.transit_time,
                "details": r.details.to_json(),
            }
            for r in rows
        ],
        "precision": [
            [title, p.joint.tolist(), p.alone.tolist(), p.alone_unresolved.tolist()]
            for title, p in check.rows()
        ],
        "simulations": [check.simulations, check.simulated_now],
    }


def run(tmp_path: Path) -> dict[str, Any]:
    """Run the check serially in ``tmp_path`` and record it."""
    study = _two_rig_study(tmp_path)
    check = run_precision_check(study, tmp_path / "out", placements=2, executor="serial")
    return recorded(check, tmp_path / "out")


def _close(got: Any, want: Any) -> bool:
    if isinstance(want, float) and isinstance(got, float):
        return math.isclose(got, want, rel_tol=1e-12, abs_tol=1e-15) or (
            math.isnan(got) and math.isnan(want)
        )
    if isinstance(want, dict) and isinstance(got, dict):
        return got.keys() == want.keys() and all(_close(got[k], want[k]) for k in want)
    if isinstance(want, list) and isinstance(got, list):
        return len(got) == len(want) and all(_close(g, w) for g, w in zip(got, want, strict=True))
    return got == want


def test_the_check_stores_and_judges_what_it_did(tmp_path):
    got = json.loads(json.dumps(run(tmp_path)))
    want = json.loads(GOLDEN.read_text())
    assert got["simulations"] == want["simulations"]
    assert len(got["stored"]) == len(want["stored"])
    for g, w in zip(got["stored"], want["stored"], strict=True):
        assert _close(g, w), (g, w)
    assert _close(got["precision"], want["precision"])


def test_a_check_whose_every_simulation_fails_stops_after_8_and_resumes_once_fixed(
    tmp_path, monkeypatch
):
    """The study loop's failure streak: 8 simulations failing in a row before the first
    success stop the check, quoting the first; the set-up fixed, a rerun simulates the failed
    ones again and the rest."""
    import yaml

    from parcelfit.errors import ParcelfitError

    study = _two_rig_study(tmp_path)
    doc = yaml.safe_load(study.read_text())
    doc["simulator"]["factory"] = "tests.fake_sim:make_broken"
    study.write_text(yaml.safe_dump(doc))
    out = tmp_path / "out"
    with pytest.raises(ParcelfitError) as err:
        run_precision_check(study, out, placements=2, executor="serial")
    assert err.value.message.startswith(
        "8 simulations in a row failed, so the run stopped early; the first: failed: "
        "RuntimeError: solver licence expired"
    )
    assert err.value.file == str(out)
    store = Store(out / "precision.sqlite", readonly=True)
    statuses = [e.status for e in store.evaluations("precision")]
    store.close()
    assert len(statuses) == 28 and statuses.count("failed") == 8 and statuses.count("ok") == 0
    monkeypatch.setenv("FAKE_SIM_FIXED", "1")
    check = run_precision_check(study, out, placements=2, executor="serial")
    assert check.simulated_now == check.simulations == 28
    store = Store(out / "precision.sqlite", readonly=True)
    rows = store.evaluations("precision")
    store.close()
    # the 8 failed runs again and the 20 never tried, in the rows they were stored in
    assert [e.status for e in rows] == ["ok"] * 28
    assert len({(e.details.case, json.dumps(e.params), e.seed) for e in rows}) == 28
