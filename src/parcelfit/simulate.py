"""One test case simulated with MuJoCo outside a study (``parcelfit simulate``): the simulator
built from the command's options, one run, or an ensemble of seeded placements with its
summary table.

`case_simulation` checks the options and builds the simulator, the parameters (the consignment
type's defaults with ``NAME=VALUE`` assignments in catalogue units over them, SI inside) and the
test case, before anything is simulated; `simulate_placements` runs the placements in the
project's executor (`parcelfit.sim.executors`: spawned worker processes that die with this
one, as MuJoCo and numba are not fork-safe; in this process for one worker) and writes each run
the moment it arrives, then the summary table.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from parcelfit.errors import ParcelfitError
from parcelfit.runs import TestCase, write_trajectory
from parcelfit.sim import factory, mujoco
from parcelfit.sim.ensemble import EnsembleSummary, member_of, summarise
from parcelfit.sim.executors import Task, local_executor, serial_executor
from parcelfit.sim.mujoco import MujocoSimulator, load_consignment, load_rig
from parcelfit.sim.mujoco.rig import Rig
from parcelfit.sim.params import parse_assignments, shell_cells
from parcelfit.study.joint import simulate_items


@dataclass(frozen=True)
class CaseSimulation:
    """A MuJoCo simulator ready for one test case: the simulator, the parameters (SI), the
    case and its rig."""

    simulator: MujocoSimulator
    params: dict[str, float]
    case: TestCase
    rig: Rig


def parse_shell_cells(text: str) -> tuple[int, int, int]:
    """``--shell-cells`` text (``4,4,1``) as three whole numbers, checked."""
    try:
        numbers = [float(part) for part in text.split(",")]
    except ValueError:
        raise ParcelfitError(
            f"--shell-cells {text!r} is not three numbers", fix="write e.g. 4,4,1"
        ) from None
    return shell_cells(numbers)


def case_simulation(
    rig: str,
    consignment: str,
    setting: int,
    assignments: list[str],
    *,
    record_vertices: bool = False,
    **options: Any,
) -> CaseSimulation:
    """The simulator of ``rig`` and ``consignment`` (bundled names or .yaml files) at speed
    ``setting``, with ``assignments`` (``NAME=VALUE`` in catalogue units) over the consignment
    type's default parameters; ``options`` are `SimulatorConfig`'s (``shell_cells`` may be the
    ``4,4,1`` text; ``timestep`` [s], ``spacing`` [m], ``wall_limit`` [s], ...). An unknown
    setting or a bad value is refused here, before any simulation."""
    rig_obj = load_rig(rig)
    cons = load_consignment(consignment)
    try:
        params = cons.parameter_values(user_values=parse_assignments(assignments))
    except ParcelfitError as exc:  # a value given with --set
        raise ParcelfitError(exc.message, where="--set", fix=exc.fix) from None
    if isinstance(options.get("shell_cells"), str):
        options["shell_cells"] = parse_shell_cells(options["shell_cells"])
    # looked up as the command runs (a test may stand in for the simulator)
    config = factory.SimulatorConfig("mujoco", rig=rig, consignment=consignment, **options)
    sim = factory.make_simulator(config)
    assert isinstance(sim, mujoco.MujocoSimulator)
    rig_obj.drive_speeds(setting)  # a clear error for an unknown setting before simulating
    return CaseSimulation(
        sim.with_options(record_vertices=record_vertices),
        params,
        TestCase(rig_obj.name, cons.name, setting),
        rig_obj,
    )


@dataclass(frozen=True)
class Placements:
    """An ensemble's outcome: one row per placement in seed order (seed, status, transit time
    [s], rotation [deg], outcome, wall time [s]), its summary and where the table went."""

    rows: list[dict[str, Any]]
    summary: EnsembleSummary
    table: Path


def simulate_placements(
    run: CaseSimulation,
    first: int,
    n: int,
    workers: int,
    out: Path,
    on_run: Callable[[], None] = lambda: None,
) -> Placements:
    """Simulate ``n`` placements from seed ``first`` with ``workers`` processes; each run goes to
    ``out`` with ``-s<seed>`` before its suffix the moment it arrives (``on_run`` is called
    then), the table to ``out`` with ``-ensemble.csv``."""
    import pandas as pd

    seeds = list(range(first, first + n))
    rows: list[dict[str, Any]] = []
    members: list[Any] = []
    items = [(Task(run.params, run.case, f"{out.stem}-s{seed}"), seed) for seed in seeds]
    executor = local_executor(min(workers, n)) if workers > 1 else serial_executor()
    with executor:
        for i, result in simulate_items(executor, run.simulator, items):
            m = member_of(seeds[i], result)
            if m.run is not None:
                write_trajectory(
                    m.run.trajectory, out.with_name(f"{out.stem}-s{m.seed}{out.suffix}")
                )
            members.append(m)
            rows.append(
                {
                    "seed": m.seed,
                    "status": m.status.value,
                    "transit_time_s": m.transit_time,
                    "rotation_deg": None if m.rotation is None else math.degrees(m.rotation),
                    "outcome": m.outcome,
                    "wall_time_s": m.wall_time,
                }
            )
            on_run()
    members.sort(key=lambda m: m.seed)
    rows.sort(key=lambda r: r["seed"])
    table_path = out.with_name(f"{out.stem}-ensemble.csv")
    out.parent.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(rows).to_csv(table_path, index=False)
    return Placements(rows, summarise(members), table_path)
