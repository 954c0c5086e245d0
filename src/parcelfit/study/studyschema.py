"""The study file's schema: its sections (file units, checked by pydantic as they are read;
``reference``, ``cases``, ``cost``, ``executor``, ``validation``, ``weights``, ``optimizer``; some
shared with screen files) and the whole file (`StudyFile`) as `parcelfit.schema.FileModel`
models. The format is shown in `parcelfit.study.studyfile`, which loads a file through these
models and converts it to SI (`Study`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any

from pydantic import ConfigDict, Field, field_validator, model_validator

from parcelfit.errors import ParcelfitError, shown
from parcelfit.optimize.bo import SETTING_CHOICES, BOSettings
from parcelfit.optimize.sampler import SAMPLER_SETTINGS, SAMPLERS
from parcelfit.runs.run import MAX_SPEED_SETTING
from parcelfit.schema import (
    Choice,
    FileModel,
    Flag,
    Number,
    Text,
    Whole,
    check_keys,
    or_default,
)
from parcelfit.sim.ensemble import MAX_PLACEMENTS
from parcelfit.sim.executors import MAX_WORKERS
from parcelfit.sim.factory import SimulatorSection
from parcelfit.sim.params import MAX_REFINEMENT

# the most a study may ask for (each is checked on load, before anything runs): evaluations
# (``budget``, ``initial``, ``validation.every``), simulations in one batch (``batch_size``)
MAX_EVALUATIONS = 10_000
MAX_BATCH_SIZE = 256


class ReferenceSection(FileModel):
    """``reference``: the dataset folder (relative to the file), test case and speed setting."""

    dataset: Annotated[str, Text()]
    """The dataset folder (holding dataset.yaml), relative to this file."""
    rig: Annotated[str | None, Text(nullable=True)] = None
    """The test case's rig as the dataset names it (default: the simulator's rig; a rig file's
    stem)."""
    consignment: Annotated[str | None, Text(nullable=True)] = None
    """The test case's consignment type as the dataset names it (default: the simulator's; a
    consignment file's stem)."""
    speed_setting: Annotated[int, Whole(ge=1, le=MAX_SPEED_SETTING)]
    """The speed setting fitted (whole number >= 1, as in the dataset)."""


class JudgedCaseSection(FileModel):
    """One test case of ``validation.cases`` or ``transfer``: dataset folder (relative to the
    file; default the first case's), rig and consignment (default the simulator's) and speed
    setting. Each is judged on its own, at the nominal placement: no weight, no placements."""

    dataset: Annotated[str | None, Text(nullable=True)] = None
    """The dataset folder, relative to this file (default: the first case's)."""
    rig: Annotated[str | None, Text(nullable=True)] = None
    """The case's rig as the dataset names it (default: the simulator's rig)."""
    consignment: Annotated[str | None, Text(nullable=True)] = None
    """The case's consignment type as the dataset names it (default: the simulator's)."""
    speed_setting: Annotated[int, Whole(ge=1, le=MAX_SPEED_SETTING)]
    """The case's speed setting (whole number >= 1)."""

    @classmethod
    def allowed_keys(cls, data: Mapping[Any, Any]) -> list[str]:
        for key in ("weight", "placements"):
            if key in data and key not in cls.model_fields:  # a fitted case (below) takes them
                raise ParcelfitError(
                    f"only fitted cases take {key}: validation and transfer cases are judged "
                    "each on its own, simulated once at the nominal placement",
                    where=key,
                    fix=f"leave {key} out here (a study folder begun with it continues only "
                    "with --restart, as the study file changed)",
                )
        return super().allowed_keys(data)


class CaseSection(JudgedCaseSection):
    """One fitted test case of ``cases``: as a validation case, and its weight in the cost and,
    with the ensemble cost, its own number of placements (default ``cost.placements``): a case
    whose placements scatter less than its real runs (E1: 1.5 ms of transit time against the
    real runs' 16.8 ms, 3.4 ms adjusted for belt speeds) loses less by fewer than one whose
    placements spin at some seeds (E3)."""

    weight: Annotated[float, Number(ge=0)] = 1.0
    """Weight of this case's cost in the sum (>= 0) [-]."""
    placements: Annotated[int | None, Whole(ge=1, le=MAX_PLACEMENTS, nullable=True)] = None
    """Seeded placements of this case per evaluation with the ensemble cost (default:
    cost.placements)."""


