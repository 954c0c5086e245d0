"""Simulation speed: 2 s of E3 (induction) with the flexible parcels, one core.

    python benchmarks/bench_sim.py [--repeats 3] [--types KPBW PB] [--scene KEY=VALUE ...]
                                   [--peer KEY=VALUE ...] [--iterations N] [--rig E3|FILE]
                                   [--explain] [--profile] [--windows S] [--neighbours N]

Simulates exactly 2 s (the end box is widened so the run does not stop at the rig's end) for
KPBW (flexible packaging, rigid content) and PB (polybag, soft content), or the ``--types``
given, at speed setting 1 and the default resolution, and prints the median wall time, steps
per second, and the ratio to the published cost of one such simulation (about 5 hours on a
16-core desktop with a commercial MFBD solver, method.md section 10). MuJoCo runs one
simulation on one core.

Beside the configuration measured (the defaults, or ``--scene``) it measures a peer in the same
run, alternating the two (``--peer``, default the contact and friction laws before 2026-12-01:
``contact_law=impedance friction=geom``), and prints the ratio of their wall times, so that a
change of the machine's state between runs moves both.

``--explain`` says, for each type above its target, how much its fidelity costs and why: when
the bundled E3 would have ended the run timed; for each fidelity choice (`FIDELITY`) the type
timed against the cheaper configuration the choice replaced (alternating the two, as the peer),
the ratio, and why the choice was made with the note that measured it; then the profile line
(below) of the run as timed and of each cheaper configuration. ``--windows S`` adds to each
profile a line per window of S seconds (rounded to whole steps): mean Newton iterations and
contacts per step, and the steps in which the friction law slid some contact by hand.

``--profile`` then steps each type's scene, and the peer's, once more for the same 2 s with
MuJoCo's own timers and prints where a step's time goes: the constraint solver, positions and
collisions, and the rest (mostly the smooth dynamics' factorisation), with the mean Newton
iterations, contacts, constraint rows and degrees of freedom (nv). ``--windows S`` adds the
same per-window lines to ``--profile`` as to ``--explain``.

Other work on the machine slows a run when it takes time on the benchmark's core. Under the
table, and under each comparison of ``--explain``, the benchmark prints its own share of a
core while it timed and the cores other processes kept busy (`machine_load.py`), and warns when
its share fell below 0.95 or the others took more than the free cores by over 0.2: the times
are then not a measure against the targets; the ratios, measured alternately, are less affected.
``--neighbours N`` starts N busy processes beside the table, to show what other work does.
``--rig FILE`` times a variant of E3 (``--explain`` only with the bundled one).
"""

from __future__ import annotations

import argparse
import statistics
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any, NamedTuple

import mujoco
import numpy as np

from parcelfit.runs import TestCase
from parcelfit.sim.mujoco import MujocoSimulator, Rig, SceneOptions, SimOptions, load_rig
from parcelfit.sim.mujoco.friction import Stepper
from parcelfit.sim.mujoco.mjlog import CountedWarnings
from parcelfit.sim.mujoco.options import parse_scene_options
from parcelfit.sim.mujoco.simulator import _set_velocity

sys.path.insert(0, str(Path(__file__).resolve().parent))

from machine_load import (
    Watch,
    busy_neighbour,
    installed,
    processor,
    report_machine,
    usable_cores,
)

PUBLISHED_SECONDS = 5 * 3600.0
BUDGET = {"KPBW": 8.0, "PB": 30.0}  # s, the targets of the physics issue
FORMER_LAWS = ["contact_law=impedance", "friction=geom"]


class Fidelity(NamedTuple):
    """A fidelity choice of a consignment type: the cheaper configuration it replaced (scene
    options, KEY=VALUE) and why it was made, naming the research note that measured it."""

    cheaper: list[str]
    why: str


