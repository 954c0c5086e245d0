"""One honest verdict on a calibration: every check on a line of its own, and one overall verdict.

A calibration is judged by four checks and one analysis:

* **published criteria** (method section 8): the recommended parameters, simulated on the
  validation cases, pass the three published criteria on every case;
* **band test** (parcelfit's stricter criterion): that simulation stays inside the real runs'
  band over at least 95 % of the path on every validation case;
* **transfer check**: the recommended parameters pass the published criteria on every transfer
  case (cases that took no part in the calibration, usually another rig);
* **convergence check**: the recommended parameters, simulated again on every validation and
  transfer case by the model refined (every mesh spacing and the time step halved, by default),
  pass or fail the published criteria on each case as on the model itself, and the band test
  on each validation case (the outcomes are compared, not the numbers);
* **parameters determined** (`parcelfit.study.identify`): which parameters the data fix.

Each check passed, failed or was not run. The overall verdict is ``trustworthy`` only when all
four checks passed and the parameters were analysed; a failed check makes it ``not
trustworthy``, else a check not run makes it ``incomplete``: it never reads better than the
worst of its checks. How many parameters are determined does not change the level (a model
can pass every check with parameters the data leave open), but the verdict always says it, and
what an undetermined parameter means (`UNDETERMINED_MEANING`).

`combine` makes the verdict from the checks; `study_verdict` makes the checks from what a
study stored (its results and test cases). Both are pure: they read no file. The terminal
(``calibrate``, ``demo``, ``status``), ``status --json`` and the report all show this verdict.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

if TYPE_CHECKING:
    from parcelfit.study.identify import Identifiability
    from parcelfit.study.results import ConvergenceRecord, StudyResults, ValidationRecord
    from parcelfit.study.store import CaseRecord

Outcome = Literal["passed", "failed", "not run"]
Level = Literal["not trustworthy", "incomplete", "trustworthy"]
LEVELS: tuple[Level, ...] = ("not trustworthy", "incomplete", "trustworthy")  # worst first

CRITERIA, BAND, TRANSFER = "published criteria", "band test", "transfer check"
CONVERGENCE = "convergence check"
PARAMETERS = "parameters determined"
UNDETERMINED_MEANING = (
    "A parameter that is not determined is one the data leave open: no value in its "
    "interval can be ruled out by them, so a prediction that depends on it carries that range."
)
CONVERGENCE_ADVICE = (
    "A failed convergence check means a case's outcome depends on the model's mesh or time "
    "step: give the study's simulator a finer spacing than the type's own mesh (film_spacing "
    "around a soft content) and timestep (or a rig_timesteps entry) and calibrate again in a new "
    "study folder (or with --restart); the runs get slower."
)


@dataclass(frozen=True)
class Check:
    """One check's outcome and, in words, on which cases and why (``detail``)."""

    name: str
    outcome: Outcome
    detail: str = ""

    def line(self) -> str:
        """E.g. ``transfer check: failed (E1/KPBW/1: DTW_theta)``."""
        return f"{self.name}: {self.outcome}" + (f" ({self.detail})" if self.detail else "")

    def to_json(self) -> dict[str, Any]:
        """The JSON form: ``name``, ``outcome`` (passed, failed, not run) and ``detail``."""
        return {"name": self.name, "outcome": self.outcome, "detail": self.detail}


@dataclass(frozen=True)
class Determined:
    """Which parameters the data determine: ``analysed`` False when the analysis was not run
    (``detail`` says why); else the determined names and the others with their kind (lower
    bound, upper bound, narrowed, undetermined)."""

    analysed: bool
    determined: tuple[str, ...] = ()
    open: tuple[tuple[str, str], ...] = ()  # (name, kind) of each parameter not determined
    detail: str = ""

    @property
    def total(self) -> int:
        """How many parameters were analysed."""
        return len(self.determined) + len(self.open)

    @property
    def outcome(self) -> str:
        """``k of n`` determined, or ``not run``."""
        return f"{len(self.determined)} of {self.total}" if self.analysed else "not run"

    def line(self) -> str:
        """E.g. ``parameters determined: 1 of 4 (mu_d_BePa; not determined: E_Pa
        (undetermined), k_MePa (lower bound))``."""
        if not self.analysed:
            return f"{PARAMETERS}: not run" + (f" ({self.detail})" if self.detail else "")
        named = ", ".join(self.determined) or "none"
        if self.open:
            named += "; not determined: " + ", ".join(f"{n} ({k})" for n, k in self.open)
        return f"{PARAMETERS}: {self.outcome} ({named})"

    def to_json(self) -> dict[str, Any]:
        """The JSON form."""
        return {
            "name": PARAMETERS,
            "outcome": self.outcome,
            "analysed": self.analysed,
            "determined": list(self.determined),
            "not_determined": [{"name": n, "kind": k} for n, k in self.open],
            "detail": self.detail,
        }