class CostSection(FileModel):
    """``cost``: ``published`` (equation 3 against the reference run) or ``ensemble``
    (``placements`` seeded placements against all real runs, plus the transit-time term
    weighted by ``transit_weight``, on the transit times as measured or, with ``transit:
    adjusted``, adjusted for the belt speeds each run rode at)."""

    kind: Annotated[str, Choice(("published", "ensemble"), what="cost")] = "published"
    """published: equation 3 against the reference run; ensemble: seeded placements against all
    real runs with a transit-time term."""
    placements: Annotated[int, Whole(ge=1, le=MAX_PLACEMENTS)] = 1
    """Seeded placements per case and evaluation (ensemble cost only; the published cost
    simulates one)."""
    mirrored: Annotated[bool, Flag()] = False
    """Antithetic placements (ensemble cost, 2 or more placements): each seeded placement
    beside its mirror image (every offset negated, the nominal start first when ``placements``
    is odd), so that the fixed sample of placements averages to the nominal start, and the
    transit term's variance taken from the pairs' means; false: independent draws. A simulator of
    your own (``backend: python``) gets seed -s for the mirror image of placement s."""
    transit_weight: Annotated[float, Number(ge=0)] = 1.0
    """Weight w_T of the ensemble cost's transit-time term [-]."""
    transit: Annotated[str, Choice(("measured", "adjusted"), what="transit time")] = "measured"
    """measured: transit times as measured; adjusted: adjusted for the belt speeds each run rode
    at (ensemble cost only)."""

    @classmethod
    def prepare(cls, data: Any) -> Any:
        return {"kind": data} if isinstance(data, str) else data

    @model_validator(mode="after")
    def _published_is_one_run(self) -> CostSection:
        if self.kind == "published" and self.placements != 1:
            raise ParcelfitError(
                "the published cost compares one simulation with the reference run",
                where="placements",
                fix="use kind: ensemble for several placements, or leave placements out",
            )
        if self.kind == "published" and self.mirrored:
            raise ParcelfitError(
                "the published cost simulates the nominal placement only: nothing to mirror",
                where="mirrored",
                fix="use kind: ensemble with placements: 2 or more, or leave mirrored out",
            )
        if self.mirrored and self.placements < 2:
            raise ParcelfitError(
                "mirrored placements pair a placement with its mirror image: one placement "
                "has nothing to pair",
                where="mirrored",
                fix="use placements: 2 or more, or leave mirrored out",
            )
        if self.kind == "published" and self.transit != "measured":
            raise ParcelfitError(
                "the published cost has no transit-time term to adjust",
                where="transit",
                fix="use kind: ensemble with transit: adjusted, or leave transit out",
            )
        return self


class ScreenExecutorSection(FileModel):
    """``executor`` of a screen file: on this machine, local processes or serial (in this
    process); ``executor: KIND`` is short for ``executor: {kind: KIND}``."""

    kind: Annotated[str, Choice(("serial", "local"), what="executor")] = "local"
    """Where simulations run: local (worker processes) or serial (in this process, one at a
    time). `executor: serial` is short for `{kind: serial}`."""
    workers: Annotated[int | None, Whole(ge=1, le=MAX_WORKERS, nullable=True)] = None
    """Worker processes of the local executor (default: one per core)."""

    @classmethod
    def prepare(cls, data: Any) -> Any:
        return {"kind": data} if isinstance(data, str) else data


class ExecutorSection(ScreenExecutorSection):
    """``executor`` of a study file: local processes, serial (in this process, for debugging),
    or a Dask ``scheduler`` (tcp://...)."""

    kind: Annotated[str, Choice(("serial", "local", "dask"), what="executor")] = "local"
    """Where simulations run: local (worker processes), serial (in this process) or dask (a Dask
    cluster at `scheduler`)."""
    scheduler: Annotated[str | None, Text()] = None
    """The Dask scheduler's address, e.g. tcp://HOST:8786 (kind: dask)."""


class Bounds(FileModel):
    """One fitted parameter: ``[low, high]`` or ``{low, high, log}`` (catalogue units)."""

    low: Annotated[float, Number()]
    """Lower end of the range, in the catalogue's unit (see `parcelfit params`)."""
    high: Annotated[float, Number()]
    """Upper end of the range, in the catalogue's unit."""
    log: Annotated[bool, Flag()] = False
    """Search the range on a log scale."""

    @classmethod
    def prepare(cls, data: Any) -> Any:
        if isinstance(data, list) and len(data) == 2:
            return {"low": data[0], "high": data[1]}
        if not isinstance(data, Mapping):
            raise ParcelfitError(
                f"expected [low, high] or {{low, high, log}}, got {shown(data)}",
                fix="write e.g. mu_d_BePa: [0.3, 0.6]",
            )
        return data


