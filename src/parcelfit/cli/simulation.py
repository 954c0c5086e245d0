"""The simulation commands: one test case (or an ensemble of its placements), the bundled rigs,
consignment types and parameters, and twin datasets."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape
from rich.progress import Progress, TimeElapsedColumn
from rich.table import Table
from rich.text import Text

from parcelfit.cli.options import (
    SettingOption,
    WorkersOption,
    at_most,
    check_executor,
    check_paths,
    worker_count,
    workers_at_most,
)
from parcelfit.cli.output import console, resumes, say_cost
from parcelfit.errors import ParcelfitError
from parcelfit.progress import ProgressEvent
from parcelfit.sim.params import MAX_REFINEMENT

if TYPE_CHECKING:
    from parcelfit.simulate import CaseSimulation


def simulate(
    rig: Annotated[
        str, typer.Option(help="Bundled rig name (E1, E2a, E2b, E3) or a rig .yaml file.")
    ] = "E3",
    consignment: Annotated[
        str,
        typer.Option(
            help="Bundled consignment type (KPBW, PB, KP, BW) or a consignment .yaml file."
        ),
    ] = "KPBW",
    setting: SettingOption = 1,
    set_: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            metavar="NAME=VALUE",
            help="A parameter in the catalogue's unit (see `parcelfit params`); repeatable.",
        ),
    ] = None,
    out: Annotated[Path, typer.Option(help="Trajectory file to write (.csv or .parquet).")] = Path(
        "run.csv"
    ),
    video: Annotated[
        Path | None,
        typer.Option(help="Also write a top-view animation (.gif, or .mp4 with ffmpeg)."),
    ] = None,
    timestep: Annotated[
        float | None,
        typer.Option(
            help="Time step [s]; replaces the rig's step_refinement.",
            show_default="1/2400 s (interpolated shell), 1/1200 s (full shell), divided by the "
            "rig's step_refinement",
        ),
    ] = None,
    spacing: Annotated[
        float | None,
        typer.Option(
            help="Shell mesh spacing for rigid contents [m].",
            show_default="the type's own (mesh_spacing), else 0.03 m",
        ),
    ] = None,
    film_spacing: Annotated[
        float | None,
        typer.Option(
            help="Film mesh spacing around a soft content [m].",
            show_default="0.05 m",
        ),
    ] = None,
    membrane_cap: Annotated[
        float | None,
        typer.Option(
            help="Largest in-plane stiffness E*t of the packaging shell [N/m]: the shell keeps "
            "its bending stiffness (see the simulator's README, Resolution).",
        ),
    ] = None,
    belt_friction: Annotated[
        str,
        typer.Option(
            help="Friction law on belts, strips and rollers: mujoco (MuJoCo's contacts) or "
            "coulomb (Coulomb forces at the contact points; see the simulator's README, Sliding).",
        ),
    ] = "mujoco",
    shell_dof: Annotated[
        str,
        typer.Option(
            help="The packaging shell's degrees of freedom: auto (the consignment file's "
            "shell if it names one, e.g. trilinear over the cells of its shell_cells for the "
            "bundled rigid-content types; else quadratic around a rigid content, full around a soft "
            "one), full (one per vertex; give a fine --timestep, "
            "e.g. 0.000208333 for 1/4800 s), quadratic or trilinear (see the simulator's "
            "README, Spin).",
        ),
    ] = "auto",
    shell_cells: Annotated[
        str | None,
        typer.Option(
            help="An interpolated shell's grid of cells along the parcel's length, width and "
            "height, e.g. 4,4,1 (default: the consignment file's with its own shell, else one).",
        ),
    ] = None,
    rim_brace: Annotated[
        float | None,
        typer.Option(
            help="Braces across an interpolated shell's rim cells, as a share of an ideal "
            "wedge's stiffness (0: none; e.g. 0.067 with --shell-cells 5,5,1 for KPBW; default: "
            "the consignment file's; see the simulator's README, Rim).",
            min=0,
            max=10,
        ),
    ] = None,
    mass_lumping: Annotated[
        str,
        typer.Option(
            help="How the packaging's (and a soft content's) mass is spread over the bodies that "
            "carry it: area (lumped by area and volume) or equal (MuJoCo's own equal shares, "
            "the former model).",
        ),
    ] = "area",
    refinement: Annotated[
        int,
        typer.Option(
            help="Divide every mesh spacing and the time step (the type's, the rig's or the "
            "ones given) by this: the same run on a refined model, as a calibration's "
            "convergence check simulates it; the wall-clock limit is multiplied by its cube.",
            min=1,
            max=MAX_REFINEMENT,
        ),
    ] = 1,
    wall_limit: Annotated[float, typer.Option(help="Wall-clock limit [s].")] = 600.0,
    seed: Annotated[
        int | None,
        typer.Option(
            help="Placement seed: draw the start pose from the rig's hand-placement scatter "
            "(default: the nominal pose; with --repeat, 0); a negative seed is the mirror image "
            "of its positive one's draw (a calibration's run ...-p-1 with cost.mirrored).",
        ),
    ] = None,
    repeat: Annotated[
        int,
        typer.Option(
            help="Simulate an ensemble of this many placements (seeds SEED, SEED+1, ...) and "
            "summarise transit times and rotations.",
            min=1,
        ),
    ] = 1,
    workers: WorkersOption = None,
) -> None:
    """Simulate one test case with MuJoCo and write the run (t, x, y, theta; SI units).

    With --repeat N, simulate N seeded placements and write each run (OUT with -s<seed> before
    its suffix), a summary table (OUT with -ensemble.csv) and print the ensemble statistics."""
    from parcelfit.runs import write_trajectory
    from parcelfit.runs.io import check_trajectory_path
    from parcelfit.sim.ensemble import MAX_PLACEMENTS
    from parcelfit.simulate import case_simulation

    at_most(repeat, "--repeat", MAX_PLACEMENTS)
    at_most(seed, "--seed", 2**32 - 1)
    workers_at_most(workers)
    check_paths(out, video)  # before a simulation of minutes
    check_trajectory_path(out)
    if video is not None:
        from parcelfit.sim.mujoco.render import check_video_path

        check_video_path(video)
        if repeat > 1:
            raise ParcelfitError("--video works with one run only", fix="leave out --repeat")
    run = case_simulation(
        rig,
        consignment,
        setting,
        set_ or [],
        record_vertices=video is not None,
        timestep=timestep,
        spacing=spacing,
        film_spacing=film_spacing,
        membrane_cap=membrane_cap,
        shell_dof=shell_dof,
        shell_cells=shell_cells,
        rim_brace=rim_brace,
        belt_friction=belt_friction,
        mass_lumping=mass_lumping,
        wall_limit=wall_limit,
    )
    if refinement > 1:
        run = replace(run, simulator=run.simulator.with_refinement(refinement))
    case = run.case
    if repeat > 1:
        _simulate_ensemble(run, seed or 0, repeat, worker_count(workers), out)
        return
    with console.status(f"simulating {case.label}"):
        result, frames = run.simulator.with_placement(seed).run_with_frames(run.params, case)
    d = result.diagnostics
    colour = "green" if result.ok else "red"
    console.print(
        f"[{colour}]{result.status.value}[/]: {d.get('message')}; {d.get('simulated_time', 0):.3f} s "
        f"simulated in {result.wall_time:.2f} s wall ({d.get('steps_per_second', 0):.0f} steps/s)"
    )
    if result.run is not None:
        tt = result.run.transit_time
        why = d.get("transit_note") or "a light barrier was not crossed"
        if tt is not None:
            console.print(f"transit time: {tt:.4f} s")
        elif d.get("barriers_out_of_order"):  # the status line said why
            console.print("transit time: not measured (the light barriers broke out of order)")
        else:
            console.print(f"transit time: not measured ({why})")
        from parcelfit.sim.ensemble import signed_rotation

        turned = math.degrees(signed_rotation(result.run.trajectory))
        console.print(
            f"rotation: {turned:+.2f} degrees (the heading at the end minus at the start; "
            "predict and the ensemble statistics use its size)"
        )
        console.print(Text(f"wrote {write_trajectory(result.run.trajectory, out)}"))
    if video is not None and frames is not None:
        from parcelfit.sim.mujoco.render import animate_run

        with console.status("rendering the animation"):
            console.print(Text(f"wrote {animate_run(run.rig, frames, video, title=case.label)}"))
    if not result.ok:
        raise typer.Exit(code=1)


def _shell_text(dof: str, cells: tuple[int, int, int]) -> str:
    """A shell for a table: its degrees of freedom and, if more than one, its cells."""
    if cells == (1, 1, 1):
        return dof
    return f"{dof}, {cells[0]} x {cells[1]} x {cells[2]} cells"


def _simulate_ensemble(run: CaseSimulation, first: int, n: int, workers: int, out: Path) -> None:
    """Simulate ``n`` placements from seed ``first`` (`parcelfit.simulate.simulate_placements`)
    with a progress bar; print their table and summary."""
    import math

    from parcelfit.simulate import simulate_placements

    case = run.case
    if not any(run.rig.start.scatter):
        console.print(
            Text(
                f"rig {run.rig.name} has no start.scatter: every placement starts at the nominal "
                f"pose, so the {n} runs are alike (give start.scatter in the rig file)",
                style="yellow",
            )
        )
    with Progress(*Progress.get_default_columns(), TimeElapsedColumn(), console=console) as bar:
        task = bar.add_task(f"{case.label}: {n} placements", total=n)
        done = simulate_placements(run, first, n, workers, out, lambda: bar.advance(task))
    rows, st, table_path = done.rows, done.summary, done.table
    table = Table(title=f"{case.label}: {n} placements (seeds {first}-{first + n - 1})")
    for col in ("seed", "status", "transit time [s]", "rotation [deg]", "outcome"):
        table.add_column(escape(col), justify="right" if col != "status" else "left")
    for r in rows:
        table.add_row(
            str(r["seed"]),
            r["status"],
            "-" if r["transit_time_s"] is None else f"{r['transit_time_s']:.3f}",
            "-" if r["rotation_deg"] is None else f"{r['rotation_deg']:.1f}",
            r["outcome"],
        )
    console.print(table)
    console.print(
        f"rotation [deg]: median {math.degrees(st.rotation_median):.1f} "
        f"(quartiles {math.degrees(st.rotation_q25):.1f}-{math.degrees(st.rotation_q75):.1f}, "
        f"max {math.degrees(st.rotation_max):.1f}); > 90 deg in {st.share_over_90:.0%}, "
        f"> 180 deg in {st.share_over_180:.0%}; {st.spins} spins, {st.slides} slides",
        markup=False,
    )
    console.print(
        f"transit time [s]: median {st.transit_median:.3f}, mean {st.transit_mean:.3f} "
        f"+- {st.transit_sem:.3f} (standard error); rank correlation with rotation "
        + (
            f"{st.rank_correlation:.2f}"
            if math.isfinite(st.rank_correlation)
            else "none (no spread in one of the two)"
        ),
        markup=False,
    )
    console.print(f"wrote {n} runs and {table_path}", markup=False)
    if st.n_ok < st.n:
        raise typer.Exit(code=1)


def rigs() -> None:
    """List the bundled test rigs with their speed settings, and the bundled consignment types
    with their sizes and shells."""
    from parcelfit.sim.mujoco import bundled_rig_names, load_rig

    table = Table(title="Bundled rigs (parcelfit simulate --rig NAME)", title_justify="left")
    for col in ("rig", "surfaces", "speed settings [m/s]", "light barriers"):
        table.add_column(escape(col))  # units in [] are text, not Rich markup
    for name in bundled_rig_names():
        r = load_rig(name)
        speeds = "; ".join(
            f"{k}: " + ", ".join(f"{d} {v:g}" for d, v in r.speeds[k].items())
            for k in sorted(r.speeds)
        )
        table.add_row(
            name,
            ", ".join(f"{s.name} ({s.type})" for s in r.surfaces),
            speeds,
            " -> ".join(b.name for b in r.barriers),
        )
    console.print(table)
    _print_folder("rigs", "rig")
    from parcelfit.sim.mujoco import SceneOptions, bundled_consignment_names, load_consignment

    table = Table(title="Bundled consignment types (--consignment NAME)", title_justify="left")
    for col in (
        "type",
        "mass [g]",
        "outer L x W x H [mm]",
        "content",
        "content L x W x H [mm]",
        "packaging shell",
    ):
        table.add_column(escape(col))
    default_scene = SceneOptions()
    for name in bundled_consignment_names():
        c = load_consignment(name)
        table.add_row(
            name,
            f"{c.mass * 1e3:g}",
            " x ".join(f"{v * 1e3:g}" for v in c.outer),
            c.content_kind,
            " x ".join(f"{v * 1e3:g}" for v in c.content),
            _shell_text(*default_scene.shell_of(c)),
        )
    console.print(table)
    _print_folder("consignments", "consignment")


def _print_folder(kind: str, what: str) -> None:
    """Where the bundled files of ``kind`` lie, to be copied as the start of one's own."""
    from importlib.resources import files

    folder = files("parcelfit.sim.mujoco").joinpath(kind)
    console.print(
        Text(f"their files, to copy as the start of your own {what} file: {folder}"),
        highlight=False,
    )


