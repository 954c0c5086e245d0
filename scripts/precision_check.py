"""Which parameters can a study's test cases determine, given the real runs' scatter?

    python scripts/precision_check.py STUDY.yaml [--placements 10] [--candidates E2a/KPBW/2 ...]
                                      [--at NAME=VALUE ...] [--adjust-transit] [--workers 2]
                                      [--out precision-check]

The same as ``parcelfit precision`` (`parcelfit.study.precision_check`): for every parameter of
the study, the study's fitted test cases (and, as candidates, its validation and transfer cases
and any named with ``--candidates``, real runs from the first case's dataset) are simulated with
the parameter at the low and the high end of its range, every other parameter at the centre of
its range (or at ``--at`` values, catalogue units, e.g. a twin's hidden truth), over
``--placements`` seeded placements (seeds 1..K, the same at both ends and, for the placements'
scatter, at the point itself).
`parcelfit.study.precision` turns the change of the mean statistics (transit time, rotation,
lateral drift; with ``--adjust-transit`` the transit time adjusted for the belt speeds each run
rode at, `parcelfit.metrics.transit_adjustment`) and the real runs' scatter into the 95 %
half-width each parameter could be determined to, as a share of its range: the fitted cases
jointly, each alone, and the fitted cases plus each candidate. A half-width above 10 % says
that no calibration on these cases can be expected to recover the parameter within 10 % of its
range. Writes ``precision-check.md`` and prints it; resumes from ``statistics.json`` in the
output folder. The simulations are cases x (parameters x 2 + 1) x K.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from parcelfit.atomic import write_text_atomic
from parcelfit.errors import ParcelfitError
from parcelfit.progress import ProgressEvent
from parcelfit.sim.params import parse_assignments
from parcelfit.study.precision_check import TABLE_FILE, command_line, run_precision_check


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("study", type=Path)
    ap.add_argument("--placements", type=int, default=10)
    ap.add_argument("--candidates", nargs="*", default=[], metavar="RIG/TYPE/SETTING")
    ap.add_argument("--at", nargs="*", default=[], metavar="NAME=VALUE")
    ap.add_argument(
        "--adjust-transit",
        action="store_true",
        help="compare transit times adjusted for the belt speeds each run rode at",
    )
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--out", type=Path, default=Path("precision-check"))
    args = ap.parse_args(argv)

    def say(event: ProgressEvent) -> None:
        if event.done is None or event.done % 20 == 0 or event.done == event.total:
            print(f"  {event.message}", file=sys.stderr)

    check = run_precision_check(
        args.study,
        args.out,
        placements=args.placements,
        candidates=args.candidates,
        at=parse_assignments(args.at),
        adjust_transit=args.adjust_transit,
        workers=args.workers,
        progress=say,
    )
    command = command_line(
        "python scripts/precision_check.py",
        args.study,
        placements=args.placements,
        candidates=args.candidates or [],
        at=args.at or [],
        adjust_transit=args.adjust_transit,
        repeated=False,
    )
    text = check.markdown(command, args.workers)
    write_text_atomic(args.out / TABLE_FILE, text)
    print(text)
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except ParcelfitError as exc:  # a bad study, dataset or --at: say what and how to fix it
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
