"""Twin experiments: "real-like" datasets made with the simulator from hidden true parameters.

Every run is a separate specimen and a separate placement, so the runs scatter the way real
experiments do (method.md sections 2 and 3):

* specimen: every friction coefficient x (1 + N(0, friction_cv)), every contact stiffness and
  Young's modulus x (1 + N(0, stiffness_cv));
* placement jitter at the start guide: N(0, placement_sd) [m] in x and y, N(0, angle_sd) [deg];
* belt speeds: every drive x (1 + U(-speed_dev, speed_dev)) (real belts deviate up to 3 %);
* tracking noise: N(0, tracking_sd) [m] on x and y, N(0, heading_sd) [rad] on theta;
* model-form difference: the "real" runs use a finer shell mesh (``real_spacing``) than the
  model that will be calibrated, so a calibration cannot reach zero cost.

The truth (parameters in the catalogue's units, and every setting above) is written beside the
dataset as ``truth.yaml``; the dataset is marked ``synthetic: true``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import yaml

from parcelfit.errors import ParcelfitError
from parcelfit.runs import Box, CaseData, Run, TestCase, Trajectory, save_dataset
from parcelfit.sim.mujoco import MujocoSimulator, SceneOptions, SimOptions
from parcelfit.sim.params import CATALOGUE, resolve


@dataclass(frozen=True)
class TwinSettings:
    """How real-like the twin runs are (see the module docstring for each quantity)."""

    runs: int = 10
    friction_cv: float = 0.03
    stiffness_cv: float = 0.05
    placement_sd: float = 0.005
    angle_sd: float = 1.5
    speed_dev: float = 0.03
    tracking_sd: float = 0.001
    heading_sd: float = 0.003
    real_spacing: float = 0.02


def _specimen(
    truth: Mapping[str, float], rng: np.random.Generator, s: TwinSettings
) -> dict[str, float]:
    out = dict(truth)
    for name in out:
        if name.startswith(("mu_d_", "mu_CoPa")):
            out[name] *= 1 + rng.normal(0, s.friction_cv)
        elif name.startswith(("k_", "E_")):
            out[name] *= 1 + rng.normal(0, s.stiffness_cv)
    return out


def make_twin_dataset(
    folder: str | Path,
    cases: Sequence[TestCase],
    truth_user: Mapping[str, Mapping[str, float]],
    *,
    settings: TwinSettings | None = None,
    seed: int = 0,
    name: str = "twin",
    progress: Callable[[str], None] | None = None,
) -> Path:
    """Simulate ``settings.runs`` real-like runs per test case; returns the dataset.yaml path.

    ``truth_user`` maps a consignment type to its true parameters in the catalogue's units; the
    others take their defaults.
    """
    s = settings or TwinSettings()
    rng = np.random.default_rng(seed)
    sim = MujocoSimulator()
    out_cases = []
    truth_si: dict[str, dict[str, float]] = {}
    for case in cases:
        cons = sim.consignment(case.consignment)
        if case.consignment not in truth_si:
            truth_si[case.consignment] = resolve(
                cons.content_kind, user_values=truth_user.get(case.consignment, {})
            )
        rig = sim.rig(case.rig)
        runs = []
        for k in range(s.runs):
            params = _specimen(truth_si[case.consignment], rng, s)
            drives = {d for sp in rig.speeds.values() for d in sp}
            scene = SceneOptions(
                spacing=s.real_spacing,
                soft_shell_spacing=max(s.real_spacing, 0.03),
                speed_factors={
                    d: 1 + rng.uniform(-s.speed_dev, s.speed_dev) for d in sorted(drives)
                },
                start_offset=(
                    rng.normal(0, s.placement_sd),
                    rng.normal(0, s.placement_sd),
                    rng.normal(0, s.angle_sd),
                ),
            )
            twin = MujocoSimulator(
                SimOptions(scene=scene), rigs={rig.name: rig}, consignments={cons.name: cons}
            )
            run_id = f"{case.rig}-{case.consignment}-{case.speed_setting}-{k + 1:02d}"
            res = twin.run(params, case, run_id=run_id)
            if not res.ok or res.run is None:
                raise ParcelfitError(
                    f"twin run {run_id} ended {res.status.value}: {res.diagnostics.get('message')}"
                )
            tr = res.run.trajectory
            n = len(tr)
            noisy = Trajectory(
                t=tr.t,
                x=tr.x + rng.normal(0, s.tracking_sd, n),
                y=tr.y + rng.normal(0, s.tracking_sd, n),
                theta=tr.theta + rng.normal(0, s.heading_sd, n),
            )
            runs.append(Run(run_id, case, noisy, res.run.transit_time))
            if progress:
                progress(f"{run_id}: {res.wall_time:.1f} s")
        regions = tuple(r for r in rig.regions if isinstance(r, Box)) or rig.regions
        out_cases.append(CaseData(case, tuple(runs), regions, rig.margin))
    path = save_dataset(
        folder,
        name,
        out_cases,
        synthetic=True,
        description=(
            f"SYNTHETIC twin-experiment data, not measured: simulated with parcelfit's MuJoCo model from hidden "
            f"true parameters (truth.yaml), {s.runs} specimens per test case with friction, stiffness, placement, "
            f"belt-speed and tracking variation, and a finer shell mesh ({s.real_spacing * 1e3:g} mm) than the default."
        ),
    )
    units = {p.name: p for p in CATALOGUE}
    truth_doc = {
        "synthetic": True,
        "seed": seed,
        "settings": asdict(s),
        "truth": {
            c: {k: float(units[k].from_si(v)) for k, v in p.items()} for c, p in truth_si.items()
        },
        "units": {k: units[k].unit for k in units},
    }
    (Path(folder) / "truth.yaml").write_text(
        yaml.safe_dump(truth_doc, sort_keys=False), encoding="utf-8"
    )
    return path


__all__ = ["TwinSettings", "make_twin_dataset"]
