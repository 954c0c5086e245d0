"""The ``details`` of a stored evaluation as a typed record (`EvaluationDetails`).

One record serves every kind of row in the store (`parcelfit.study.store`); each writer sets
the fields of its kind and leaves the others unset:

- a fitting evaluation: the simulator's ``message`` and diagnostics, and for a joint or
  ensemble study the per-case cost parts (``cases``, `CaseCost`) or, when a simulation did
  not succeed, which one (``failed_run``);
- a validation: its ``case``, ``passed`` and the three published criteria and the band test
  (`TransitCriterion`, `MeanCriterion`, `EnvelopeCriterion`);
- a run of a screen, prediction or design: its quantities (``rotation``, ``exit_x``,
  ``exit_y``, ``exit_heading``) and, when it failed, the ``message``;
- a run of a precision check: its ``case`` and statistics (the transit time is the row's own
  column) and the ridden speeds a transit-time adjustment needs.

The stored form (`EvaluationDetails.to_json`) is the JSON the store has always held: the
fields set, under their stored names (``transit_time``, ``xy`` and ``theta`` for the
criteria), so a store written by an earlier parcelfit reads, and writes back, as it was. A
simulator's own diagnostics beyond the common ones (``steps``, ``simulated_time``,
``steps_per_second``, ``worker_restarts``) differ from backend to backend and are kept as
extra keys, as stored.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from parcelfit.errors import ParcelfitError


class _Stored(BaseModel):
    """A part of a stored record: its stored keys kept as given (unknown ones too)."""

    model_config = ConfigDict(frozen=True, extra="allow", populate_by_name=True)

    def to_json(self) -> dict[str, Any]:
        """The stored form: the fields that were set, under their stored names."""
        return self.model_dump(by_alias=True, exclude_unset=True)


class CaseCost(_Stored):
    """The cost part of one test case in a joint or ensemble evaluation."""

    case: str = Field(description="the test case's label")
    weight: float = Field(description="its weight in the study's cost [-]")
    cost: float = Field(description="its unweighted cost [-]")
    run_files: list[str | None] = Field(
        default_factory=list, description="its simulated runs, relative to the study folder"
    )
    seeds: list[int | None] = Field(
        default_factory=list,
        description="their placement seeds (None: nominal placement; -s: placement s mirrored)",
    )
    transit_times: list[float | None] = Field(
        default_factory=list, description="their simulated transit times [s]"
    )
    adjusted_transit_times: list[float | None] | None = Field(
        None, description="the transit times adjusted like the real runs' [s] (None: none)"
    )
    dtw_xy: float | None = Field(None, description="published cost: DTW distance of x-y [m]")
    dtw_theta: float | None = Field(None, description="published cost: DTW of the heading [rad]")
    trajectory_term: float | None = Field(None, description="ensemble cost: trajectory term [-]")
    transit_term: float | None = Field(None, description="ensemble cost: transit term [-]")
    se: float | None = Field(None, description="ensemble cost: the trajectory term's SE [-]")
    mean_transit_time: float | None = Field(None, description="ensemble: mean transit time [s]")

    @property
    def is_ensemble(self) -> bool:
        """True for a part of the ensemble cost (it has a trajectory term)."""
        return self.trajectory_term is not None


class FailedRun(_Stored):
    """The simulation that did not succeed in a joint evaluation."""

    case: str = Field(description="its test case's label")
    placement: int | None = Field(None, description="its placement seed (None: nominal)")


class TransitCriterion(_Stored):
    """Criterion 1 of a validation: the simulated transit time inside the real runs' range."""

    simulated: float | None = Field(None, description="the simulated transit time [s]")
    low: float | None = Field(None, description="the lower end of the accepted range [s]")
    high: float | None = Field(None, description="the upper end of the accepted range [s]")
    passed: bool = False


class MeanCriterion(_Stored):
    """Criterion 2 or 3 of a validation: the simulation's mean squared distance to the real
    runs against the largest real run's (x-y [m^2], heading [rad^2])."""

    simulated_mean: float | None = Field(None, description="the simulation's mean distance")
    largest_real_mean: float | None = Field(None, description="the largest real run's")
    passed: bool = False


