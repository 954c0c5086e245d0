"""Mesh and time-step convergence of the MuJoCo parcel model (writes docs/research/convergence.md).

For E3 at speed setting 1 (KPBW: rigid content; PB: soft content) the run is repeated at
several shell mesh spacings and time steps; each run is compared with the finest one by the
largest distance between the two parcel centres at equal times [mm] over the first 1.2 s, the
final heading difference [deg] and the transit time difference [ms], next to its wall time.

    python scripts/convergence_study.py [--quick] [--out FILE]

The tables are rewritten; the hand-written text after the marker line (`MARKER`) in the output
file is kept.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

from parcelfit.runs import TestCase
from parcelfit.sim.mujoco import MujocoSimulator, SceneOptions, SimOptions

OUT = Path(__file__).resolve().parents[1] / "docs" / "research" / "convergence.md"
HORIZON = 1.2  # s, compared span


def run(case: TestCase, **scene: float) -> tuple:
    sim = MujocoSimulator(SimOptions(scene=SceneOptions(**scene), duration=1.5))
    t0 = time.perf_counter()
    res = sim.run({}, case)
    return res, time.perf_counter() - t0


def compare(ref, other) -> tuple[float, float, float]:
    a, b = ref.run.trajectory, other.run.trajectory
    t = np.arange(0, HORIZON, 1 / 60)
    dx = np.interp(t, a.t, a.x) - np.interp(t, b.t, b.x)
    dy = np.interp(t, a.t, a.y) - np.interp(t, b.t, b.y)
    dth = math.degrees(np.interp(HORIZON, a.t, a.theta) - np.interp(HORIZON, b.t, b.theta))
    ta, tb = ref.run.transit_time, other.run.transit_time
    dtt = float("nan") if ta is None or tb is None else 1e3 * (tb - ta)
    return 1e3 * float(np.max(np.hypot(dx, dy))), dth, dtt


# Everything after this line in the output file is written by hand (readings, earlier
# measurements) and is kept when the script rewrites the tables above it.
MARKER = (
    "<!-- The tables above are written by scripts/convergence_study.py; the text below is kept. -->"
)


def kept_text(path: Path) -> str:
    """The hand-written part of an earlier output file: everything after `MARKER` ("" if the
    file or the marker is missing)."""
    if not path.is_file():
        return ""
    _, found, tail = path.read_text(encoding="utf-8").partition(MARKER)
    return tail.lstrip("\n") if found else ""


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer variants (for a smoke test)")
    ap.add_argument("--out", type=Path, default=OUT, help=f"file to write (default {OUT.name})")
    args = ap.parse_args()
    lines = [
        "# Convergence of the parcel model",
        "",
        "Written by `scripts/convergence_study.py` on the 2-core development machine. Each run of E3 at",
        "speed setting 1 is compared with the finest run of its block: largest centre distance at equal",
        f"times over the first {HORIZON} s [mm], heading difference at {HORIZON} s [deg], transit-time",
        "difference [ms] (LS2 is crossed after 1.2 s, so runs without a transit time show nan), and",
        "wall time for 1.5 s simulated [s]. The spacing blocks run at the default step of their",
        "shell (1/2400 s around the rigid KP/BW content, 1/1200 s around PB's soft one).",
        "",
    ]
    blocks = [
        # each block at the default step of its shell (1/2400 s rigid, 1/1200 s soft contents)
        ("KPBW", "spacing", [0.015, 0.02, 0.03, 0.04, 0.05], {"timestep": 1 / 2400}),
        ("KPBW", "timestep", [1 / 9600, 1 / 4800, 1 / 2400, 1 / 1200, 1 / 600], {"spacing": 0.03}),
        ("PB", "soft_shell_spacing", [0.03, 0.04, 0.05], {"timestep": 1 / 1200}),
    ]
    if args.quick:
        blocks = [("KPBW", "spacing", [0.03, 0.05], {"timestep": 1 / 2400})]
    for cons, key, values, fixed in blocks:
        case = TestCase("E3", cons, 1)
        results = [(v, *run(case, **{key: v}, **fixed)) for v in values]
        ref = results[0][1]
        label = "time step [ms]" if key == "timestep" else f"{key} [mm]"
        lines += [
            f"## {cons}: {key}",
            "",
            f"| {label} | status | max centre distance [mm] | "
            "heading diff [deg] | transit diff [ms] | wall [s] |",
            "|---|---|---|---|---|---|",
        ]
        for v, res, wall in results:
            d, h, tt = compare(ref, res) if res.run is not None else (float("nan"),) * 3
            lines.append(
                f"| {v * 1e3:.3g} | {res.status.value} | {d:.1f} | {h:.2f} | {tt:.1f} | {wall:.1f} |"
            )
            print(
                cons,
                key,
                v,
                res.status.value,
                f"{d:.1f} mm {h:.2f} deg {tt:.1f} ms {wall:.1f} s",
                flush=True,
            )
        lines.append("")
    lines += [MARKER, "", kept_text(args.out)]
    args.out.write_text("\n".join(lines).rstrip("\n") + "\n", encoding="utf-8")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
