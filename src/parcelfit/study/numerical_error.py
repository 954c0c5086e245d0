"""The model's numerical error at a design: what its mesh and time step add to a prediction's band.

A prediction's runs come from a discretised model: a shell meshed at some spacing, contact
points at another, a fixed time step. Where a quantity has not converged in them, the model's
runs sit off the converged answer by an amount no parameter set and no placement reproduces,
and a band built from them alone can miss real runs that the model would meet refined (on the
bundled twin made on a mesh twice as fine as the model's, the exit heading's band held 13 of
30 unseen E1 runs: docs/research/predict-coverage.md). The calibration's convergence check
judges the validation and transfer cases once refined; a prediction is for another design, so
it estimates the error on the design itself.

**Estimate.** The recommended parameters p* (the calibration's; the plausible set's medians
where the store holds no fit, and the record says which) are simulated on the design at K seeded placements, each with
its drives off their mean speeds as the prediction's own runs, once by the model and once by
the model refined R times over (the study's ``validation.refinement``: every mesh spacing and
the time step divided by R, ``with_refinement``), the same placements and drives for both:
matched pairs. Per quantity q (`parcelfit.study.run_scatter.QUANTITIES`) and placement i,

    d_i = q_refined,i - q_model,i            (transit time: divided by q_model,i)
    e_i = d_i R / (R - 1)
    s_num^2 = median(e)^2 + (1.4826 MAD(e))^2

d is only the part of the model's error that the refinement removes: for an error that falls
as h^p with the mesh spacing or step h, the model's error is d R^p / (R^p - 1) (Richardson's
extrapolation). e takes p = 1 (twice d at R = 2), a conservative assumption: MuJoCo's time
stepping is of first order, but an error set by the mesh can fall faster (E1 KP/BW's median
turn 0.8 / 0.3 / 0.2 degrees on 30 / 15 / 7.5 mm meshes, docs/research/convergence-check.md,
where the factor would be nearer 4/3, a second-order error's). s_num is the squared
systematic shift plus the robust variance of the errors about it (MAD the median absolute
deviation, scipy.stats.median_abs_deviation with scale "normal"). Robust for
the reason the real runs' scatter is (`parcelfit.study.run_scatter`): a placement that spins
on one mesh and slides on the other differs by a turn, and one such pair would make the band
span every outcome; such placements are counted (`changed`: the rotation on opposite sides of
`parcelfit.sim.ensemble.SPIN_ANGLE`) and the prediction counts them in its notes. The median and
the MAD are robust to them only while fewer than half the pairs change outcome; from half on, the sd
is the outcomes' spread, and the note says so. The rotation is compared as the absolute angle
it is predicted as (a turn whose sign flips with the mesh moves the exit heading, not it).

**In the band of a real run** s_num joins the real runs' own scatter s_q as an independent
normal term, s^2 = s_q^2 + s_num^2 (`parcelfit.study.run_scatter.real_run_band`): centred on
the model, not shifted to the refined model, because the refined model is not the converged
one either and the sign of what is left is not known. The model's own band (q05, q95) is left
as simulated.

Hand-written because it is a few lines of NumPy over the stored runs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.stats import median_abs_deviation

from parcelfit.sim.ensemble import SPIN_ANGLE
from parcelfit.study.defaults import NUMERICAL_RUNS
from parcelfit.study.run_scatter import QUANTITIES, RELATIVE

FEW_PAIRS = 3  # fewer matched pairs than this give no spread worth the name: the notes say so


@dataclass(frozen=True)
class NumericalError:
    """The model's numerical error at a design, per quantity (module docstring): ``sd`` (SI,
    or a share of the value for the transit time; absent where no pair has the quantity), the
    ``refinement`` it was measured with, the matched ``pairs`` that ended ok on both models of
    the ``runs`` asked for, and how many of them ``changed`` outcome (spin or slide); ``at``
    names the parameters simulated (``recommended`` or the plausible set's ``medians``).
    ``reason`` says why it was not estimated (then ``sd`` is empty)."""

    sd: Mapping[str, float]
    refinement: int
    pairs: int = 0
    changed: int = 0
    reason: str | None = None
    runs: int = 0
    at: str = "recommended"

    def to_json(self) -> dict[str, object]:
        """The stored form (prediction.json)."""
        return {
            "sd": dict(self.sd),
            "refinement": self.refinement,
            "pairs": self.pairs,
            "runs": self.runs,
            "changed": self.changed,
            "at": self.at,
            "reason": self.reason,
        }


def differences(
    model: Sequence[Mapping[str, float | None]],
    refined: Sequence[Mapping[str, float | None]],
    quantity: str,
) -> np.ndarray:
    """d_i of ``quantity`` over the matched pairs (module docstring; unit of the quantity, the
    transit time's a share of the model's), pairs without a finite value on both left out."""
    out = []
    for a, b in zip(model, refined, strict=True):
        va, vb = a.get(quantity), b.get(quantity)
        if va is None or vb is None or not (math.isfinite(va) and math.isfinite(vb)):
            continue
        if quantity in RELATIVE:
            if va == 0:
                continue
            out.append((vb - va) / va)
        else:
            out.append(vb - va)
    return np.asarray(out, float)


def estimate_numerical_error(
    model: Sequence[Mapping[str, float | None] | None],
    refined: Sequence[Mapping[str, float | None] | None],
    refinement: int,
    at: str = "recommended",
) -> NumericalError:
    """s_num per quantity (module docstring) from the quantities of the model's and the model's
    refined ``refinement`` (> 1) times runs at the same placements, in the same order (None: a
    run that did not end ok; its pair is left out); ``at`` names the parameters they ran at."""
    if len(model) != len(refined):
        raise ValueError(f"{len(model)} model runs against {len(refined)} refined ones")
    if refinement < 2:
        raise ValueError(f"refinement {refinement}: a numerical error needs 2 or more")
    runs = len(model)
    pairs = [(a, b) for a, b in zip(model, refined, strict=True) if a is not None and b is not None]
    if not pairs:
        return NumericalError(
            {}, refinement, reason="no placement ended ok on both models", runs=runs, at=at
        )
    a_runs = [a for a, _ in pairs]
    b_runs = [b for _, b in pairs]
    sd = {}
    scale = refinement / (refinement - 1)  # the model's error from the part refining removes
    for q in QUANTITIES:
        d = differences(a_runs, b_runs, q) * scale
        if d.size:
            spread = float(median_abs_deviation(d, scale="normal")) if d.size > 1 else 0.0
            sd[q] = math.sqrt(float(np.median(d)) ** 2 + spread**2)
    changed = 0
    for a, b in pairs:
        ra, rb = a.get("rotation"), b.get("rotation")
        if ra is not None and rb is not None and (ra > SPIN_ANGLE) != (rb > SPIN_ANGLE):
            changed += 1
    return NumericalError(sd, refinement, len(pairs), changed, runs=runs, at=at)


def numerical_notes(error: NumericalError | None) -> list[str]:
    """Sentences for the prediction's notes: why the numerical error was not estimated; how
    many placements changed outcome when the model was refined (and, from half of them on,
    that the sd is then the outcomes' spread); and that it rests on few placements."""
    if error is None:
        return []
    if error.reason is not None:
        return [
            f"the model's numerical error was not estimated ({error.reason}): the band of a "
            "real run holds no error of the mesh or the time step"
        ]
    notes = []
    refined = (
        f"the model refined {error.refinement} times over (every mesh spacing and the time step)"
    )
    if error.changed and 2 * error.changed >= error.pairs:
        notes.append(
            f"at {error.changed} of {error.pairs} placements {refined} changed the outcome "
            "(spin or slide): the design's outcomes are not converged, and the numerical "
            "error's sd is the spread between outcomes, not a mesh or step error"
        )
    elif error.changed:
        notes.append(
            f"at {error.changed} of {error.pairs} placements {refined} changed the outcome "
            "(spin or slide): the design's outcomes are not converged; the numerical error's "
            "sd is robust to them (a median and a robust spread)"
        )
    if error.pairs < error.runs:
        notes.append(
            f"the model's numerical error rests on {error.pairs} of {error.runs} placements "
            "(the others did not end ok on both models)"
        )
    if error.pairs < FEW_PAIRS:
        notes.append(
            f"the model's numerical error rests on {error.pairs} placement(s): a rough "
            "estimate (the simulator takes no placements, or --numerical-runs is small)"
        )
    return notes


__all__ = [
    "NUMERICAL_RUNS",
    "NumericalError",
    "differences",
    "estimate_numerical_error",
    "numerical_notes",
]