FIDELITY: dict[str, list[Fidelity]] = {
    "KPBW": [
        Fidelity(
            ["shell_cells=4,4,1"],
            "its shell over 5 x 5 x 1 cells (72 nodes against 50): on E3's slides a stiffer "
            "packaging turns 16 of 17 further and a stiffer content contact slows all 17, the "
            "signs of the full shell at a fine step (4 x 4 x 1 cells: 7 of 16 and 15 of 17), and "
            "its outcomes hold on a finer mesh at 18 of 20 placements (4 x 4 x 1: 16) "
            "(docs/research/rim-brace/README.md)",
        ),
    ],
    "PB": [
        Fidelity(
            FORMER_LAWS,
            "the penalty contact, whose stiffness follows the packaging's, and the friction "
            "decided per contact, under which a sliding parcel keeps touching the belt "
            "(docs/research/contact-law.md); the profile lines below show where the steps' "
            "time goes in each",
        ),
        Fidelity(
            ["impratio=1000"],
            "MuJoCo's impratio of 1e4 under the penalty law, which stiffens the friction rows "
            "against the normal's so that a sticking contact holds (at 100 a KP/BW pushed with "
            "half its weight creeps 0.03 mm/s, from 1e3 it holds; docs/research/contact-law.md), "
            "with a factor of ten to spare: MuJoCo's Newton solver iterates more the stiffer the "
            "friction rows are (docs/research/pb-speed.md)",
        ),
        Fidelity(
            ["timestep=1/600"],
            "its step, 1/1200 s: at 1/600 s every E3 outcome holds, but at setting 2 the polybag "
            "arrives 50 ms late (median, paired, measured on the former 40 mm meshes; "
            "docs/research/pb-speed.md)",
        ),
    ],
}


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument(
        "--types",
        nargs="+",
        default=["KPBW", "PB"],
        help="consignment types to time (e.g. KP with --scene shell_dof=quadratic as its peer)",
    )
    ap.add_argument(
        "--iterations",
        type=int,
        default=None,
        help="MuJoCo's iteration cap instead of the default (e.g. 50, the former default, as a peer)",
    )
    ap.add_argument(
        "--scene",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="scene options other than the defaults (e.g. belt_friction=coulomb)",
    )
    ap.add_argument(
        "--peer",
        nargs="*",
        default=FORMER_LAWS,
        metavar="KEY=VALUE",
        help="scene options of the peer measured alternately (default: the former laws)",
    )
    ap.add_argument(
        "--explain",
        action="store_true",
        help="for each type above its target, time its fidelity choices against the cheaper "
        "configurations they replaced and say why they were made",
    )
    ap.add_argument(
        "--windows",
        type=float,
        default=None,
        metavar="SECONDS",
        help="with --explain or --profile: each profile also per window of this length (Newton "
        "iterations, contacts, steps with a contact slid by hand)",
    )
    ap.add_argument(
        "--rig",
        default="E3",
        help="the E3 rig to time: the bundled one (default) or a variant's rig file, e.g. "
        "examples/e3-variants/E3-centres.yaml (E3's start before 2026-12-05)",
    )
    ap.add_argument(
        "--neighbours",
        type=int,
        default=0,
        metavar="N",
        help="keep N other processes busy (each a pure-Python loop on one core) while timing "
        "the table, to show what other work on the machine does to the times",
    )
    ap.add_argument(
        "--profile",
        action="store_true",
        help="also print where a step's time goes (MuJoCo's timers, Newton iterations, contacts)",
    )
    args = ap.parse_args()
    if args.explain and args.rig != "E3":
        ap.error("--explain describes the bundled E3: leave out --rig")
    if args.neighbours < 0:
        ap.error("--neighbours takes a whole number of processes, 0 or more")
    if args.windows is not None and not args.windows > 0:
        ap.error("--windows takes a positive number of seconds")
    if args.windows is not None and not args.profile and not args.explain:
        ap.error("--windows takes effect with --explain or --profile")
    rig = load_rig(args.rig)
    rig = replace(rig, end=replace(rig.end, x=(-1.0, 3.9), duration=2.0, after_last_barrier=10.0))
    given: dict[str, Any] = parse_scene_options(args.scene)
    if args.iterations is not None:
        given["iterations"] = args.iterations
    scene = SceneOptions(**given)
    peer = SceneOptions(**{**given, **parse_scene_options(args.peer)})
    sim = MujocoSimulator(SimOptions(scene=scene), rigs={"E3": rig})
    peer_sim = MujocoSimulator(SimOptions(scene=peer), rigs={"E3": rig})
    cores = usable_cores()
    print(f"processor: {processor()}, {cores} usable cores; rig: {args.rig}")
    print(f"installed: {installed(('mujoco', 'numba', 'numpy'))}")
    print(
        f"E3, speed setting 1, 2.0 s simulated, default resolution, one core, "
        f"iteration cap {scene.iterations}, contact law {scene.contact_law}, friction "
        f"{scene.friction}; peer: {' '.join(args.peer) or 'the same'}"
    )
    print(
        f"{'case':<10}{'wall [s]':>10}{'steps/s':>10}{'x faster than 5 h':>20}{'target [s]':>12}"
        f"{'peer [s]':>10}{'ratio':>7}  (range of wall)"
    )
    over: list[str] = []
    neighbours = [busy_neighbour() for _ in range(args.neighbours)]
    machine: list[str] = []
    for cons in args.types:
        watch = Watch()
        (walls, peer_walls), rates = _alternate(cons, (sim, peer_sim), args.repeats)
        machine.append(
            report_machine(
                f"while timing E3/{cons} and its peer", watch.own_share(), watch.cores(), cores - 1
            )
        )
        wall, peer_wall = statistics.median(walls), statistics.median(peer_walls)
        print(
            f"{'E3/' + cons:<10}{wall:>10.2f}{statistics.median(rates):>10.0f}{PUBLISHED_SECONDS / wall:>20.0f}"
            + (f"{BUDGET[cons]:>12.0f}" if cons in BUDGET else f"{'-':>12}")
            + f"{peer_wall:>10.2f}{wall / peer_wall:>7.2f}"
            + f"  ({min(walls):.2f}-{max(walls):.2f})"
        )
        if cons in BUDGET and wall > BUDGET[cons]:
            over.append(cons)
    print("\n".join(machine))
    for proc in neighbours:
        proc.terminate()
        proc.join()
    if neighbours:
        print(f"(neighbour processes busy beside the table: {len(neighbours)})")
    if args.explain:
        _explain(over, sim, rig, given, args.repeats, args.windows)
    if args.profile:
        print(f"\n{'case':<10}{PROFILE_COLUMNS}")
        for cons in args.types:
            print(f"{'E3/' + cons:<10}" + _profile(sim, cons, args.windows))
            print(f"{'  peer':<10}" + _profile(peer_sim, cons, args.windows))