@dataclass(frozen=True)
class Verdict:
    """The overall verdict (``level`` and its sentence ``text``) with every check behind it."""

    level: Level
    text: str
    criteria: Check
    band: Check
    transfer: Check
    convergence: Check
    parameters: Determined

    @property
    def checks(self) -> tuple[Check, Check, Check, Check]:
        """The four checks that decide the level."""
        return (self.criteria, self.band, self.transfer, self.convergence)

    @property
    def convergence_advice(self) -> str | None:
        """What to do about a failed convergence check (`CONVERGENCE_ADVICE`), else None."""
        return CONVERGENCE_ADVICE if self.convergence.outcome == "failed" else None

    @property
    def trustworthy(self) -> bool:
        """True only when every check passed and the parameters were analysed."""
        return self.level == "trustworthy"

    def lines(self) -> list[str]:
        """The summary for a terminal: one line per check, what an undetermined parameter
        means (when one is), what to do about a failed convergence check (when it failed), and
        the verdict last."""
        out = [c.line() for c in self.checks] + [self.parameters.line()]
        if self.parameters.open:
            out.append(UNDETERMINED_MEANING)
        if self.convergence_advice:
            out.append(self.convergence_advice)
        return [*out, f"verdict: {self.text}"]

    def to_json(self) -> dict[str, Any]:
        """The JSON form (``status --json``): ``level``, ``text``, ``checks`` (published
        criteria, band test, transfer check, convergence check), ``parameters``,
        ``undetermined_means`` and ``convergence_advice`` (None where they do not apply)."""
        return {
            "level": self.level,
            "text": self.text,
            "checks": [c.to_json() for c in self.checks],
            "parameters": self.parameters.to_json(),
            "undetermined_means": UNDETERMINED_MEANING if self.parameters.open else None,
            "convergence_advice": self.convergence_advice,
        }


def combine(
    criteria: Check, band: Check, transfer: Check, convergence: Check, parameters: Determined
) -> Verdict:
    """The overall verdict of the checks: ``not trustworthy`` when one failed, else
    ``incomplete`` when one was not run (the parameter analysis too), else ``trustworthy``.
    The sentence names every check that failed or was not run, and the determined count."""
    checks = (criteria, band, transfer, convergence)
    failed = [f"{c.name} failed" for c in checks if c.outcome == "failed"]
    not_run = [f"{c.name} not run" for c in checks if c.outcome == "not run"]
    if not parameters.analysed:
        not_run.append("parameter analysis not run")
    level: Level
    if failed:
        level, text = "not trustworthy", "not trustworthy: " + ", ".join(failed + not_run)
    elif not_run:
        level, text = "incomplete", "incomplete: " + ", ".join(not_run)
    else:
        level, text = (
            "trustworthy",
            f"trustworthy: {CRITERIA}, {BAND}, {TRANSFER} and {CONVERGENCE} passed",
        )
    if parameters.analysed:
        text += f"; {len(parameters.determined)} of {parameters.total} parameters determined"
    return Verdict(level, text, criteria, band, transfer, convergence, parameters)


# -- the checks of a study's stored results ----------------------------------------------------


def _failed_criteria(v: ValidationRecord) -> str:
    """Why a record fails the published criteria, e.g. ``DTW_theta`` or ``the run ended
    failed``."""
    r = v.verdict
    if r is None:
        return v.message or f"the run ended {v.status}"
    names = [
        n
        for n, ok in (
            ("transit time", r.transit_time.passed),
            ("DTW_xy", r.xy.passed),
            ("DTW_theta", r.theta.passed),
        )
        if not ok
    ]
    return ", ".join(names) or "failed"