class EnvelopeCriterion(_Stored):
    """The stricter band test reported beside the published verdict."""

    inside_y: float | None = Field(None, description="share of y samples inside the band [-]")
    inside_theta: float | None = Field(None, description="share of heading samples inside [-]")
    worst_y_m: float | None = Field(None, description="largest y excursion outside [m]")
    worst_theta_rad: float | None = Field(None, description="largest heading excursion [rad]")
    passed: bool = False


class EvaluationDetails(_Stored):
    """The ``details`` of one stored evaluation (see the module docstring for who sets what)."""

    message: str | None = Field(None, description="why it failed, or the simulator's message")
    # fitting evaluations
    cases: list[CaseCost] | None = Field(None, description="a joint evaluation's case parts")
    failed_run: FailedRun | None = None
    steps: int | None = Field(None, description="simulator steps taken [-]")
    simulated_time: float | None = Field(None, description="simulated time [s]")
    steps_per_second: float | None = Field(None, description="simulator speed [1/s]")
    worker_restarts: int | None = Field(None, description="worker restarts for this task [-]")
    # validations
    case: str | None = Field(None, description="a validation's test case (None: one case)")
    passed: bool | None = Field(None, description="a validation's published verdict")
    transit: TransitCriterion | None = Field(None, alias="transit_time")
    xy: MeanCriterion | None = None
    theta: MeanCriterion | None = None
    envelope: EnvelopeCriterion | None = None
    # runs of a screen, prediction or design
    rotation: float | None = Field(None, description="the run's net rotation [rad]")
    exit_x: float | None = Field(None, description="the run's last x position [m]")
    exit_y: float | None = Field(None, description="the run's last y position [m]")
    exit_heading: float | None = Field(None, description="its unwrapped last heading [rad]")
    # runs of a precision check (`parcelfit.study.precision_check`); ``case`` names their case
    region_rotation: float | None = Field(
        None, description="net rotation over the case's regions of interest [rad]"
    )
    lateral_drift: float | None = Field(None, description="lateral drift over the regions [m]")
    start_speed: float | None = Field(None, description="speed over its first window [m/s]")
    end_speed: float | None = Field(None, description="speed over its last window [m/s]")

    @classmethod
    def from_json(cls, doc: Mapping[str, Any] | None) -> EvaluationDetails:
        """Read the stored form (None or empty: no details)."""
        return cls.model_validate(dict(doc or {}))

    @classmethod
    def parse(cls, text: str | None, where: Path | None = None) -> EvaluationDetails:
        """Read the stored JSON text (None: no details); a damaged one is a `ParcelfitError`."""
        try:
            return cls.from_json(json.loads(text) if text else None)
        except (ValueError, TypeError, ValidationError) as exc:
            raise ParcelfitError(
                f"an evaluation's details in the study database are damaged ({exc})",
                file=where,
                fix="restore the database from a backup",
            ) from None

    def dumps(self) -> str:
        """The stored JSON text (values JSON cannot hold written as text, as always)."""
        return json.dumps(self.to_json(), default=str)

    def with_message(self, message: str) -> EvaluationDetails:
        """A copy with ``message`` set."""
        return self.model_validate({**self.to_json(), "message": message})

    def diagnostic(self, key: str) -> Any:
        """A simulator's own diagnostic (an extra key; None when absent)."""
        return (self.model_extra or {}).get(key)

    @property
    def quantities(self) -> dict[str, float | None]:
        """A run's quantities other than its transit time (SI; None where absent)."""
        return {
            "rotation": self.rotation,
            "exit_x": self.exit_x,
            "exit_y": self.exit_y,
            "exit_heading": self.exit_heading,
        }


__all__ = [
    "CaseCost",
    "EnvelopeCriterion",
    "EvaluationDetails",
    "FailedRun",
    "MeanCriterion",
    "TransitCriterion",
]