def _alternate(
    cons: str, sims: tuple[MujocoSimulator, ...], repeats: int
) -> tuple[list[list[float]], list[float]]:
    """Wall times [s] of ``repeats`` 2 s runs of ``cons`` on E3 by each simulator, alternating
    them so that a change of the machine's state moves all alike; and the first's steps/s."""
    walls: list[list[float]] = [[] for _ in sims]
    rates: list[float] = []
    for _ in range(repeats):
        for i, which in enumerate(sims):
            res = which.run({}, TestCase("E3", cons, 1))
            assert res.ok and abs(res.diagnostics["simulated_time"] - 2.0) < 0.01, res.diagnostics
            walls[i].append(res.wall_time)
            if i == 0:
                rates.append(res.diagnostics["steps_per_second"])
    return walls, rates


def _explain(
    over: list[str],
    sim: MujocoSimulator,
    rig: Rig,
    given: dict[str, Any],
    repeats: int,
    window: float | None = None,
) -> None:
    """For each type above its target: when the bundled E3 would have ended the run; its
    fidelity choices' cost against the cheaper configurations they replaced (median wall times
    [s], measured alternately) and why; the profiles of the run as timed and of each cheaper one."""
    if not over:
        print("\nevery type timed that has a target is within it")
        return
    for cons in over:
        print(f"\nE3/{cons} is above its target of {BUDGET[cons]:.0f} s. What its fidelity costs:")
        bundled = MujocoSimulator(sim.options).run({}, TestCase("E3", cons, 1))
        if bundled.ok:
            print(
                f"  (on the bundled E3, whose end box stops a run {_bundled_end_note()}, this run "
                f"ends after {bundled.diagnostics['simulated_time']:.2f} s of the 2 s timed)"
            )
        profiles: list[tuple[str, MujocoSimulator]] = [("as timed", sim)]
        for choice in FIDELITY.get(cons, []):
            cheaper = SceneOptions(**{**given, **parse_scene_options(choice.cheaper)})
            label = " ".join(choice.cheaper)
            if cheaper == sim.options.scene:
                print(f"  {label}: already the configuration timed (--scene), not compared")
                continue
            cheap_sim = MujocoSimulator(SimOptions(scene=cheaper), rigs={"E3": rig})
            watch = Watch()
            (walls, cheap_walls), _ = _alternate(cons, (sim, cheap_sim), repeats)
            machine = report_machine(
                "    while timing these", watch.own_share(), watch.cores(), usable_cores() - 1
            )
            wall, cheap = statistics.median(walls), statistics.median(cheap_walls)
            print(
                f"  {wall:.2f} s against {cheap:.2f} s with {label}: {wall / cheap:.2f} times, for {choice.why}"
            )
            print(machine)
            profiles.append((label, cheap_sim))
        print(f"  where a step goes:\n  {'scene':<40}{PROFILE_COLUMNS}")
        for label, which in profiles:
            print(f"  {label[:40]:<40}" + _profile(which, cons, window))