def criteria_check(group: Sequence[ValidationRecord], name: str = CRITERIA) -> Check:
    """The published criteria on every case of one validation (or of the transfer check)."""
    if not group:
        return Check(name, "not run", "no validation stored yet")
    bad = [v for v in group if not v.passed]
    cases = ", ".join(v.case for v in group)
    after = group[0].after_iteration
    when = "" if after is None else f" after iteration {after}"
    if bad:
        return Check(name, "failed", "; ".join(f"{v.case}: {_failed_criteria(v)}" for v in bad))
    return Check(name, "passed", f"{cases}{when}")


def band_check(group: Sequence[ValidationRecord]) -> Check:
    """The stricter band test on every case of the validation shown (not run on a case whose
    run gave no verdict or that has fewer than two real runs)."""
    if not group:
        return Check(BAND, "not run", "no validation stored yet")
    words, failed, missing, need = [], False, [], 0.0
    for v in group:
        env = None if v.verdict is None else v.verdict.envelope
        if env is None:
            missing.append(v.case)
            continue
        failed |= not env.passed
        need = max(need, env.min_inside)
        words.append(
            f"{v.case}: lateral {env.inside_y * 100:.0f} %, heading {env.inside_theta * 100:.0f} "
            "% of the path inside"
        )
    said = "; ".join(words) + f"; needs {need * 100:.0f} %"
    if failed:
        return Check(BAND, "failed", said)
    if missing:
        why = "no verdict or fewer than two real runs on " + ", ".join(missing)
        return Check(BAND, "not run", why)
    return Check(BAND, "passed", said)


def transfer_check(records: Sequence[ValidationRecord], planned: bool, stopped: bool) -> Check:
    """The published criteria on every transfer case; not run when the study names none, or
    before it stops (the check runs then)."""
    if records:
        return criteria_check(records, TRANSFER)
    if not planned:
        return Check(TRANSFER, "not run", "the study names no transfer cases")
    if not stopped:
        return Check(TRANSFER, "not run", "it runs when the study stops")
    return Check(TRANSFER, "not run", "the study stopped without recommended parameters")


def _outcome_word(v: ValidationRecord) -> str:
    return "passes" if v.passed else f"fails ({_failed_criteria(v)})"


def _band_passed(v: ValidationRecord) -> bool | None:
    """The band test's outcome of a record (None: no band, fewer than two real runs)."""
    env = None if v.verdict is None else v.verdict.envelope
    return None if env is None else env.passed


def last_validation(results: StudyResults | None) -> list[ValidationRecord]:
    """Every case's record of a study's last validation: that of the recommended parameters,
    which the transfer and convergence checks simulate too (not an earlier one that passed)."""
    group: list[ValidationRecord] = []
    for v in () if results is None else results.validations:
        if group and v.after_iteration != group[-1].after_iteration:
            group = []
        group.append(v)
    return group


def convergence_pairs(
    refined: Sequence[ValidationRecord], judged: Sequence[ValidationRecord]
) -> list[tuple[ValidationRecord | None, ValidationRecord]]:
    """Each refined run with the model's own run it is compared with: the judged run (the last
    validation's, then the transfer check's; a case in both, its validation) of the same case
    and parameters; None where there is none. The verdict and the report pair them so."""
    own: dict[str, ValidationRecord] = {}
    for v in judged:
        own.setdefault(v.case, v)
    out: list[tuple[ValidationRecord | None, ValidationRecord]] = []
    for r in refined:
        v = own.get(r.case)
        out.append((v if v is not None and v.params == r.params else None, r))
    return out


