import numpy as np
import pytest

from parcelfit import ParcelfitError
from parcelfit.optimize import BatchBO, BOSettings, Dimension, Space


def test_space_round_trip_linear_and_log():
    space = Space([Dimension("mu", 0.3, 0.6), Dimension("k", 1e5, 1e6, log=True)])
    p = {"mu": 0.45, "k": 10**5.5}
    u = space.to_unit(p)
    assert u == pytest.approx([0.5, 0.5])
    back = space.from_unit(u)
    assert back["mu"] == pytest.approx(0.45) and back["k"] == pytest.approx(10**5.5)
    assert space.to_unit({"mu": 9.0, "k": 1.0}).tolist() == [1.0, 0.0]
    with pytest.raises(ParcelfitError, match="log scale needs low > 0"):
        Dimension("x", 0.0, 1.0, log=True)
    with pytest.raises(ParcelfitError, match="low < high"):
        Dimension("x", 1.0, 1.0)
    with pytest.raises(ParcelfitError, match="parameters missing"):
        space.to_unit({"mu": 0.4})
    assert Space.from_bounds({"a": (0, 1), "b": {"low": 1, "high": 10, "log": True}}).dims[1].log


def test_initial_design_is_a_latin_hypercube():
    bo = BatchBO(Space.from_bounds({"a": (0, 1), "b": (0, 1), "c": (0, 1)}), batch_size=4, seed=3)
    pts = np.array([[p["a"], p["b"], p["c"]] for _ in range(4) for p in bo.ask()])
    assert pts.shape == (16, 3)
    for j in range(3):
        assert sorted(np.floor(pts[:, j] * 16).astype(int).tolist()) == list(range(16))


def _quadratic(p):
    return (p["a"] - 0.3) ** 2 + (p["b"] - 0.7) ** 2 + 0.5 * (p["c"] - 0.5) ** 2


def _run(seed, n_batches, settings=None):
    bo = BatchBO(
        Space.from_bounds({"a": (0, 1), "b": (0, 1), "c": (0, 1)}),
        batch_size=4,
        seed=seed,
        settings=settings or BOSettings(n_samples=1000, n_restarts=1),
    )
    asked = []
    for _ in range(n_batches):
        batch = bo.ask()
        asked.append(batch)
        for p in batch:
            bo.tell(p, _quadratic(p))
    return bo, asked


@pytest.mark.slow
def test_same_seed_same_batches_and_batches_are_diverse():
    _, a = _run(5, 6)
    _, b = _run(5, 6)
    assert a == b
    _, c = _run(6, 6)
    assert a != c
    last = np.array([[p["a"], p["b"], p["c"]] for p in a[-1]])
    dists = np.linalg.norm(last[:, None] - last[None], axis=2)[np.triu_indices(4, 1)]
    assert dists.min() > 1e-3


@pytest.mark.slow
def test_converges_on_a_smooth_function_and_beats_its_initial_design():
    bo, _ = _run(1, 12)
    initial_best = min(o.cost for o in bo.observations[:16])
    params, cost = bo.best()
    assert cost < 0.01 < initial_best
    assert params["a"] == pytest.approx(0.3, abs=0.1) and params["b"] == pytest.approx(0.7, abs=0.1)


def test_pending_points_are_not_asked_twice():
    bo, _ = _run(2, 5)
    first, second = bo.ask(), bo.ask()
    u1 = np.array([bo.space.to_unit(p) for p in first])
    u2 = np.array([bo.space.to_unit(p) for p in second])
    assert np.min(np.linalg.norm(u1[:, None] - u2[None], axis=2)) > 1e-3


def test_failures_are_penalised_not_fatal():
    bo = BatchBO(
        Space.from_bounds({"a": (0, 1), "b": (0, 1)}),
        batch_size=4,
        seed=0,
        settings=BOSettings(n_initial=8, n_samples=500, n_restarts=0),
    )
    for _i in range(4):
        for p in bo.ask():
            bo.tell(p, None if p["a"] > 0.8 else p["a"] + p["b"])
    assert all(o.cost is None or np.isfinite(o.cost) for o in bo.observations)
    assert any(o.cost is None for o in bo.observations)
    assert bo.best()[1] == min(o.cost for o in bo.observations if o.cost is not None)
    assert len(bo.ask()) == 4


def test_replaying_tells_gives_the_same_next_batch():
    bo, _asked = _run(9, 6)
    fresh = BatchBO(bo.space, batch_size=4, seed=9, settings=bo.settings)
    for o in bo.observations:  # as a resumed study replays its store
        fresh.tell(o.params, o.cost)
    assert fresh.ask() == bo.ask()