class ValidationSection(FileModel):
    """``validation``: the validation speed setting (none: no validation) and how often."""

    speed_setting: Annotated[int | None, Whole(ge=1, le=MAX_SPEED_SETTING, nullable=True)] = None
    """The validation speed setting of a `reference` study (not the fitted one; none: no
    validation)."""
    every: Annotated[int, Whole(ge=1, le=MAX_EVALUATIONS)] = 5
    """Validate the recommended parameters every this many iterations."""
    cases: Annotated[list[JudgedCaseSection], or_default(list)] = Field(default_factory=list)
    """The validation test cases of a joint study (all must pass), each as in `cases` without
    weight and placements."""
    refinement: Annotated[int, Whole(ge=1, le=MAX_REFINEMENT)] = 2
    """The convergence check once the study stops: the recommended parameters simulated again on
    every validation and transfer case with every mesh spacing and the time step divided by this
    (MuJoCo, the rigid-box reference, a factory's simulator with with_refinement; 2: halved),
    passed when each case's published criteria (and each validation case's band test) give the
    same outcome as on the model itself.
    1: no check (the verdict then at best incomplete)."""

    @model_validator(mode="after")
    def _one_way(self) -> ValidationSection:
        if self.speed_setting is not None and self.cases:
            raise ParcelfitError(
                "both speed_setting and cases are given",
                where="cases",
                fix="list the validation speed setting as one of the cases",
            )
        return self


class WeightsSection(FileModel):
    """``weights`` of equation (3): position and heading terms, >= 0, not both zero."""

    xy: Annotated[float, Number(ge=0)] = 1.0
    """Weight of the position term (DTW_xy) in equation 3 (>= 0) [-]."""
    theta: Annotated[float, Number(ge=0)] = 1.0
    """Weight of the heading term (DTW_theta) in equation 3 (>= 0) [-]."""

    @model_validator(mode="after")
    def _not_both_zero(self) -> WeightsSection:
        if self.xy + self.theta <= 0:
            raise ParcelfitError(
                "both weights are zero, so every simulation would cost nothing",
                fix="give xy or theta a positive weight",
            )
        return self


_GP_KEYS = sorted(set(BOSettings.__dataclass_fields__) - {"n_initial"})
# the counts among the settings, with their bounds (a million candidates per ask take seconds)
_SETTING_COUNTS = {
    "n_samples": Whole(ge=10, le=1_000_000),
    "n_restarts": Whole(ge=0, le=100),
    "polish": Whole(ge=0, le=100),
    "nei_samples": Whole(ge=2, le=65536),  # a power of 2, checked when the settings are made
}


def _setting(name: str, value: Any) -> Any:
    """An optimizer setting checked by its type (that of the `BOSettings` default), for a
    count by its bounds, for a text by its choices (`SETTING_CHOICES`); how settings combine is
    checked when the settings are made."""
    default = BOSettings.__dataclass_fields__[name].default
    choices = SETTING_CHOICES.get(name)
    check: Whole | Flag | Number | Text | Choice = (
        (Choice(choices, what=f"{name} value") if choices else None)
        or _SETTING_COUNTS.get(name)
        or (Flag() if isinstance(default, bool) else None)
        or (Number() if isinstance(default, float) else None)
        or Text()
    )
    try:
        return check.check(value)
    except ParcelfitError as exc:
        raise ParcelfitError(exc.message, where=name, fix=exc.fix) from None


class OptimizerSection(FileModel):
    """``optimizer``: the sampler and, for gp and published, `BOSettings` fields (checked when
    the settings are made)."""

    model_config = ConfigDict(extra="allow")  # merged with FileModel's
    sampler: Annotated[str, Choice(tuple(SAMPLERS), what="optimizer")] = "gp"
    """The optimiser: gp (the default batch Bayesian optimisation), published (the published
    settings), tpe or optuna-gp (Optuna) or botorch (BoTorch); gp and published take the
    optimiser settings (their own table below) beside it."""

    @classmethod
    def allowed_keys(cls, data: Mapping[Any, Any]) -> list[str]:
        name = data.get("sampler", "gp")
        if name in SAMPLERS and name not in SAMPLER_SETTINGS:
            check_keys(data, ["sampler"], fix=f"the {name} sampler takes no settings but `sampler`")
        return ["sampler", *_GP_KEYS]

    @model_validator(mode="after")
    def _typed_settings(self) -> OptimizerSection:
        self.settings  # noqa: B018 - each setting checked now, named where it stands
        return self

    @property
    def settings(self) -> dict[str, Any]:
        """The BOSettings overrides, each checked by its type (counts by their bounds)."""
        return {str(k): _setting(str(k), v) for k, v in (self.model_extra or {}).items()}


