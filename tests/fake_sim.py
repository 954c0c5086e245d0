"""A cheap analytic simulator for testing the calibration loop.

A parcel moves along x at the speed setting's belt speed; its lateral drift is set by
mu_d_BePa and its turn by mu_d_MePa, so both are identifiable from the trajectory. Environment:
FAKE_SIM_DELAY [s] sleeps per simulation (for kill tests); FAKE_SIM_LOG appends each run id
when its simulation starts; FAKE_SIM_CRASH_ONCE names a file: the first simulation to find it
missing creates it and kills its own process with SIGKILL (a worker dying mid-simulation);
FAKE_SIM_HANG names a file: a simulation finding it there runs for 120 s more;
FAKE_SIM_INTERRUPT_AFTER=k: the simulation after the k-th one started in a process raises
KeyboardInterrupt (Ctrl-C; count in `started`); FAKE_SIM_MESH_ERROR [rad] adds a discretisation
error to the heading, (1 - exp(-2 t)) times it divided by the simulator's refinement
(`with_refinement`), the shape of mu_d_MePa's turn, so a calibration can absorb it.
"""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Mapping

import numpy as np

from parcelfit.runs import CaseData, Run, TestCase, Trajectory, save_dataset
from parcelfit.sim.protocol import SimResult, SimStatus

SPEEDS = {1: 1.0, 2: 1.4}
TRUTH = {"mu_d_BePa": 0.5, "mu_d_MePa": 0.2}


