"""The optimiser interface the calibration loop talks to, and the named optimisers a study
file can choose (``optimizer: {sampler: ...}``).

A `Sampler` proposes parameter sets (``ask``), learns costs (``tell``; ``None`` for a failed
evaluation), keeps the points it asked and was not yet told (pending), and is deterministic in
its seed and its history of tells: a resumed study rebuilds it by replaying ``tell`` from the
store and gets the same next batch.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol, runtime_checkable

from parcelfit.errors import ParcelfitError
from parcelfit.optimize.bo import BatchBO, BOSettings
from parcelfit.optimize.space import Space

SAMPLERS = ("gp", "published", "tpe", "optuna-gp", "botorch")


@runtime_checkable
class Sampler(Protocol):
    """Ask/tell batch optimiser that minimises a cost."""

    space: Space
    batch_size: int
    seed: int

    def ask(self, n: int | None = None) -> list[dict[str, float]]:
        """The next ``n`` parameter sets (default: the batch size)."""
        ...

    def tell(self, params: Mapping[str, float], cost: float | None) -> None:
        """Report an evaluated parameter set's cost (None or non-finite: failed)."""
        ...

    def best(self) -> tuple[dict[str, float], float] | None:
        """The evaluated parameters with the lowest cost, and that cost."""
        ...

    def recommend(self) -> tuple[dict[str, float], float] | None:
        """The parameters to report and validate, with their observed cost."""
        ...

    @property
    def n_told(self) -> int:
        """How many evaluations were told."""
        ...


def make_sampler(
    name: str,
    space: Space,
    *,
    batch_size: int = 4,
    seed: int = 0,
    settings: BOSettings | None = None,
    n_initial: int = 16,
    options: Mapping[str, Any] | None = None,
) -> Sampler:
    """The optimiser called ``name``: "gp" (our GP batch BO, ``settings``), "published" (the
    configuration of method.md section 7), "tpe" or "optuna-gp" (Optuna's TPE or GPSampler
    through its ask/tell) or "botorch" (BoTorch's SingleTaskGP with qLogNEI)."""
    if name == "gp":
        return BatchBO(space, batch_size=batch_size, seed=seed, settings=settings or BOSettings())
    if name == "published":
        return BatchBO(
            space,
            batch_size=batch_size,
            seed=seed,
            settings=settings or BOSettings.published(n_initial=n_initial),
        )
    if name == "tpe":
        from parcelfit.optimize.optuna_sampler import OptunaSampler

        return OptunaSampler(space, batch_size=batch_size, seed=seed, **dict(options or {}))
    if name == "optuna-gp":
        from parcelfit.optimize.optuna_sampler import OptunaSampler

        opts = {"n_startup_trials": n_initial, **dict(options or {})}
        return OptunaSampler(space, batch_size=batch_size, seed=seed, kind="gp", **opts)
    if name == "botorch":
        from parcelfit.optimize.botorch_sampler import BoTorchSampler

        opts = {"n_initial": n_initial, **dict(options or {})}
        return BoTorchSampler(space, batch_size=batch_size, seed=seed, **opts)
    raise ParcelfitError(f"unknown optimizer {name!r}", fix=f"use one of {', '.join(SAMPLERS)}")
