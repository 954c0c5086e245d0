"""How much of each test case's transit-time scatter the belt speeds explain.

    python scripts/transit_adjustment.py DATASET [DATASET ...]

For every test case of the datasets, fits the adjustment of
`parcelfit.metrics.transit_adjustment` on its real runs and prints a markdown table: runs, the
transit times' standard deviation as measured and adjusted [ms], and the coefficients on the
start and end speeds [s per m/s] (0 where the adjustment explains nothing and is not kept).
The figures in docs/method.md ("Transit times adjusted for the belt speeds") come from
``python scripts/transit_adjustment.py src/parcelfit/data/examples/twin
examples/e3-e1-kpbw-joint/twin-e2``.
"""

from __future__ import annotations

import sys

from parcelfit.errors import ParcelfitError
from parcelfit.metrics.transit_adjustment import fit_transit_adjustment
from parcelfit.runs import load_dataset


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__, file=sys.stderr)
        return 2
    print("| dataset | case | runs | sd measured [ms] | sd adjusted [ms] | a_start | a_end |")
    print("|---|---|---|---|---|---|---|")
    for folder in argv:
        data = load_dataset(folder)
        for case in data.cases:
            adj = fit_transit_adjustment(data[case].runs)
            a_start, a_end = adj.coefficients
            print(
                f"| {data.name} | {case.label} | {adj.runs} | {adj.sd_before * 1e3:.1f} | "
                f"{adj.sd_after * 1e3:.1f} | {a_start:+.2f} | {a_end:+.2f} |"
            )
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv[1:]))
    except ParcelfitError as exc:  # a missing or malformed dataset: say what and how to fix it
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
