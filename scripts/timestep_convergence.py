"""Time-step convergence of transit time and rotation, with and without the shell's membrane cap.

    python scripts/timestep_convergence.py                     # E3 KPBW, 4 placements
    python scripts/timestep_convergence.py --types KPBW KP --seeds -1 0 6 13 --caps 0 3.125e4
    python scripts/timestep_convergence.py --seeds -1 --set E_Pa=200   # another parameter value

For each consignment type, placement (seed -1: the nominal pose) and membrane cap (0: none, the
shell's E_Pa t_Pa as given; otherwise `SceneOptions.membrane_cap` [N/m]), the E3 run at speed
setting 1 is simulated at time steps 1/600, 1/1200 and 1/2400 s, and each is compared with the
1/2400 s run of the same variant: transit time difference [ms] and net rotation [deg]. Writes
``docs/research/timestep-convergence.md`` (``--out``, or ``timestep-convergence-<set>.md`` with ``--set``).
Default parameters unless ``--set NAME=VALUE`` (catalogue units) says otherwise (E_Pa 1000
N/mm^2, t_Pa 0.5 mm: membrane stiffness E t = 5e5 N/m).
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
from parcelfit.sim.params import parse_assignments

STEPS = (1 / 600, 1 / 1200, 1 / 2400)
DURATION = 2.6  # s: long enough for a parcel that catches on the plate to reach LS2


def simulate(
    job: tuple[str, int, float, float, tuple[str, ...]],
) -> tuple[tuple, float | None, float, float]:
    """(job, transit time [s] or None, net rotation [deg], wall time [s]) of one run."""
    cons, seed, cap, dt, assignments = job
    scene = SceneOptions(timestep=dt, membrane_cap=cap or None)
    sim = MujocoSimulator(SimOptions(scene=scene, duration=DURATION))
    if seed >= 0:
        sim = sim.with_placement(seed)
    t0 = time.perf_counter()
    params = sim.consignment(cons).parameter_values(parse_assignments(assignments))
    run = sim.run(params, TestCase("E3", cons, 1)).run
    assert run is not None, f"{job} failed"
    tr = run.trajectory
    return (
        job,
        run.transit_time,
        math.degrees(float(tr.theta[-1] - tr.theta[0])),
        (time.perf_counter() - t0),
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--types", nargs="+", default=["KPBW"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[-1, 0, 6, 13])
    ap.add_argument("--caps", nargs="+", type=float, default=[0.0, 3.125e4])
    ap.add_argument("--set", nargs="*", default=[], help="NAME=VALUE in the catalogue's unit")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--out", type=Path, default=Path("docs/research"))
    args = ap.parse_args()
    given = tuple(args.set)
    jobs = list(itertools.product(args.types, args.seeds, args.caps, STEPS, [given]))
    t0 = time.perf_counter()
    res = {}
    with ProcessPoolExecutor(args.workers) as ex:
        for job, transit, rot, wall in ex.map(simulate, jobs):
            res[job[:4]] = (transit, rot, wall)
            print(
                f"{job}: transit {transit} s, rotation {rot:.1f} deg, {wall:.1f} s wall", flush=True
            )
    lines = [
        "# Time-step convergence on E3, with and without the membrane cap",
        "",
        f"Written by `python scripts/timestep_convergence.py --types {' '.join(args.types)} --seeds "
        f"{' '.join(map(str, args.seeds))} --caps {' '.join(f'{c:g}' for c in args.caps)}"
        + (f" --set {' '.join(given)}" if given else "")
        + "`: E3 speed setting 1, "
        + (
            f"parameters at their defaults but {', '.join(given)}"
            if given
            else "default parameters"
        )
        + " (membrane stiffness E_Pa t_Pa = 5e5 N/m at the defaults), seed -1 the nominal "
        "placement. Each run against the 1/2400 s run of the same type, placement and cap.",
        "",
        "| type | seed | membrane cap [N/m] | rotation 1/600 / 1/1200 / 1/2400 [deg] | transit at "
        "1/2400 [s] | transit 1/600 - 1/2400 [ms] | transit 1/1200 - 1/2400 [ms] | wall 1/600 [s] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    gaps: dict[float, list[float]] = {c: [] for c in args.caps}
    for cons, seed, cap in itertools.product(args.types, args.seeds, args.caps):
        r = [res[(cons, seed, cap, dt)] for dt in STEPS]
        ref = r[2][0]
        d = [None if x[0] is None or ref is None else 1e3 * (x[0] - ref) for x in r[:2]]
        if d[0] is not None:
            gaps[cap].append(abs(d[0]))
        cap_text = "none" if not cap else f"{cap:g}"
        lines.append(
            f"| {cons} | {seed if seed >= 0 else 'nominal'} | {cap_text} | "
            f"{' / '.join(f'{x[1]:.0f}' for x in r)} | {ref if ref is None else f'{ref:.3f}'} | "
            + " | ".join("-" if v is None else f"{v:+.1f}" for v in d)
            + f" | {r[0][2]:.1f} |"
        )
    lines.append("")
    for cap, g in gaps.items():
        cap_text = "no cap" if not cap else f"cap {cap:g} N/m"
        if g:
            lines.append(
                f"- {cap_text}: |transit 1/600 - 1/2400| median {np.median(g):.1f} ms, "
                f"largest {max(g):.1f} ms over {len(g)} runs"
            )
    lines += ["", f"Wall time {time.perf_counter() - t0:.0f} s on {args.workers} processes."]
    args.out.mkdir(parents=True, exist_ok=True)
    suffix = "-" + "-".join(g.replace("=", "") for g in given) if given else ""
    (args.out / f"timestep-convergence{suffix}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
