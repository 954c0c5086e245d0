"""What simulations cost: the one-line estimate a long job prints before it starts.

A MuJoCo run's wall time on one core is taken from measurements (`benchmarks/bench_sim.py` and
``parcelfit simulate`` on a 2-core machine): a run on E3 at the default time step takes about
`RUN_SECONDS` ``["rigid"]`` seconds around a rigid content over the shell of 4 x 4 x 1 cells
(BW, KP; 50 nodes), in proportion to the shell's nodes over a finer grid (KP/BW's 5 x 5 x 1
cells, 72 nodes: about 11.5 s against 12.1 s measured), and `RUN_SECONDS` ``["soft"]`` around
the polybag's soft one. A rig that refines the step (``step_refinement`` in its file: E1 and
E2a, 2) costs that many times more, and a rig whose runs last longer than E3's costs more in
proportion; an explicit ``timestep`` scales by the default step over it. The rigid-box
reference and the analytic test simulator are counted as fast; an external solver's time is
unknown. Machines differ by a factor of two or more, and a calibration that passes its
validation stops before its budget: an estimate says how many simulations a job will run at
most and roughly how long that takes, not when it ends.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from parcelfit.errors import ParcelfitError
from parcelfit.sim.factory import SimulatorConfig

# wall seconds of one run on E3 at the default step, one core, by content kind
RUN_SECONDS = {"rigid": 8.0, "soft": 40.0}
# seconds of one run of the rigid-box reference (numba; after its first compilation)
RIGIDBOX_SECONDS = 2.0
# seconds of one run of a python backend (the analytic test simulator is instant)
PYTHON_SECONDS = 0.05
# the default time step by content kind [s] (`SceneOptions`)
DEFAULT_STEP = {"rigid": 1 / 2400, "soft": 1 / 1200}
# a run's simulated time against E3's (about 1.6 s): E1 about 2.1 s, the flow splitter 2.5 s
_DURATION = {"E3": 1.0, "E1": 1.3, "E2a": 1.6, "E2b": 1.6}


def run_seconds(
    config: SimulatorConfig, rig: str | None = None, consignment: str | None = None
) -> float | None:
    """Expected wall time [s] of one run of ``config`` on one core, on ``rig`` and
    ``consignment`` (names, default: the configuration's); None where no time is known (an
    external solver, a rig or type that cannot be read)."""
    if config.backend == "python":
        return PYTHON_SECONDS
    if config.backend == "external":
        return None
    if config.backend == "rigidbox":
        return RIGIDBOX_SECONDS
    from parcelfit.sim.mujoco import SceneOptions, load_consignment, load_rig

    try:
        loaded = load_rig(_file_or_name(rig, config.rig or "E3"))
        kind = load_consignment(_file_or_name(consignment, config.consignment or "KPBW"))
    except ParcelfitError:
        return None
    factor = _DURATION.get(loaded.name, 1.0)
    step = (config.rig_timesteps or {}).get(loaded.name) or config.timestep
    if step is None:
        factor *= loaded.step_refinement
    else:
        factor *= DEFAULT_STEP[kind.content_kind] / step
    if kind.content_kind == "rigid":
        # an interpolated shell's nodes over a 4 x 4 x 1 grid's: 12.1 s against 8.3 s measured
        # for 5 x 5 x 1 against 4 x 4 x 1 cells (`benchmarks/bench_sim.py`), 72 against 50 nodes;
        # a coarser grid is not counted as cheaper (the contacts and the rig cost the same)
        scene = SceneOptions(shell_dof=config.shell_dof or "auto", shell_cells=config.shell_cells)
        _, cells = scene.shell_of(kind)  # the grid the scene builds for this type
        factor *= max(1.0, _shell_nodes(cells) / _shell_nodes((4, 4, 1)))
        # the mesh of contact points is not counted: KP's 22.5 mm took 1.01 times its former
        # 30 mm (`python benchmarks/bench_sim.py --types KP --peer spacing=0.03`)
    return RUN_SECONDS[kind.content_kind] * factor


def refined_seconds(
    config: SimulatorConfig, refinement: int, rig: str | None = None, consignment: str | None = None
) -> float | None:
    """Expected wall time [s] of one run of ``config`` refined ``refinement`` times over (the
    convergence check; `run_seconds` otherwise), None where no time is known (an external
    solver): on MuJoCo around a rigid content with an interpolated shell ``refinement`` times
    the model's (2.1-2.2 times measured at 2 for KP/BW on E3 and E1, docs/research/
    convergence-check.md: the steps double, the shell's nodes stay), a Python factory's as
    many times, else its cube (a film's, a full shell's or the reference's points grow as its
    square, the steps as itself; not measured)."""
    seconds = run_seconds(config, rig, consignment)
    if seconds is None:
        return None
    power = 3
    if config.backend == "python":  # its cost is its own: counted as its steps'
        power = 1
    elif config.backend == "mujoco" and (config.shell_dof or "auto") != "full":
        from parcelfit.sim.mujoco import load_consignment

        try:
            kind = load_consignment(_file_or_name(consignment, config.consignment or "KPBW"))
        except ParcelfitError:
            kind = None
        if kind is not None and kind.content_kind == "rigid":
            power = 1
    return seconds * refinement**power


def _shell_nodes(cells: tuple[int, int, int]) -> int:
    """Nodes of an interpolated shell over ``cells`` (length, width, height) cells."""
    return math.prod(c + 1 for c in cells)


def _file_or_name(name: str | None, configured: str) -> str:
    """The configured rig or consignment (a bundled name or a file) that ``name`` means: the
    configured file where its stem is ``name``, else ``name`` as a bundled name."""
    if name is None:
        return configured
    path = Path(configured)
    if path.suffix.lower() in (".yaml", ".yml") and path.stem == name:
        return configured
    return name


@dataclass(frozen=True)
class Estimate:
    """How many simulations a job runs (at most) and their expected wall time on ``workers``
    processes; ``seconds`` is None where a run's time is unknown."""

    simulations: int
    seconds: float | None
    workers: int

    def text(self, note: str = "") -> str:
        """One line: ``expected cost: N simulations on W processes, about T`` (and ``note``)."""
        where = f"on {self.workers} process{'es' if self.workers != 1 else ''}"
        if self.seconds is None:
            time = "time unknown (no measured per-run time for this simulator)"
        else:
            time = f"about {duration_text(self.seconds)}"
        line = f"expected cost: {self.simulations} simulations {where}, {time}"
        return line + (f"; {note}" if note else "")


def estimate(runs: Iterable[tuple[int, float | None]], workers: int) -> Estimate:
    """The estimate of ``runs``, pairs of (number of simulations, seconds each), spread over
    ``workers`` processes (one simulation per process at a time)."""
    runs = list(runs)
    count = sum(n for n, _ in runs)
    known = all(s is not None for _, s in runs)
    total = sum(n * s for n, s in runs if s is not None) if known else None
    workers = max(1, workers)
    seconds = None
    if total is not None:
        # whole rounds of `workers` simulations: a single long run does not split
        longest = max((s for n, s in runs if n and s is not None), default=0.0)
        seconds = max(total / min(workers, max(count, 1)), longest)
    return Estimate(count, seconds, workers)


def duration_text(seconds: float) -> str:
    """A duration rounded for reading: seconds under two minutes, then minutes, then hours."""
    if seconds < 120:
        return f"{max(1, math.ceil(seconds / 5) * 5):.0f} s"
    if seconds < 2 * 3600:
        return f"{math.ceil(seconds / 60):.0f} min"
    return f"{seconds / 3600:.1f} h"


__all__ = ["RUN_SECONDS", "Estimate", "duration_text", "estimate", "run_seconds"]
