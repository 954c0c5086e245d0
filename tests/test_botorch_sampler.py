"""The botorch and optuna-gp samplers (skipped where torch / BoTorch are not installed) and the
refusals that need neither."""

import sys

import pytest

from parcelfit import ParcelfitError
from parcelfit.optimize import Dimension, Space
from parcelfit.optimize.sampler import Sampler, make_sampler

SPACE = Space([Dimension("a", 0.0, 1.0), Dimension("b", 1e-3, 1.0, log=True)])
FAST = {"num_restarts": 2, "raw_samples": 32, "mc_samples": 64}  # small: the test's CPU time


def _cost(p):
    """A quadratic in the unit cube of SPACE, minimum 0 at a = 0.3, log10 b = -1 (u_b = 2/3)."""
    import math

    return (p["a"] - 0.3) ** 2 + ((math.log10(p["b"]) + 1.0) / 3.0) ** 2


def _run(name, batches, n_initial=4, fail_above=None, **options):
    sampler = make_sampler(
        name, SPACE, batch_size=2, seed=5, n_initial=n_initial, options=options or None
    )
    told = []
    for _ in range(batches):
        batch = sampler.ask()
        for p in batch:
            cost = None if fail_above is not None and p["a"] > fail_above else _cost(p)
            sampler.tell(p, cost)
            told.append((p, cost))
    return sampler, told


@pytest.mark.slow
def test_botorch_batches_are_deterministic_and_a_replay_asks_the_same():
    pytest.importorskip("botorch")
    first, told = _run("botorch", 4, fail_above=0.95, **FAST)  # two model-based batches
    second, _ = _run("botorch", 4, fail_above=0.95, **FAST)
    assert isinstance(first, Sampler) and first.n_told == 8
    batch = first.ask()
    assert second.ask() == batch
    assert len({tuple(p.values()) for p in batch}) == 2
    assert all(0.0 <= p["a"] <= 1.0 and 1e-3 <= p["b"] <= 1.0 for p in batch)
    resumed = make_sampler("botorch", SPACE, batch_size=2, seed=5, n_initial=4, options=FAST)
    for p, c in told:  # as a resumed study replays its store
        resumed.tell(p, c)
    assert resumed.ask() == batch
    other = make_sampler("botorch", SPACE, batch_size=2, seed=6, n_initial=4, options=FAST)
    for p, c in told:
        other.tell(p, c)
    assert other.ask() != batch  # the seed matters


@pytest.mark.slow
def test_botorch_finds_a_quadratics_minimum():
    pytest.importorskip("botorch")
    sampler, told = _run("botorch", 10, n_initial=6, num_restarts=4, raw_samples=128)
    params, cost = sampler.best()
    assert cost == min(c for _, c in told)
    assert cost < 2e-3  # the LHS alone: about 0.01-0.05
    assert params["a"] == pytest.approx(0.3, abs=0.05)
    assert params["b"] == pytest.approx(0.1, rel=0.4)
    rec_params, rec_cost = sampler.recommend()
    assert rec_cost == _cost(rec_params) and rec_cost < 5e-3


@pytest.mark.slow
def test_optuna_gp_batches_are_deterministic_and_a_replay_asks_the_same():
    pytest.importorskip("optuna")
    pytest.importorskip("torch")
    first, told = _run("optuna-gp", 6, fail_above=0.95)
    second, _ = _run("optuna-gp", 6, fail_above=0.95)
    batch = first.ask()
    assert second.ask() == batch and len({tuple(p.values()) for p in batch}) == 2
    resumed = make_sampler("optuna-gp", SPACE, batch_size=2, seed=5, n_initial=4)
    for p, c in told:
        resumed.tell(p, c)
    assert resumed.ask() == batch
    assert first.best()[1] == min(c for _, c in told if c is not None)


def test_without_botorch_the_error_names_the_extra(monkeypatch):
    for name in ["botorch", *(m for m in sys.modules if m.startswith("botorch."))]:
        monkeypatch.setitem(sys.modules, name, None)  # importing it raises ImportError
    with pytest.raises(ParcelfitError, match=r"the botorch optimizer needs the 'botorch' extra"):
        make_sampler("botorch", SPACE)
    pytest.importorskip("optuna")
    monkeypatch.setitem(sys.modules, "torch", None)
    with pytest.raises(ParcelfitError, match=r"the optuna-gp optimizer needs the 'botorch' extra"):
        make_sampler("optuna-gp", SPACE)


def test_a_study_file_names_botorch_and_optuna_gp_without_settings(tmp_path):
    from parcelfit.study.studyfile import load_study

    from .test_calibration import write_study

    for name in ("botorch", "optuna-gp"):
        assert load_study(write_study(tmp_path, optimizer={"sampler": name})).sampler == name
        with pytest.raises(ParcelfitError, match=r"optimizer: unknown key 'n_samples'"):
            load_study(write_study(tmp_path, optimizer={"sampler": name, "n_samples": 10}))