def trajectory(
    p: Mapping[str, float],
    setting: int,
    t_end: float = 1.5,
    rig: str = "R",
    placement: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> tuple[Trajectory, float]:
    """Analytic run on rig R: x = v t, y = 0.4 (mu_B - 0.3) t^2, theta = 3 (mu_M - 0.15)
    (1 - exp(-2 t)) + 1e-4 (E_Pa / 1 GPa) t. Rig Q (a second rig) turns the parcel by E_Pa as
    well: theta + 2 (E_Pa / 1 GPa - 0.9) (1 - exp(-3 t)). Two bench tests (the rig files
    examples/bench/B1.yaml and B2.yaml by their names): on B1 (belt step) the transit time
    follows mu_d_BePa three times as strongly as on R, nothing else; on B2 (plate impact) the
    turn follows k_MePa, theta + 0.5 (k_MePa / 1000 N/mm - 0.55) (1 - exp(-4 t)), and the
    lateral position E_Pa, y + 0.005 (E_Pa / 1 GPa - 0.9) t. Every other rig name runs as R.
    ``placement`` (dy [m], dtheta [rad], relative transit-time change) shifts the start as a
    seeded placement does."""
    t = np.arange(0.0, t_end, 1 / 60)
    v = SPEEDS[setting]
    dy, dth, dt = placement
    y = 0.4 * (p["mu_d_BePa"] - 0.3) * t**2 + dy * (1 + t)
    # E_Pa has a tiny effect on rig R (an almost inert parameter); the other catalogue
    # parameters none
    e = p.get("E_Pa", 1e9) / 1e9
    theta = 3.0 * (p["mu_d_MePa"] - 0.15) * (1 - np.exp(-2 * t)) + 1e-4 * e * t + dth
    if rig == "Q":
        theta = theta + 2.0 * (e - 0.9) * (1 - np.exp(-3 * t))
    if rig == "B2":
        k = p.get("k_MePa", 6.11e5) / 1e6
        theta = theta + 0.5 * (k - 0.55) * (1 - np.exp(-4 * t))
        y = y + 0.005 * (e - 0.9) * t
    slope = 0.6 if rig == "B1" else 0.2
    transit = 1.0 / v * (1 + slope * (p["mu_d_BePa"] - 0.45)) * (1 + dt)
    return Trajectory(t=t, x=v * t, y=y, theta=theta), transit


def placement(seed: int) -> tuple[float, float, float]:
    """The start scatter of placement ``seed``: dy [m], dtheta [rad], relative transit change;
    a negative seed mirrors the positive one's (as the MuJoCo rigs' placements do)."""
    if seed < 0:
        dy, dth, dt = placement(-seed)
        return -dy, -dth, -dt
    rng = np.random.default_rng([seed, 0x91])
    return (
        float(rng.normal(0, 0.002)),
        float(rng.normal(0, 0.01)),
        float(rng.normal(0, 0.003)),
    )


started = 0  # simulations started in this process


class AnalyticSimulator:
    """Implements the Simulator protocol with `trajectory`."""

    def __init__(
        self,
        delay: float = 0.0,
        log: str | None = None,
        crash_once: str | None = None,
        placement_seed: int | None = None,
        mesh_error: float = 0.0,
        refinement: int = 1,
    ) -> None:
        self.delay = delay
        self.log = log
        self.crash_once = crash_once
        self.placement_seed = placement_seed
        self.mesh_error = mesh_error
        self.refinement = refinement

    def with_placement(self, seed: int | None) -> AnalyticSimulator:
        """The same simulator with placement ``seed`` (None: the nominal start)."""
        return AnalyticSimulator(
            self.delay, self.log, self.crash_once, seed, self.mesh_error, self.refinement
        )

    def with_refinement(self, factor: int) -> AnalyticSimulator:
        """The same simulator refined ``factor`` times over (its mesh error divided by it)."""
        return AnalyticSimulator(
            self.delay,
            self.log,
            self.crash_once,
            self.placement_seed,
            self.mesh_error,
            self.refinement * factor,
        )

    def run(
        self, params: Mapping[str, float], case: TestCase, run_id: str | None = None
    ) -> SimResult:
        t0 = time.perf_counter()
        if self.log:  # logged when a simulation starts, so a restarted one appears twice
            with open(self.log, "a") as fh:
                fh.write(f"{run_id}\n")
        if self.delay:
            time.sleep(self.delay)
        global started
        started += 1
        limit = int(os.environ.get("FAKE_SIM_INTERRUPT_AFTER", "1000000000"))
        if started > limit:
            raise KeyboardInterrupt  # Ctrl-C during a simulation in this process (serial)
        hang = os.environ.get("FAKE_SIM_HANG")
        if hang and os.path.exists(hang):  # a simulation of minutes, started after the file
            time.sleep(120)
        if self.crash_once:
            try:
                open(self.crash_once, "x").close()
            except FileExistsError:
                pass
            else:
                os.kill(os.getpid(), signal.SIGKILL)
        if params["mu_d_BePa"] > 0.59:  # a region where "the solver" fails
            return SimResult(
                None, SimStatus.UNSTABLE, time.perf_counter() - t0, {"message": "diverged"}
            )
        start = (0.0, 0.0, 0.0) if self.placement_seed is None else placement(self.placement_seed)
        traj, transit = trajectory(params, case.speed_setting, rig=case.rig, placement=start)
        if self.mesh_error:
            turn = self.mesh_error / self.refinement * (1 - np.exp(-2 * traj.t))
            traj = Trajectory(t=traj.t, x=traj.x, y=traj.y, theta=traj.theta + turn)
        return SimResult(
            Run(run_id or "sim", case, traj, transit), SimStatus.OK, time.perf_counter() - t0, {}
        )


PARENT_MARK: str | None = None  # set by a test in its own process: a forked worker has it too


class EnsembleProbe(AnalyticSimulator):
    """Stands in for the MuJoCo simulator of `parcelfit simulate --repeat`: every run appends
    its process id and the `PARENT_MARK` it sees to the file ``probe``."""

    def __init__(self, probe: str, placement_seed: int | None = None) -> None:
        super().__init__(placement_seed=placement_seed)
        self.probe = probe

    def with_options(self, **_: object) -> EnsembleProbe:
        return self

    def with_placement(self, seed: int | None) -> EnsembleProbe:
        return EnsembleProbe(self.probe, seed)

    def run(
        self, params: Mapping[str, float], case: TestCase, run_id: str | None = None
    ) -> SimResult:
        with open(self.probe, "a") as fh:
            fh.write(f"{os.getpid()} {PARENT_MARK}\n")
        return super().run(params, case, run_id)


class BrokenSimulator:
    """A simulator whose every run raises (a broken set-up: a missing solver, an expired
    licence); its message spans two lines. With FAKE_SIM_FIXED set it runs as `make`'s."""

    def with_placement(self, seed: int | None) -> BrokenSimulator:
        return self

    def run(
        self, params: Mapping[str, float], case: TestCase, run_id: str | None = None
    ) -> SimResult:
        if os.environ.get("FAKE_SIM_FIXED"):
            return make().run(params, case, run_id)
        raise RuntimeError("solver licence expired\nask the licence server's admin")


def make_broken() -> BrokenSimulator:
    """Factory named in study files (tests.fake_sim:make_broken)."""
    return BrokenSimulator()


def make() -> AnalyticSimulator:
    """Factory named in study files (tests.fake_sim:make)."""
    return AnalyticSimulator(
        float(os.environ.get("FAKE_SIM_DELAY", "0")),
        os.environ.get("FAKE_SIM_LOG"),
        os.environ.get("FAKE_SIM_CRASH_ONCE"),
        mesh_error=float(os.environ.get("FAKE_SIM_MESH_ERROR", "0")),
    )


def write_reference_dataset(
    folder, n_runs: int = 8, seed: int = 0, rigs=("R",), truth=None, nominal_rigs=("R",)
):
    """Runs of the truth (default `TRUTH`, E_Pa 1 GPa; any other parameter it names, such as
    k_MePa, scatters alike) with specimen-to-specimen variation, placement scatter and
    tracking noise, at speed settings 1 and 2 of each rig. The runs of ``nominal_rigs`` start
    at the nominal placement (no placement scatter; the tests' data of rig R, made before
    placements existed); a twin that should scatter as the simulator's ensemble placements do
    passes ``nominal_rigs=()``."""
    rng = np.random.default_rng(seed)
    truth = {**TRUTH, **(truth or {})}
    cases = []
    for rig, setting in ((r, k) for r in rigs for k in (1, 2)):
        case = TestCase(rig, "P", setting)
        runs = []
        for k in range(n_runs):
            p = {
                "mu_d_BePa": truth["mu_d_BePa"] * (1 + rng.normal(0, 0.03)),
                "mu_d_MePa": truth["mu_d_MePa"] * (1 + rng.normal(0, 0.03)),
            }
            if "E_Pa" in truth:
                p["E_Pa"] = truth["E_Pa"] * (1 + rng.normal(0, 0.03))
            for name in sorted(set(truth) - {"mu_d_BePa", "mu_d_MePa", "E_Pa"}):
                p[name] = truth[name] * (1 + rng.normal(0, 0.03))
            start = (
                (0.0, 0.0, 0.0) if rig in nominal_rigs else placement(int(rng.integers(1 << 30)))
            )
            traj, transit = trajectory(p, setting, rig=rig, placement=start)
            noisy = Trajectory(
                t=traj.t,
                x=traj.x + rng.normal(0, 0.001, len(traj)),
                y=traj.y + rng.normal(0, 0.001, len(traj)),
                theta=traj.theta + rng.normal(0, 0.003, len(traj)),
            )
            runs.append(
                Run(f"{rig}-P-{setting}-{k}", case, noisy, transit * (1 + rng.normal(0, 0.01)))
            )
        cases.append(CaseData(case, tuple(runs)))
    return save_dataset(folder, "fake-reference", cases, synthetic=True)
