"""The base of the backends that simulate the rig and consignment files (`RigBackend`): the
MuJoCo model and the rigid-box reference."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any, Generic, Self, TypeVar

from parcelfit.sim.mujoco.consignment import Consignment, load_consignment
from parcelfit.sim.mujoco.rig import Rig, load_rig

OptionsT = TypeVar("OptionsT")


class RigBackend(Generic[OptionsT]):
    """What the MuJoCo model and the rigid-box reference share: their options (a frozen
    dataclass with a ``placement_seed`` field), the rigs and consignments given at construction
    (else bundled, loaded on first use), and copies with changed options or placement."""

    def __init__(
        self,
        options: OptionsT,
        rigs: Mapping[str, Rig] | None = None,
        consignments: Mapping[str, Consignment] | None = None,
    ) -> None:
        self.options = options
        self._rigs = dict(rigs or {})
        self._consignments = dict(consignments or {})

    def rig(self, name: str) -> Rig:
        """The rig called ``name`` (given at construction, else bundled)."""
        if name not in self._rigs:
            self._rigs[name] = load_rig(name)
        return self._rigs[name]

    def consignment(self, name: str) -> Consignment:
        """The consignment type called ``name`` (given at construction, else bundled)."""
        if name not in self._consignments:
            self._consignments[name] = load_consignment(name)
        return self._consignments[name]

    def with_options(self, **changes: Any) -> Self:
        """The same backend (rigs and consignments) with option fields changed."""
        return type(self)(replace(self.options, **changes), self._rigs, self._consignments)  # type: ignore[arg-type]

    def with_placement(self, seed: int | None) -> Self:
        """The same backend with placement ``seed`` (None: the nominal start pose)."""
        return self.with_options(placement_seed=seed)

    def with_speed_factors(self, factors: Mapping[str, float]) -> Self:
        """The same backend with each drive's speed times its factor [-] (drive -> factor; a
        drive not listed runs at its rig's speed)."""
        raise NotImplementedError  # each backend keeps the factors in its own options
