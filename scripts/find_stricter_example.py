"""Search the bundled twin data for a polybag simulation that the published validation criteria
pass and the stricter band test fails (the case `parcelfit demo` shows in its report).

    python scripts/find_stricter_example.py [--workers 2]

Simulates E3 / PB at speed setting 2 over a grid of belt and guide-plate friction values (the
other parameters at the twin data's truth) and prints, for each, the three published criteria
and the band test. The chosen set goes into parcelfit.demo.STRICTER_EXAMPLE.
"""

from __future__ import annotations

import argparse
import itertools
import multiprocessing
from concurrent.futures import ProcessPoolExecutor

from parcelfit.demo import demo_dataset
from parcelfit.metrics import select_reference, validate
from parcelfit.runs import TestCase, load_dataset
from parcelfit.sim.mujoco import MujocoSimulator

CASE = TestCase("E3", "PB", 2)
TRUTH = {"mu_d_BePa": 0.50, "mu_d_MePa": 0.20, "E_Pa": 120.0, "k_MePa": 300.0}


def verdict(user: dict[str, float]) -> tuple[dict[str, float], str]:
    sim = MujocoSimulator()
    params = sim.consignment("PB").parameter_values({**TRUTH, **user})
    res = sim.run(params, CASE)
    if not res.ok or res.run is None:
        return user, f"simulation {res.status.value}"
    sel = select_reference(load_dataset(demo_dataset())[CASE])
    v = validate(res.run.trajectory, res.run.transit_time, sel)
    env = v.envelope
    return user, (
        f"published {'PASS' if v.passed else 'fail'} (tt {v.transit_time.passed}, xy "
        f"{v.xy.passed}, theta {v.theta.passed}); band {'PASS' if env and env.passed else 'fail'}"
        + (
            f" (y {env.inside_y:.2f}, theta {env.inside_theta:.2f} inside, worst "
            f"{env.worst_y * 1e3:.1f} mm)"
            if env
            else ""
        )
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    grid = [
        {"mu_d_BePa": b, "mu_d_MePa": m}
        for b, m in itertools.product((0.35, 0.40, 0.45, 0.55, 0.60), (0.15, 0.25, 0.35))
    ]
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(args.workers, mp_context=ctx) as pool:
        for user, text in pool.map(verdict, grid):
            print(user, text, flush=True)


if __name__ == "__main__":
    main()
