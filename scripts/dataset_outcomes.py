"""What the runs of a dataset did, test case by test case: transit times and net rotations.

Usage:
    python scripts/dataset_outcomes.py DATASET [--against OTHER] [--cases E3/KPBW/1 ...]

For each test case of DATASET (a folder with a dataset.yaml, tracked or made by `parcelfit
synth`): the number of runs, the median transit time [s], the median net rotation [deg] (the
unwrapped heading's change from the first to the last sample, `parcelfit.sim.ensemble.rotation`),
the shares of runs turning more than 90 and 180 degrees, and each run's rotation. With
``--against`` a second dataset's same cases are printed beside it, run by run (runs matched by
their id), so that a regenerated dataset can be compared with the one it replaces.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from pathlib import Path

from parcelfit.runs import TestCase
from parcelfit.runs.dataset import CaseData, load_dataset
from parcelfit.sim.ensemble import Member, rotation, summarise
from parcelfit.sim.protocol import SimStatus


def case_summary(case: CaseData) -> dict[str, object]:
    """One case's outcome: runs, median transit [s], median rotation [deg], shares of runs
    above 90 and 180 degrees [-] and each run's rotation [deg] by run id; the statistics are
    `parcelfit.sim.ensemble.summarise`'s, the real runs taken as an ensemble's members."""
    members = [
        Member(k, SimStatus.OK, r.transit_time, rotation(r.trajectory), r, 0.0)
        for k, r in enumerate(case.runs)
    ]
    summary = summarise(members)
    return {
        "runs": len(case.runs),
        "median_transit": summary.transit_median,
        "median_rotation": math.degrees(summary.rotation_median),
        "above_90": summary.share_over_90,
        "above_180": summary.share_over_180,
        "rotations": {m.run.id: math.degrees(m.rotation) for m in members},
    }


def _line(label: str, s: dict[str, object]) -> str:
    return (
        f"  {label}: {s['runs']} runs, median transit {s['median_transit']:.3f} s, median "
        f"rotation {s['median_rotation']:.1f} deg, above 90 / 180 deg "
        f"{100 * s['above_90']:.0f} % / {100 * s['above_180']:.0f} %"
    )


def report(folder: Path, against: Path | None = None, cases: Sequence[str] = ()) -> list[str]:
    """The printed lines for DATASET (and OTHER beside it, where given)."""
    ds = load_dataset(folder)
    other = load_dataset(against) if against is not None else None
    wanted = [TestCase.parse(c) for c in cases] or sorted(ds.cases)
    lines: list[str] = []
    for case in wanted:
        here = case_summary(ds[case])
        lines.append(f"{case.label}")
        lines.append(_line("this", here))
        rot_here: dict[str, float] = here["rotations"]  # type: ignore[assignment]
        if other is not None and case in other.cases:
            there = case_summary(other[case])
            lines.append(_line("other", there))
            rot_there: dict[str, float] = there["rotations"]  # type: ignore[assignment]
            for run_id, deg in rot_here.items():
                was = rot_there.get(run_id)
                was_text = f"{was:.1f}" if was is not None else "-"
                lines.append(f"    {run_id}: {deg:.1f} deg (other {was_text})")
        else:
            lines.append("    rotations [deg]: " + ", ".join(f"{v:.1f}" for v in rot_here.values()))
    return lines


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("dataset", type=Path)
    parser.add_argument("--against", type=Path, default=None, help="a dataset to compare with")
    parser.add_argument("--cases", nargs="*", default=[], help="test cases, e.g. E3/KPBW/1")
    args = parser.parse_args(argv)
    print("\n".join(report(args.dataset, args.against, args.cases)))


if __name__ == "__main__":
    main()