def _bundled_end_note() -> str:
    """How the bundled E3 ends a run, in words."""
    end = load_rig("E3").end
    return (
        f"when the centre leaves x = {end.x[0]:g} to {end.x[1]:g} m, {end.after_last_barrier:g} s after "
        f"the last light barrier or at {end.duration:g} s"
    )


# the columns of a `_profile` line, after its first (a case or a scene)
PROFILE_COLUMNS = (
    f"{'ms/step':>9}{'solver':>8}{'pos+col':>9}{'rest':>7}"
    f"{'Newton it':>11}{'contacts':>10}{'rows':>7}{'nv':>6}"
)


def _profile(sim: MujocoSimulator, cons: str, window: float | None = None) -> str:
    """One 2 s run of ``cons`` on E3 stepped here with MuJoCo's timers: per step [ms] in total,
    in the constraint solver, in positions and collisions, and the rest; mean Newton
    iterations, contacts and constraint rows per step; the degrees of freedom. With ``window``
    [s], also a line per window of that length: mean Newton iterations and contacts per step,
    and the steps in which the friction law slid some contact by hand."""
    scene = sim.scene({}, TestCase("E3", cons, 1))
    rows = 0
    per_step_iters: list[int] = []
    per_step_contacts: list[int] = []
    by_hand: list[int] = []
    with CountedWarnings():  # counted, not printed, as in the simulator's own runs
        model = scene.model()
        data = mujoco.MjData(model)
        _set_velocity(model, data, np.asarray(scene.start_velocity))
        stepper = Stepper(
            model, data, scene, sim.consignment(cons).parameter_values(), sim.options.scene
        )
        n = round(2.0 / model.opt.timestep)
        for _ in range(n):
            before = stepper.contact.explicit_steps if stepper.contact is not None else 0
            stepper.step()
            rows += data.nefc
            per_step_iters.append(int(data.solver_niter[0]))
            per_step_contacts.append(int(data.ncon))
            after = stepper.contact.explicit_steps if stepper.contact is not None else 0
            by_hand.append(after - before)

    def per_step(timer: mujoco.mjtTimer) -> float:
        t = data.timer[timer]
        return 1e3 * t.duration / max(t.number, 1)

    total = per_step(mujoco.mjtTimer.mjTIMER_STEP)
    solver = per_step(mujoco.mjtTimer.mjTIMER_CONSTRAINT)
    position = per_step(mujoco.mjtTimer.mjTIMER_POSITION)
    line = (
        f"{total:>9.2f}{solver:>8.2f}{position:>9.2f}{total - solver - position:>7.2f}"
        f"{sum(per_step_iters) / n:>11.2f}{sum(per_step_contacts) / n:>10.0f}{rows / n:>7.0f}{model.nv:>6d}"
    )
    if window is None:
        return line
    for t0, t1, steps, it, con, hand in window_means(
        per_step_iters, per_step_contacts, by_hand, model.opt.timestep, window
    ):
        slid = str(hand) if stepper.contact is not None else "- (no per-contact law)"
        line += (
            f"\n      {t0:4.2f}-{t1:4.2f} s: Newton it {it:6.2f}, contacts {con:5.0f}, "
            f"steps with a contact slid by hand {slid} of {steps}"
        )
    return line


def window_means(
    iterations: list[int], contacts: list[int], by_hand: list[int], step: float, window: float
) -> list[tuple[float, float, int, float, float, int]]:
    """Per window of ``window`` seconds (rounded to whole steps of ``step`` s, at least one; the
    last may be shorter): its start and end [s], its steps, the mean Newton iterations and
    contacts per step, and the steps with a contact slid by hand."""
    n = len(iterations)
    w = max(1, round(window / step))
    out = []
    for k in range(0, n, w):
        m = min(k + w, n)
        out.append(
            (
                k * step,
                m * step,
                m - k,
                float(np.mean(iterations[k:m])),
                float(np.mean(contacts[k:m])),
                int(np.sum(by_hand[k:m])),
            )
        )
    return out


if __name__ == "__main__":
    main()