def convergence_check(
    convergence: ConvergenceRecord | None,
    judged: Sequence[ValidationRecord],
    stopped: bool,
) -> Check:
    """Whether the refined model's runs (``convergence``) give every case the published
    criteria's pass or fail that the model's own runs (``judged``: the last validation's and
    the transfer check's) gave it, and every validation case the band test's too (both decide
    the verdict there). Not run before the study stops, when switched off, when the
    simulator cannot be refined, or where a case cannot be compared: no run of the model with
    the same parameters, or a run (the model's or the refined one) without a verdict (a
    time-out, an instability: the check cannot tell, it says so)."""
    if convergence is None:
        why = (
            "it runs when the study stops"
            if not stopped
            else "no result stored (a study stopped without recommended parameters, or "
            "concluded before this check: rerun parcelfit calibrate to run it)"
        )
        return Check(CONVERGENCE, "not run", why)
    if convergence.reason is not None or not convergence.runs:
        return Check(CONVERGENCE, "not run", convergence.reason or "no runs")
    differ, open_ = [], []
    for v, r in convergence_pairs(convergence.runs, judged):
        if v is None:
            open_.append(f"{r.case}: no run of the model with the same parameters")
        elif v.verdict is None or r.verdict is None:  # a run that did not finish, or not
            ended = [  # comparable: nothing to compare on this case
                f"{who} run ended {x.status}" + (f" ({x.message})" if x.message else "")
                for who, x in (("the model's", v), ("the refined", r))
                if x.verdict is None
            ]
            open_.append(f"{r.case}: " + ", ".join(ended))
        elif v.passed != r.passed:
            differ.append(f"{r.case} {_outcome_word(v)} on the model, {_outcome_word(r)} refined")
        elif v.after_iteration is not None and _band_passed(v) != _band_passed(r):
            # a validation case: its band test decides the verdict too
            word = {True: "passes", False: "fails", None: "has no band"}
            differ.append(
                f"{r.case}'s band test {word[_band_passed(v)]} on the model, "
                f"{word[_band_passed(r)]} refined"
            )
    how = (
        "every mesh spacing and the time step halved"
        if convergence.refinement == 2
        else f"every mesh spacing and the time step divided by {convergence.refinement}"
    )
    if differ:
        also = f"; not compared: {'; '.join(open_)}" if open_ else ""
        return Check(CONVERGENCE, "failed", "; ".join(differ) + f", {how}{also}")
    if open_:
        return Check(CONVERGENCE, "not run", "; ".join(open_))
    cases = ", ".join(r.case for r in convergence.runs)
    return Check(CONVERGENCE, "passed", f"{cases}: the same outcomes with {how}")


def determined(ident: Identifiability | None, stopped: bool) -> Determined:
    """Which parameters the data determine, from the study's analysis (None: not run)."""
    if ident is None:
        why = (
            "too few finished evaluations to analyse"
            if stopped
            else "the analysis runs when the study stops"
        )
        return Determined(False, detail=why)
    return Determined(
        True,
        tuple(p.name for p in ident.parameters if p.determined),
        tuple((p.name, p.verdict) for p in ident.parameters if not p.determined),
    )


def study_verdict(
    results: StudyResults | None,
    cases: Sequence[CaseRecord] | None = None,
    stopped: bool = False,
) -> Verdict:
    """The verdict of a study from its stored results (None: none stored), its test cases
    (the store's ``cases``: a transfer case has role ``transfer``) and whether it stopped. The
    validation judged is the last one (every case of it): that of the recommended parameters,
    which the transfer check simulates too, not an earlier one that passed."""
    group = last_validation(results)
    transfer = () if results is None else results.transfer
    planned = bool(transfer) or any(c.role == "transfer" for c in cases or ())
    return combine(
        criteria_check(group),
        band_check(group),
        transfer_check(transfer, planned, stopped),
        convergence_check(
            None if results is None else results.convergence, [*group, *transfer], stopped
        ),
        determined(None if results is None else results.identifiability, stopped),
    )


__all__ = [
    "BAND",
    "CONVERGENCE",
    "CRITERIA",
    "LEVELS",
    "PARAMETERS",
    "TRANSFER",
    "UNDETERMINED_MEANING",
    "Check",
    "Determined",
    "Level",
    "Outcome",
    "Verdict",
    "band_check",
    "combine",
    "convergence_check",
    "convergence_pairs",
    "criteria_check",
    "determined",
    "last_validation",
    "study_verdict",
    "transfer_check",
]