def params(
    consignment: Annotated[
        str,
        typer.Option(
            help="Bundled consignment type (or a consignment .yaml file) whose parameters to list."
        ),
    ] = "KPBW",
) -> None:
    """List the simulation parameters with units, screening ranges and defaults."""
    from parcelfit.sim.mujoco import load_consignment
    from parcelfit.sim.params import parameters_for

    cons = load_consignment(consignment)
    specs = parameters_for(cons.content_kind)
    own = dict(cons.parameters)
    table = Table(
        title=f"{len(specs)} parameters for {cons.name} ({cons.content_kind} content); "
        "* = published screening range"
        + ("; ^ = this type's own default (its consignment file)" if own else ""),
        title_justify="left",
    )
    for col in ("name", "meaning", "unit", "low", "high", "default"):
        table.add_column(col, justify="right" if col in ("low", "high", "default") else "left")
    for p in specs:
        r = p.range_for(cons.content_kind)
        table.add_row(
            p.name + (" *" if p.published else ""),
            p.meaning,
            p.unit,
            f"{r.low:g}",
            f"{r.high:g}",
            f"{own[p.name]:g} ^" if p.name in own else f"{r.default:g}",
        )
    console.print(table)


def synth(
    spec: Annotated[Path, typer.Argument(help="Twin specification YAML (cases, truth, settings).")],
    out: Annotated[Path, typer.Option("--out", help="Folder for the dataset.")] = Path("twin"),
    executor: Annotated[
        str | None,
        typer.Option(
            metavar="[serial|local]",
            help="Where simulations run: local (worker processes; the default for more than "
            "one worker) or serial (in this process, one at a time; for debugging).",
        ),
    ] = None,
    workers: WorkersOption = None,
) -> None:
    """Make a SYNTHETIC twin-experiment dataset from hidden true parameters (and truth.yaml)."""
    from parcelfit.synth import load_twin_spec

    check_executor(executor, ("serial", "local"))
    check_paths(out)
    resumes()
    from parcelfit.synth import expected_cost

    workers_at_most(workers)
    tw = load_twin_spec(spec)
    workers = worker_count(workers)
    total = len(tw.cases) * tw.settings.runs
    serial = executor == "serial" or (executor is None and workers <= 1)
    where = "in this process" if serial else f"on {workers} processes"
    console.print(
        f"[bold]twin dataset[/] {tw.name}: {len(tw.cases)} test cases x {tw.settings.runs} runs "
        f"{where} [yellow](SYNTHETIC)[/]"
    )
    say_cost(expected_cost(tw, 1 if serial else workers))
    with Progress(*Progress.get_default_columns(), TimeElapsedColumn(), console=console) as bar:
        task = bar.add_task("simulating twin runs", total=total)

        def step(event: ProgressEvent) -> None:
            bar.update(task, completed=event.done)
            bar.console.print(Text(f"  {event.message}"), highlight=False)

        path = tw.make(out, workers=workers, executor=executor, progress=step)
    truth_file = path.parent / "truth.yaml"
    console.print(f"[green]done[/]: {escape(str(path))} and {escape(str(truth_file))}")