class StudyFile(FileModel):
    """A study file as written (see the module docstring)."""

    name: Annotated[str, Text()]
    """The study's name (shown in outputs and the report)."""
    simulator: SimulatorSection
    """The simulator and its settings (see the simulator section)."""
    parameters: dict[Any, Bounds]
    """The parameters to fit, each `[low, high]` or `{low, high, log}` in the catalogue's units
    (`parcelfit params`)."""
    fixed: Annotated[dict[Any, Annotated[float, Number()]], or_default(dict)] = Field(
        default_factory=dict
    )
    """Parameters held at a value other than their default, in the catalogue's units."""
    reference: ReferenceSection | None = None
    """The one fitted test case (the published method); or give `cases`."""
    cases: Annotated[list[CaseSection], or_default(list)] = Field(default_factory=list)
    """The fitted test cases of a joint study (instead of `reference`)."""
    cost: Annotated[CostSection, or_default(dict)] = Field(default_factory=CostSection)
    """The cost of a case: published (default) or ensemble."""
    transfer: Annotated[list[JudgedCaseSection], or_default(list)] = Field(default_factory=list)
    """Test cases the calibrated parameters are judged on once the study stops (not fitted)."""
    validation: Annotated[ValidationSection, or_default(dict)] = Field(
        default_factory=ValidationSection
    )
    """The validation case(s) and how often to validate."""
    weights: Annotated[WeightsSection, or_default(dict)] = Field(default_factory=WeightsSection)
    """The weights of equation 3's position and heading terms."""
    optimizer: Annotated[OptimizerSection, or_default(dict)] = Field(
        default_factory=OptimizerSection
    )
    """The optimiser and its settings."""
    initial: Annotated[int, Whole(ge=1, le=MAX_EVALUATIONS)] = 16
    """Size of the initial design (Latin hypercube) [evaluations]."""
    executor: Annotated[ExecutorSection, or_default(dict)] = Field(default_factory=ExecutorSection)
    """Where simulations run (the command line's --executor, --workers and --scheduler win)."""
    batch_size: Annotated[int, Whole(ge=1, le=MAX_BATCH_SIZE)] = 4
    """Evaluations per optimiser batch (run in parallel)."""
    budget: Annotated[int, Whole(ge=1, le=MAX_EVALUATIONS)] = 80
    """The most fitting evaluations (the study stops earlier when a validation passes)."""
    seed: Annotated[int, Whole(ge=0, le=2**32 - 1)] = 0
    """Seed of the initial design and the optimiser (0 to 2^32 - 1)."""

    @field_validator("parameters")
    @classmethod
    def _some(cls, value: dict[Any, Bounds]) -> dict[Any, Bounds]:
        if not value:
            raise ParcelfitError("no parameters to fit", fix="list at least one")
        return value

    @model_validator(mode="after")
    def _reference_or_cases(self) -> StudyFile:
        if self.reference is None and not self.cases:
            raise ParcelfitError(
                "missing required key 'reference'",
                fix="add `reference:`",
            )
        if self.reference is not None and self.cases:
            raise ParcelfitError(
                "give either reference (one test case) or cases (a joint study)"
                + (", not both" if self.reference is not None else ""),
                where="cases" if self.cases else "reference",
                fix="e.g. reference: {dataset: data, speed_setting: 1}",
            )
        if self.cases and self.validation.speed_setting is not None:
            raise ParcelfitError(
                "a joint study names its validation cases",
                where="validation.speed_setting",
                fix="write validation: {cases: [{rig: ..., speed_setting: ...}]}",
            )
        if self.cases and not any(c.weight > 0 for c in self.cases):
            raise ParcelfitError(
                "every case has weight 0, so every simulation would cost nothing",
                where="cases",
                fix="give at least one case a positive weight",
            )
        return self

    @model_validator(mode="after")
    def _budget_holds_the_initial_design(self) -> StudyFile:
        if self.budget < self.initial:
            raise ParcelfitError(
                f"budget {self.budget} is below initial {self.initial}: the study would stop "
                "before its initial design is complete",
                where="budget",
                fix=f"raise budget to {self.initial} or more, or lower initial",
            )
        return self

    @model_validator(mode="after")
    def _validation_setting(self) -> StudyFile:
        if self.reference is None:
            return self
        if self.validation.speed_setting == self.reference.speed_setting:
            raise ParcelfitError(
                "validation must use a speed setting not used for fitting",
                where="validation.speed_setting",
                fix=f"use a setting other than {self.reference.speed_setting}",
            )
        return self
