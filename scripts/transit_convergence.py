"""Time-step convergence of the transit time on every rig, for scene variants side by side.

    python scripts/transit_convergence.py
    python scripts/transit_convergence.py --cases E1/KPBW/3 E3/BW/1 --variants impratio=1 impratio=10
    python scripts/transit_convergence.py --steps 1200 2400 4800 9600 --seeds -1 1 2

For each test case (default parameters), placement seed (-1: the nominal pose), scene variant
(``KEY=VALUE[,KEY=VALUE]`` of `SceneOptions`, e.g. ``impratio=10``) and time step 1/N s, the run
is simulated and its transit time compared with the finest step's run of the same case,
placement and variant. The transit time is the quantity a calibration leans on most (the cost's
transit term, the validation's first criterion); a step error in it biases the friction
coefficients that set it. Writes ``docs/research/transit-convergence.md`` (``--out``).
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from parcelfit.runs import TestCase
from parcelfit.sim.mujoco import MujocoSimulator, SceneOptions, SimOptions
from parcelfit.sim.mujoco.options import parse_scene_options

DEFAULT_CASES = (
    "E1/KPBW/1",
    "E1/KPBW/3",
    "E1/BW/3",
    "E2a/KPBW/2",
    "E2b/KPBW/2",
    "E3/KPBW/1",
    "E3/BW/1",
)


def simulate(job: tuple[str, int, str, int]) -> tuple[tuple, float | None, float, float]:
    """(job, transit time [s] or None, net rotation [deg], wall time [s]) of one run."""
    case_label, seed, variant, n = job
    options = parse_scene_options(filter(None, variant.split(",")))
    scene = SceneOptions(timestep=1 / n, **options)  # type: ignore[arg-type]
    sim = MujocoSimulator(SimOptions(scene=scene))
    if seed >= 0:
        sim = sim.with_placement(seed)
    case = TestCase.parse(case_label)
    t0 = time.perf_counter()
    res = sim.run(sim.consignment(case.consignment).parameter_values(), case)
    if not res.ok or res.run is None:
        return job, None, math.nan, time.perf_counter() - t0
    theta = np.unwrap(np.asarray(res.run.trajectory.theta, dtype=float))
    return job, res.run.transit_time, math.degrees(theta[-1] - theta[0]), time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--cases", nargs="+", default=list(DEFAULT_CASES))
    ap.add_argument("--seeds", nargs="+", type=int, default=[-1, 1])
    ap.add_argument("--steps", nargs="+", type=int, default=[1200, 2400, 4800], help="N of 1/N s")
    ap.add_argument("--variants", nargs="+", default=["impratio=1", "impratio=10"])
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--out", type=Path, default=Path("docs/research"))
    args = ap.parse_args()
    steps = sorted(set(args.steps))
    jobs = list(itertools.product(args.cases, args.seeds, args.variants, steps))
    t0 = time.perf_counter()
    res: dict[tuple, tuple[float | None, float, float]] = {}
    with ProcessPoolExecutor(args.workers) as ex:
        for job, transit, rot, wall in ex.map(simulate, jobs):
            res[job] = (transit, rot, wall)
            print(
                f"{job}: transit {transit} s, rotation {rot:.1f} deg, {wall:.1f} s wall", flush=True
            )
    finest = steps[-1]
    head = " | ".join(f"1/{n} - 1/{finest} [ms]" for n in steps[:-1])
    lines = [
        "# Transit-time convergence in the time step",
        "",
        f"Written by `python scripts/transit_convergence.py --cases {' '.join(args.cases)} --seeds "
        f"{' '.join(map(str, args.seeds))} --steps {' '.join(map(str, steps))} --variants "
        f"{' '.join(args.variants)}`: default parameters, seed -1 the nominal placement; each run's "
        f"transit time against the 1/{finest} s run of the same case, placement and variant.",
        "",
        f"| case | seed | variant | transit at 1/{finest} [s] | {head} | rotations [deg] | wall at 1/{steps[0]} [s] |",
        "|---|---|---|---|" + "---|" * (len(steps) - 1) + "---|---|",
    ]
    worst: dict[tuple[str, int], list[float]] = {}
    for case, seed, variant in itertools.product(args.cases, args.seeds, args.variants):
        r = [res[(case, seed, variant, n)] for n in steps]
        ref = r[-1][0]
        diffs = [None if x[0] is None or ref is None else 1e3 * (x[0] - ref) for x in r[:-1]]
        for n, dv in zip(steps[:-1], diffs, strict=True):
            if dv is not None:
                worst.setdefault((variant, n), []).append(abs(dv))
        lines.append(
            f"| {case} | {seed if seed >= 0 else 'nominal'} | {variant} | "
            f"{'-' if ref is None else f'{ref:.4f}'} | "
            + " | ".join("-" if v is None else f"{v:+.1f}" for v in diffs)
            + f" | {' / '.join(f'{x[1]:.0f}' for x in r)} | {r[0][2]:.1f} |"
        )
    lines.append("")
    for (variant, n), g in sorted(worst.items()):
        lines.append(
            f"- {variant}, 1/{n} s: |transit - transit at 1/{finest} s| median {np.median(g):.1f} ms, "
            f"largest {max(g):.1f} ms over {len(g)} runs"
        )
    lines += ["", f"Wall time {time.perf_counter() - t0:.0f} s on {args.workers} processes."]
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "transit-convergence.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
