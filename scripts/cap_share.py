"""How often does MuJoCo's cap of 50 contacts per pair bind on the packaging during a run?

    python scripts/cap_share.py [--rig E3] [--consignment KPBW] [--setting 1] [--seed N]
                                [--every 10] [--scene KEY=VALUE ...]

Steps one run as the simulator does (`parcelfit.sim.mujoco.friction.observed_steps`) and, at
every ``--every``-th step, counts the packaging's contacts with each geom. Prints per geom the
steps sampled in which it touched, the share of them at the cap (exactly 50 contacts: MuJoCo
kept 50 of more), the largest count, and over the capped steps the mean number of contacts the
packaging would have made without the cap (`CapWeights.touching`: triangle corners within the
flex's reach of a box; other geom types are not counted). SI units inside; the scene options
as ``scripts/parameter_effects.py`` takes them. docs/research/contact-cap.md holds the output.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from collections.abc import Sequence

import mujoco
import numpy as np

from parcelfit.runs import TestCase
from parcelfit.sim.mujoco import MujocoSimulator, SimOptions
from parcelfit.sim.mujoco.contact_cap import CapWeights, packaging_contacts
from parcelfit.sim.mujoco.friction import Stepper, observed_steps
from parcelfit.sim.mujoco.mjlog import CountedWarnings
from parcelfit.sim.mujoco.options import MAX_CONTACTS_PER_PAIR, scene_options


def main(argv: Sequence[str] | None = None) -> int:
    """Print the table (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", default="E3")
    ap.add_argument("--consignment", default="KPBW")
    ap.add_argument("--setting", type=int, default=1)
    ap.add_argument("--seed", type=int, default=None, help="placement seed (default: nominal)")
    ap.add_argument("--every", type=int, default=10, help="sample every N-th step")
    ap.add_argument("--scene", nargs="*", default=[], metavar="KEY=VALUE")
    args = ap.parse_args(argv)
    scene = scene_options(args.scene)
    sim = MujocoSimulator(SimOptions(scene=scene, placement_seed=args.seed))
    rows: dict[str, list[tuple[int, float]]] = defaultdict(list)
    weights: list[CapWeights] = []
    sampled = [0]

    def observe(stepper: Stepper) -> None:
        model, data = stepper.model, stepper.data
        if not weights:
            weights.append(CapWeights(model, stepper.shell))
        if round(data.time / model.opt.timestep) % args.every:
            return
        sampled[0] += 1
        _, other, _ = packaging_contacts(data, weights[0].flex)
        for g, count in zip(*np.unique(other, return_counts=True), strict=True):
            capped = count == MAX_CONTACTS_PER_PAIR
            is_box = model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX
            touching = weights[0].touching(model, data, int(g)) if capped and is_box else np.nan
            rows[model.geom(int(g)).name].append((int(count), touching))

    t0 = time.perf_counter()
    with CountedWarnings(), observed_steps(observe):
        result = sim.run({}, TestCase(args.rig, args.consignment, args.setting))
    print(
        f"{args.rig}/{args.consignment}/{args.setting}, placement "
        f"{'nominal' if args.seed is None else args.seed}, scene {args.scene or 'default'}: "
        f"{result.status.name}, {sampled[0]} steps sampled (every {args.every}), "
        f"{time.perf_counter() - t0:.0f} s"
    )
    print(f"{'geom':<20}{'touching':>9}{'at cap':>8}{'largest':>9}{'mean uncapped count':>21}")
    for name, values in rows.items():
        counts = np.array([v[0] for v in values])
        capped = counts == MAX_CONTACTS_PER_PAIR
        touching = np.array([v[1] for v in values])[capped]
        mean = (
            f"{np.nanmean(touching):.0f}" if capped.any() and np.isfinite(touching).any() else "-"
        )
        print(f"{name:<20}{len(values):>9d}{capped.mean():>8.0%}{counts.max():>9d}{mean:>21}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
