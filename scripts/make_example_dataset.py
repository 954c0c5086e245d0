"""Generate the small SYNTHETIC example dataset bundled with parcelfit (E1 "Belt-Belt").

Not measured data: every run is simulated with MuJoCo as a rigid box (the consignment's
published outer dimensions and mass) carried by belt 1 (0.62 m/s) onto belt 2 (0.81, 1.00 or
1.57 m/s for speed settings 1-3), placed at 30 degrees by the start guide. The run-to-run
variability of real experiments is imitated: per run a friction deviation (+-5 %), placement
jitter (+-5 mm, +-2 degrees), belt speeds off their mean by up to 3 %, and 1 mm / 0.3 degree
tracking noise. Transit time: the parcel outline's first crossing of two virtual light barriers.

It serves as stand-in input for the statistics and reference-run selection until datasets made
with the full flexible-parcel models exist. Run from the repository root:

    python scripts/make_example_dataset.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import mujoco
import numpy as np

from parcelfit.runs import Box, CaseData, Run, TestCase, Trajectory, save_dataset

OUT = (
    Path(__file__).resolve().parents[1] / "src" / "parcelfit" / "data" / "examples" / "e1-synthetic"
)
SEED = 20261122
BELT1 = 0.62
BELT2 = {1: 0.81, 2: 1.00, 3: 1.57}
# consignment: (outer L, W, H [m], mass [kg], belt friction (synthetic choice))
TYPES = {
    "KPBW": (0.275, 0.20, 0.02, 0.140, 0.45),
    "PB": (0.315, 0.225, 0.02, 0.180, 0.55),
    "KP": (0.32, 0.25, 0.03, 0.380, 0.40),
    "BW": (0.20, 0.15, 0.02, 0.080, 0.50),
}
BARRIERS_X = (-0.30, 1.00)  # light barriers across the belt [m]
RUNS_PER_CASE = 10
RATE = 60.0
DT = 1.0 / 1200.0  # 20 steps per 60 Hz frame


def scene(
    size: tuple[float, float, float],
    mass: float,
    mu: float,
    v1: float,
    v2: float,
    x0: float,
    y0: float,
    yaw_deg: float,
) -> str:
    L, W, H = size
    return f"""<mujoco><compiler angle="degree"/>
<option timestep="{DT}" integrator="implicitfast" cone="elliptic"/>
<worldbody>
<geom type="box" size="0.5 0.3 0.02" pos="-0.503 0 -0.02" surfacevel="{v1} 0 0 0 0 0"
      friction="{mu} 0.005 0.0001" priority="2"/>
<geom type="box" size="1.2 0.3 0.02" pos="1.2 0 -0.02" surfacevel="{v2} 0 0 0 0 0"
      friction="{mu} 0.005 0.0001" priority="2"/>
<body pos="{x0} {y0} {H / 2 + 1e-4}" euler="0 0 {yaw_deg}"><freejoint/>
<geom type="box" size="{L / 2} {W / 2} {H / 2}" mass="{mass}" friction="{mu} 0.005 0.0001"/>
</body></worldbody></mujoco>"""


def first_crossing(t: np.ndarray, front: np.ndarray, x: float) -> float:
    i = int(np.argmax(front >= x))
    if front[i] < x:
        raise RuntimeError("barrier never crossed")
    if i == 0:
        return float(t[0])
    return float(np.interp(x, front[i - 1 : i + 1], t[i - 1 : i + 1]))


def simulate(rng: np.random.Generator, kind: str, setting: int) -> tuple[Trajectory, float]:
    L, W, H, mass, mu = TYPES[kind]
    mu *= 1 + rng.uniform(-0.05, 0.05)
    v1 = BELT1 * (1 + rng.uniform(-0.03, 0.03))
    v2 = BELT2[setting] * (1 + rng.uniform(-0.03, 0.03))
    x0, y0 = -0.60 + rng.uniform(-0.005, 0.005), rng.uniform(-0.005, 0.005)
    yaw = 30 + rng.uniform(-2, 2)
    model = mujoco.MjModel.from_xml_string(scene((L, W, H), mass, mu, v1, v2, x0, y0, yaw))
    data = mujoco.MjData(model)
    data.qvel[0] = v1
    every = round(1 / (RATE * DT))
    ts, xs, ys, th, front = [], [], [], [], []
    corners = np.array([[sx * L / 2, sy * W / 2] for sx in (-1, 1) for sy in (-1, 1)])
    mujoco.mj_forward(model, data)
    while data.time < 3.0:
        q = data.qpos
        yaw_now = 2 * np.arctan2(q[6], q[3])
        c, s = np.cos(yaw_now), np.sin(yaw_now)
        ts.append(data.time)
        xs.append(q[0])
        ys.append(q[1])
        th.append(yaw_now)
        front.append(q[0] + np.max(corners[:, 0] * c - corners[:, 1] * s))
        if q[0] > 1.6:
            break
        for _ in range(every):
            mujoco.mj_step(model, data)
    t = np.asarray(ts)
    front_a = np.asarray(front)
    transit = first_crossing(t, front_a, BARRIERS_X[1]) - first_crossing(t, front_a, BARRIERS_X[0])
    noise_xy = rng.normal(0, 0.001, (2, len(t)))
    noise_th = rng.normal(0, np.radians(0.3), len(t))
    traj = Trajectory.from_arrays(
        t,
        np.asarray(xs) + noise_xy[0],
        np.asarray(ys) + noise_xy[1],
        np.unwrap(np.asarray(th)) + noise_th,
    )
    return traj, round(transit, 4)


def main() -> int:
    rng = np.random.default_rng(SEED)
    cases = []
    for kind in TYPES:
        for setting in BELT2:
            case = TestCase("E1", kind, setting)
            runs = []
            for k in range(1, RUNS_PER_CASE + 1):
                traj, transit = simulate(rng, kind, setting)
                runs.append(Run(f"E1-{kind}-{setting}-{k:02d}", case, traj, transit))
            # the interesting section: the transfer from belt 1 to belt 2
            cases.append(
                CaseData(case, tuple(runs), regions=(Box(xmin=-0.35, xmax=0.60),), margin=0.02)
            )
    save_dataset(
        OUT,
        "e1-synthetic",
        cases,
        synthetic=True,
        description=(
            "SYNTHETIC example data, not measured: rigid boxes simulated on rig E1 (Belt-Belt) with "
            "MuJoCo, with imitated run-to-run variability and tracking noise "
            "(scripts/make_example_dataset.py)."
        ),
    )
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
