"""The optimiser interface the calibration loop talks to, and the named optimisers a study
file can choose (``optimizer: {sampler: ...}``).

A `Sampler` proposes parameter sets (``ask``), learns costs (``tell``; ``None`` for a failed
evaluation), keeps the points it asked and was not yet told (pending), and is deterministic in
its seed and its history of tells: a resumed study rebuilds it by replaying ``tell`` from the
store and gets the same next batch.

`SAMPLERS` is the registry of the names a study file may choose: name -> `SamplerFactory`. A
new sampler is a class with the `Sampler` methods in a module of its own here and one entry in
`SAMPLERS`; the name is resolved once, when the study file is read
(`parcelfit.study.studyfile.Study.new_sampler`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Protocol, runtime_checkable

from parcelfit.errors import ParcelfitError
from parcelfit.optimize.bo import BatchBO, BOSettings
from parcelfit.optimize.space import Space


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


class SamplerFactory(Protocol):
    """Makes a sampler over ``space`` asking batches of ``batch_size`` (deterministic in
    ``seed``); ``settings`` are the study file's `BOSettings` (made by the factory's
    ``settings`` maker), ``n_initial`` the size of the initial design, ``options`` other
    keyword arguments of the sampler."""

    def __call__(
        self,
        space: Space,
        *,
        batch_size: int,
        seed: int,
        settings: BOSettings | None,
        n_initial: int,
        options: Mapping[str, Any],
    ) -> Sampler: ...


def _gp(
    space: Space,
    *,
    batch_size: int,
    seed: int,
    settings: BOSettings | None,
    n_initial: int,
    options: Mapping[str, Any],
) -> Sampler:
    """Our GP batch BO with ``settings`` (default `BOSettings()`)."""
    return BatchBO(space, batch_size=batch_size, seed=seed, settings=settings or BOSettings())


def _published(
    space: Space,
    *,
    batch_size: int,
    seed: int,
    settings: BOSettings | None,
    n_initial: int,
    options: Mapping[str, Any],
) -> Sampler:
    """The GP batch BO in the configuration of method.md section 7."""
    return BatchBO(
        space,
        batch_size=batch_size,
        seed=seed,
        settings=settings or BOSettings.published(n_initial=n_initial),
    )


def _tpe(
    space: Space,
    *,
    batch_size: int,
    seed: int,
    settings: BOSettings | None,
    n_initial: int,
    options: Mapping[str, Any],
) -> Sampler:
    """Optuna's TPE through its ask/tell (the ``optuna`` extra)."""
    from parcelfit.optimize.optuna_sampler import OptunaSampler

    return OptunaSampler(space, batch_size=batch_size, seed=seed, **dict(options))


def _optuna_gp(
    space: Space,
    *,
    batch_size: int,
    seed: int,
    settings: BOSettings | None,
    n_initial: int,
    options: Mapping[str, Any],
) -> Sampler:
    """Optuna's GPSampler through its ask/tell (the ``optuna`` and ``botorch`` extras)."""
    from parcelfit.optimize.optuna_sampler import OptunaSampler

    opts = {"n_startup_trials": n_initial, **dict(options)}
    return OptunaSampler(space, batch_size=batch_size, seed=seed, kind="gp", **opts)


def _botorch(
    space: Space,
    *,
    batch_size: int,
    seed: int,
    settings: BOSettings | None,
    n_initial: int,
    options: Mapping[str, Any],
) -> Sampler:
    """BoTorch's SingleTaskGP with qLogNEI batches (the ``botorch`` extra)."""
    from parcelfit.optimize.botorch_sampler import BoTorchSampler

    opts = {"n_initial": n_initial, **dict(options)}
    return BoTorchSampler(space, batch_size=batch_size, seed=seed, **opts)


SAMPLERS: dict[str, SamplerFactory] = {
    "gp": _gp,
    "published": _published,
    "tpe": _tpe,
    "optuna-gp": _optuna_gp,
    "botorch": _botorch,
}
# The BOSettings maker of each sampler that takes BOSettings keys in the study file (called with
# n_initial and the file's keys); a sampler not named here takes no settings but its name.
SAMPLER_SETTINGS: dict[str, Callable[..., BOSettings]] = {
    "gp": BOSettings,
    "published": BOSettings.published,
}


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
    """The optimiser called ``name`` in `SAMPLERS`: "gp" (our GP batch BO, ``settings``),
    "published" (the configuration of method.md section 7), "tpe" or "optuna-gp" (Optuna's TPE
    or GPSampler through its ask/tell) or "botorch" (BoTorch's SingleTaskGP with qLogNEI)."""
    if name not in SAMPLERS:
        raise ParcelfitError(f"unknown optimizer {name!r}", fix=f"use one of {', '.join(SAMPLERS)}")
    return SAMPLERS[name](
        space,
        batch_size=batch_size,
        seed=seed,
        settings=settings,
        n_initial=n_initial,
        options=options or {},
    )
