"""Optuna's samplers (TPE, GPSampler) behind the `Sampler` interface, through Optuna's own
ask/tell.

Optuna's in-memory study holds the trials only while the process runs; the calibration store
stays the record. Points told without having been asked (a resumed study replaying its store)
are added as finished trials. Determinism: before every ask the sampler is rebuilt with a seed
derived from (seed, number of told points, number of pending points), so the same history gives
the same batch whether it was lived or replayed. Pending points are Optuna's running trials,
which TPE's ``constant_liar`` keeps the next asks away from and GPSampler conditions its
q-batch log expected improvement on. Failed evaluations are told as failed trials, which both
leave out. GPSampler (``kind="gp"``, ``sampler: optuna-gp`` in a study file) needs PyTorch
(the ``botorch`` extra installs it).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from parcelfit.errors import ParcelfitError, missing_extra
from parcelfit.optimize.space import Space


class OptunaSampler:
    """Optuna's TPE (``kind="tpe"``) or GPSampler (``kind="gp"``) as a batch ask/tell optimiser
    that minimises a cost; ``n_startup_trials`` random points come first."""

    def __init__(
        self,
        space: Space,
        batch_size: int = 4,
        seed: int = 0,
        kind: str = "tpe",
        n_startup_trials: int = 10,
    ) -> None:
        try:
            import optuna
        except ImportError as exc:
            raise missing_extra("optuna", exc, extra="optuna", what="the tpe optimizer") from exc
        if kind not in ("tpe", "gp"):
            raise ParcelfitError(f"unknown Optuna sampler {kind!r}", fix="use tpe or gp")
        if kind == "gp":
            try:
                import torch  # noqa: F401 - Optuna's GPSampler imports it when it first samples
            except ImportError as exc:
                raise missing_extra(
                    "torch", exc, extra="botorch", what="the optuna-gp optimizer"
                ) from exc
        self.kind = kind
        optuna.logging.set_verbosity(optuna.logging.WARNING)
        self._optuna = optuna
        self.space = space
        self.batch_size = batch_size
        self.seed = seed
        self.n_startup_trials = n_startup_trials
        self._study = optuna.create_study(direction="minimize")
        self._dists = {
            d.name: optuna.distributions.FloatDistribution(d.low, d.high, log=d.log)
            for d in space.dims
        }
        self._pending: list[tuple[Any, dict[str, float]]] = []
        self._told: list[tuple[dict[str, float], float | None]] = []

    @property
    def n_told(self) -> int:
        """How many evaluations were told."""
        return len(self._told)

    def ask(self, n: int | None = None) -> list[dict[str, float]]:
        """The next ``n`` parameter sets to evaluate (default: the batch size)."""
        n = self.batch_size if n is None else n
        out = []
        for _ in range(n):
            seed = np.random.SeedSequence([self.seed, len(self._told), len(self._pending)])
            state = int(seed.generate_state(1)[0])
            if self.kind == "gp":
                self._study.sampler = self._optuna.samplers.GPSampler(
                    seed=state,
                    n_startup_trials=self.n_startup_trials,
                    warn_independent_sampling=False,
                )
            else:
                self._study.sampler = self._optuna.samplers.TPESampler(
                    seed=state, constant_liar=True, n_startup_trials=self.n_startup_trials
                )
            trial = self._study.ask(self._dists)
            params = {k: float(trial.params[k]) for k in self.space.names}
            self._pending.append((trial, params))
            out.append(params)
        return out

    def tell(self, params: Mapping[str, float], cost: float | None) -> None:
        """Report an evaluated parameter set's cost (None or non-finite: failed)."""
        ok = cost is not None and math.isfinite(cost)
        state = self._optuna.trial.TrialState
        for i, (trial, asked) in enumerate(self._pending):
            if all(math.isclose(asked[k], float(params[k]), rel_tol=1e-12) for k in asked):
                del self._pending[i]
                if ok:
                    self._study.tell(trial, float(cost))  # type: ignore[arg-type]
                else:
                    self._study.tell(trial, state=state.FAIL)
                break
        else:  # replayed from a store
            self._study.add_trial(
                self._optuna.trial.create_trial(
                    params={k: float(params[k]) for k in self.space.names},
                    distributions=self._dists,
                    value=float(cost) if ok else None,  # type: ignore[arg-type]
                    state=state.COMPLETE if ok else state.FAIL,
                )
            )
        self._told.append((dict(params), float(cost) if ok else None))  # type: ignore[arg-type]

    def best(self) -> tuple[dict[str, float], float] | None:
        """The evaluated parameters with the lowest cost, and that cost."""
        ok = [(p, c) for p, c in self._told if c is not None]
        if not ok:
            return None
        p, c = min(ok, key=lambda t: t[1])  # type: ignore[arg-type, return-value]
        return dict(p), float(c)  # type: ignore[arg-type]

    def recommend(self) -> tuple[dict[str, float], float] | None:
        """The best observed parameters (as Optuna's ``best_trial``)."""
        return self.best()
