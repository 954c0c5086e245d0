"""Replay every "real" run of a twin dataset from its own first tracked pose.

Usage:
    python scripts/twin_replay.py TWIN_FOLDER --case E3/KPBW/1 [--step 0.15] [--workers 2]
                                  [--timestep 1/2400] [--truth-only]

A twin dataset (``parcelfit twin`` or ``benchmarks/bench_twin.py``) knows its hidden truth
(``truth.yaml``). This script starts the model (default scene: the calibrated model's mesh and
time step) at the first sample (x, y, theta) of each real run, so placement is no longer a
difference between the two sides, and simulates it with the truth and with each calibrated
parameter moved by +-``step`` of its screening range. Per parameter set it prints, against the
paired real run: the normalised distance D_j = DTW_xy^2 / max D_xy + DTW_theta^2 / max D_theta
(equation 3's scales, the real runs' largest pairwise distances), its mean and median, each
replay's net rotation [deg], and the transit-time residuals T_sim - T_real [ms] (mean and
rms). What is left at the truth is what the cost cannot explain by parameters: specimen,
belt-speed and tracking variation, and the model's step and mesh against the twin's. If a
parameter's replays differ from the truth's by less than that, the data of this case cannot
determine it, however the optimiser searches.

Measured output is quoted in docs/twin-benchmark.md.
"""

from __future__ import annotations

import argparse
import math
from concurrent.futures import ProcessPoolExecutor
from fractions import Fraction
from pathlib import Path

import numpy as np

from parcelfit.metrics.dtw import dtw_distance
from parcelfit.metrics.reference import select_reference
from parcelfit.runs import TestCase, Trajectory, read_truth
from parcelfit.runs.dataset import load_dataset
from parcelfit.sim.ensemble import rotation
from parcelfit.sim.mujoco.options import SceneOptions
from parcelfit.sim.mujoco.rig import load_rig
from parcelfit.sim.mujoco.simulator import MujocoSimulator, SimOptions
from parcelfit.sim.params import parameter

CALIBRATED = ("mu_d_BePa", "mu_d_MePa", "E_Pa", "k_MePa")


def _replay(
    job: tuple[TestCase, dict[str, float], tuple[float, float, float], float | None],
) -> tuple:
    """Simulate ``case`` with catalogue-unit ``values`` from an absolute pose (m, m, rad), at
    time step ``timestep`` [s] (None: the default)."""
    case, values, (x0, y0, th0), timestep = job
    rig = load_rig(case.rig)
    sx, sy = rig.start.position
    offset = (x0 - sx, y0 - sy, math.degrees(th0) - rig.start.heading)
    sim = MujocoSimulator(SimOptions(scene=SceneOptions(start_offset=offset, timestep=timestep)))
    si = {k: parameter(k).to_si(v) for k, v in values.items()}
    res = sim.run(si, case)
    if not res.ok or res.run is None:
        return None, None
    return res.run.trajectory, res.run.transit_time


def _rotation_deg(trajectory: Trajectory) -> float:
    return math.degrees(rotation(trajectory))


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("folder", help="twin folder: the dataset itself or a folder with data/ in it")
    ap.add_argument("--case", default="E3/KPBW/1")
    ap.add_argument("--truth-only", action="store_true", help="replay the truth only")
    ap.add_argument("--step", type=float, default=0.15, help="fraction of the range [-]")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--timestep", type=Fraction, default=None, help="model time step [s], e.g. 1/2400"
    )
    args = ap.parse_args()

    folder = Path(args.folder)
    data = folder / "data" if (folder / "data" / "dataset.yaml").is_file() else folder
    dataset = load_dataset(data)
    case = TestCase.parse(args.case)
    truth = read_truth(data, case.consignment)
    if not truth:
        raise SystemExit(f"{data}: no hidden truth of {case.consignment} (truth.yaml): not a twin")
    case_data = dataset[case]
    ref = select_reference(case_data)
    real_t = np.array([r.transit_time for r in case_data.runs], dtype=float)
    poses = [
        (float(r.trajectory.x[0]), float(r.trajectory.y[0]), float(r.trajectory.theta[0]))
        for r in case_data.runs
    ]

    sets: list[tuple[str, dict[str, float]]] = [("truth", dict(truth))]
    for name in () if args.truth_only else CALIBRATED:
        rng = parameter(name).range_for("rigid")
        for sign in (-1, 1):
            v = truth[name] + sign * args.step * (rng.high - rng.low)
            if rng.low <= v <= rng.high:
                sets.append((f"{name} {'+' if sign > 0 else '-'}{args.step:g}", {**truth, name: v}))

    step = "the default time step" if args.timestep is None else f"time step {args.timestep} s"
    print(f"# {case.label}: {len(poses)} real runs replayed from their first pose, {step}")
    print(
        "real rotations [deg]: "
        + " ".join(f"{_rotation_deg(r.trajectory):.0f}" for r in case_data.runs)
    )
    print(
        "| set | mean D | median D | runs with D > 1 | dT mean [ms] | dT rms [ms] | rotations [deg] |"
    )
    print("|---|---|---|---|---|---|---|")
    timestep = None if args.timestep is None else float(args.timestep)
    window = ref.comparison.window
    with ProcessPoolExecutor(args.workers) as pool:
        for label, values in sets:
            out = list(pool.map(_replay, [(case, values, p, timestep) for p in poses]))
            if any(t is None for t, _ in out):
                print(f"| {label} | a replay failed | | | | | |")
                continue
            prepared = [ref.comparison.prepare(t) for t, _ in out]
            # each replay against its own real run only (the pairs, not every combination)
            d = np.array(
                [
                    dtw_distance(p.xy, xy, window) ** 2 / ref.max_xy
                    + dtw_distance(p.theta, theta, window) ** 2 / ref.max_theta
                    for p, xy, theta in zip(prepared, ref.xy_series, ref.theta_series, strict=True)
                ]
            )
            dt = (np.array([t for _, t in out], dtype=float) - real_t) * 1e3
            rots = " ".join(f"{_rotation_deg(t):.0f}" for t, _ in out)
            print(
                f"| {label} | {d.mean():.3g} | {np.median(d):.3g} | {int((d > 1).sum())} | "
                f"{np.nanmean(dt):+.1f} | {math.sqrt(np.nanmean(dt**2)):.1f} | {rots} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
