"""Compare two ensemble checks placement by placement: does each placement end the same way?

    python scripts/compare_ensembles.py A/ensemble-check.md B/ensemble-check.md
    python scripts/compare_ensembles.py A.md B.md --labels model reference --spin 90

Reads the net rotation of every placement seed that `scripts/ensemble_check.py` writes into its
``ensemble-check.md`` ("- TYPE: r0, r1, ..." under "## RIG, speed setting S") and prints, for every
(setting, type) both files hold: the median rotation in each [deg], how many placements spin
(|rotation| above ``--spin`` degrees) in each, how many end the same way (both spin or both
slide) and the median absolute difference of the rotations [deg]. Two engines (the model against
the reference) or two numerical settings (10 mm against 5 mm contact points) alike.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

_SETTING = re.compile(r"^## .*speed setting (\d+)\s*$")
_ROTATIONS = re.compile(r"^- ([A-Za-z0-9_/]+): (-?[\d.]+(?:, -?[\d.]+)*)\s*$")


def rotations(text: str) -> dict[tuple[int, str], np.ndarray]:
    """(setting, type) -> net rotation per placement seed [deg], from an ensemble check."""
    out: dict[tuple[int, str], np.ndarray] = {}
    setting = None
    for line in text.splitlines():
        m = _SETTING.match(line)
        if m:
            setting = int(m.group(1))
            continue
        m = _ROTATIONS.match(line.strip())
        if m and setting is not None:
            out[(setting, m.group(1))] = np.array([float(v) for v in m.group(2).split(",")])
    return out


def compare(a: np.ndarray, b: np.ndarray, spin: float) -> dict[str, float]:
    """Medians [deg], spins (|rotation| > ``spin`` deg) in each, placements ending alike, and
    the median absolute difference [deg] of two ensembles over the same placement seeds."""
    n = min(len(a), len(b))
    a, b = a[:n], b[:n]
    sa, sb = np.abs(a) > spin, np.abs(b) > spin
    return {
        "n": n,
        "median a": float(np.median(np.abs(a))),
        "median b": float(np.median(np.abs(b))),
        "spins a": int(sa.sum()),
        "spins b": int(sb.sum()),
        "alike": int(np.sum(sa == sb)),
        "difference": float(np.median(np.abs(a - b))),
    }


def main(argv: Sequence[str] | None = None) -> int:
    """Print the comparison (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("first", type=Path)
    ap.add_argument("second", type=Path)
    ap.add_argument("--labels", nargs=2, default=["first", "second"], metavar=("A", "B"))
    ap.add_argument("--spin", type=float, default=90.0, help="a spin turns further [deg]")
    args = ap.parse_args(argv)
    found = []
    for path in (args.first, args.second):
        if not path.is_file():
            ap.error(f"{path}: no such file (an ensemble-check.md of scripts/ensemble_check.py)")
        found.append(rotations(path.read_text()))
    common = sorted(set(found[0]) & set(found[1]))
    if not common:
        ap.error("the two files share no (speed setting, type) with placement rotations")
    a, b = args.labels
    heads = [f"median {a}", f"median {b}", f"spins {a}", f"spins {b}", "alike", "median |diff|"]
    widths = [max(len(h), 7) + 2 for h in heads]
    print(
        f"{'setting':>7}  {'type':<6}"
        + "".join(f"{h:>{w}}" for h, w in zip(heads, widths, strict=True))
    )
    for setting, name in common:
        c = compare(found[0][(setting, name)], found[1][(setting, name)], args.spin)
        cells = [
            f"{c['median a']:.1f}",
            f"{c['median b']:.1f}",
            f"{c['spins a']:d}",
            f"{c['spins b']:d}",
            f"{c['alike']:d}/{c['n']:d}",
            f"{c['difference']:.1f}",
        ]
        print(
            f"{setting:>7}  {name:<6}"
            + "".join(f"{v:>{w}}" for v, w in zip(cells, widths, strict=True))
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
