"""The ``parcelfit`` command: a thin layer over the package's functions."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from functools import wraps
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer
from rich.console import Console
from rich.table import Table

from parcelfit import __version__
from parcelfit.errors import ParcelfitError

app = typer.Typer(
    name="parcelfit",
    help="Calibrate physics simulations of parcels with flexible packaging against tracked experiments.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
console = Console()
err_console = Console(stderr=True)
F = TypeVar("F", bound=Callable[..., Any])


def friendly_errors(func: F) -> F:
    """Show a `ParcelfitError` as one red message and exit with status 2, without a traceback."""

    @wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except ParcelfitError as exc:
            err_console.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
            raise typer.Exit(code=2) from None

    return wrapper  # type: ignore[return-value]


DatasetArg = Annotated[Path, typer.Argument(help="Dataset folder (holding dataset.yaml).")]


@app.command()
@friendly_errors
def version() -> None:
    """Print parcelfit's version."""
    console.print(f"parcelfit {__version__}")


@app.command()
@friendly_errors
def reference(
    dataset: DatasetArg,
    as_json: Annotated[bool, typer.Option("--json", help="Print machine-readable JSON.")] = False,
) -> None:
    """Choose each test case's reference run (DTW distance matrices, method section 4)."""
    from parcelfit.analysis import reference_runs
    from parcelfit.runs import load_dataset

    selections = reference_runs(load_dataset(dataset))
    if as_json:
        sys.stdout.write(json.dumps([s.to_dict() for s in selections.values()], indent=1) + "\n")
        return
    for sel in selections.values():
        table = Table(
            title=f"{sel.case.label}: reference run [bold]{sel.reference_id}[/]",
            title_justify="left",
        )
        table.add_column("run")
        table.add_column("row sum of D_combined", justify="right")
        table.add_column("transit time [s]", justify="right")
        for i, run_id in enumerate(sel.run_ids):
            mark = " *" if i == sel.index else ""
            tt = sel.transit_times[i]
            table.add_row(
                run_id + mark, f"{sel.row_sums[i]:.3f}", "-" if tt is None else f"{tt:.3f}"
            )
        console.print(table)


@app.command()
@friendly_errors
def stats(
    dataset: DatasetArg,
    out: Annotated[Path, typer.Option("--out", help="Folder for tables and box plots.")] = Path(
        "stats"
    ),
    alpha: Annotated[
        float, typer.Option(help="False discovery rate for Benjamini-Hochberg.")
    ] = 0.05,
    family: Annotated[
        str, typer.Option(help="Adjust per 'rig_setting' or over 'all' tests.")
    ] = "rig_setting",
) -> None:
    """Compare transit times between consignment types (Mann-Whitney U + Benjamini-Hochberg)."""
    from parcelfit.analysis import transit_statistics
    from parcelfit.runs import load_dataset

    result = transit_statistics(load_dataset(dataset), out, alpha=alpha, family=family)
    _print_tests(result.tests)
    for f in result.files:
        console.print(f"wrote {f}")


def _print_tests(tests: Any) -> None:
    from parcelfit.stats import significance_stars

    table = Table(
        title="Transit-time comparisons (two-sided Mann-Whitney U, BH-adjusted)",
        title_justify="left",
    )
    for col in ("rig", "setting", "A", "B", "median A [s]", "median B [s]", "p", "p adj.", ""):
        table.add_column(col, justify="right" if col not in ("rig", "A", "B") else "left")
    for _, r in tests.iterrows():
        table.add_row(
            r["rig"],
            str(r["speed_setting"]),
            r["type_a"],
            r["type_b"],
            f"{r['median_a_s']:.3f}",
            f"{r['median_b_s']:.3f}",
            f"{r['p_value']:.2g}",
            f"{r['p_adjusted']:.2g}",
            significance_stars(r["p_adjusted"]),
        )
    console.print(table)


@app.command()
@friendly_errors
def demo(
    out: Annotated[
        Path, typer.Option("--out", help="Folder for everything the demo writes.")
    ] = Path("parcelfit-demo"),
) -> None:
    """Run the analysis on the bundled SYNTHETIC example dataset: statistics and reference runs."""
    from parcelfit.analysis import reference_runs, transit_statistics, write_reference_runs
    from parcelfit.data import example_dataset_path
    from parcelfit.runs import load_dataset

    path = example_dataset_path()
    with console.status("loading the bundled example dataset"):
        ds = load_dataset(path)
    console.print(
        f"[bold]dataset[/] {ds.name}: {len(ds.cases)} test cases, {len(ds.runs())} runs "
        "[yellow](SYNTHETIC: simulated, not measured)[/]"
    )
    with console.status("transit-time statistics"):
        result = transit_statistics(ds, out / "stats")
    _print_tests(result.tests)
    with console.status("reference runs (DTW distance matrices)"):
        selections = reference_runs(ds)
    table = Table(title="Reference run per test case", title_justify="left")
    for col in (
        "test case",
        "reference run",
        "runs",
        "largest DTW_xy [m]",
        "largest DTW_theta [rad]",
    ):
        table.add_column(col)
    for s in selections.values():
        table.add_row(
            s.case.label,
            s.reference_id,
            str(len(s.run_ids)),
            f"{s.max_xy**0.5:.3f}",
            f"{s.max_theta**0.5:.3f}",
        )
    console.print(table)
    ref_file = write_reference_runs(selections, out / "reference_runs.json")
    console.print(f"[green]done[/]: results in {out}/ ({ref_file.name}, stats/)")


@app.command()
@friendly_errors
def simulate(
    rig: Annotated[
        str, typer.Option(help="Bundled rig name (E1, E2a, E2b, E3) or a rig .yaml file.")
    ] = "E3",
    consignment: Annotated[
        str, typer.Option(help="Bundled type (KPBW, PB, KP, BW) or a .yaml file.")
    ] = "KPBW",
    setting: Annotated[int, typer.Option(help="Speed setting of the rig.")] = 1,
    set_: Annotated[
        list[str] | None,
        typer.Option("--set", help="NAME=VALUE in the catalogue's unit (see `parcelfit params`)."),
    ] = None,
    out: Annotated[Path, typer.Option(help="Trajectory file to write (.csv or .parquet).")] = Path(
        "run.csv"
    ),
    video: Annotated[
        Path | None,
        typer.Option(help="Also write a top-view animation (.gif, or .mp4 with ffmpeg)."),
    ] = None,
    timestep: Annotated[float, typer.Option(help="Time step [s].")] = 1.0 / 600.0,
    spacing: Annotated[
        float, typer.Option(help="Shell mesh spacing for rigid contents [m].")
    ] = 0.03,
    wall_limit: Annotated[float, typer.Option(help="Wall-clock limit [s].")] = 600.0,
) -> None:
    """Simulate one test case with MuJoCo and write the run (t, x, y, theta; SI units)."""
    from parcelfit.runs import TestCase, write_trajectory
    from parcelfit.sim.mujoco import (
        MujocoSimulator,
        SceneOptions,
        SimOptions,
        load_consignment,
        load_rig,
    )
    from parcelfit.sim.params import parse_assignments, resolve

    rig_obj = load_rig(rig)
    cons = load_consignment(consignment)
    params = resolve(cons.content_kind, user_values=parse_assignments(set_ or []))
    sim = MujocoSimulator(
        SimOptions(
            scene=SceneOptions(timestep=timestep, spacing=spacing),
            wall_limit=wall_limit,
            record_vertices=video is not None,
        ),
        rigs={rig_obj.name: rig_obj},
        consignments={cons.name: cons},
    )
    case = TestCase(rig_obj.name, cons.name, setting)
    rig_obj.drive_speeds(setting)  # a clear error for an unknown setting before simulating
    with console.status(f"simulating {case.label}"):
        result, frames = sim.run_with_frames(params, case)
    d = result.diagnostics
    colour = "green" if result.ok else "red"
    console.print(
        f"[{colour}]{result.status.value}[/]: {d.get('message')}; {d.get('simulated_time', 0):.3f} s "
        f"simulated in {result.wall_time:.2f} s wall ({d.get('steps_per_second', 0):.0f} steps/s)"
    )
    if result.run is not None:
        tt = result.run.transit_time
        console.print(
            f"transit time: {'not measured (a light barrier was not crossed)' if tt is None else f'{tt:.4f} s'}"
        )
        console.print(f"wrote {write_trajectory(result.run.trajectory, out)}")
    if video is not None and frames is not None:
        from parcelfit.sim.mujoco.render import animate_run

        with console.status("rendering the animation"):
            console.print(f"wrote {animate_run(rig_obj, frames, video, title=case.label)}")
    if not result.ok:
        raise typer.Exit(code=1)


@app.command()
@friendly_errors
def rigs() -> None:
    """List the bundled test rigs with their speed settings."""
    from parcelfit.sim.mujoco import bundled_rig_names, load_rig

    table = Table(title="Bundled rigs (parcelfit simulate --rig NAME)", title_justify="left")
    for col in ("rig", "surfaces", "speed settings [m/s]", "light barriers"):
        table.add_column(col)
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
    from parcelfit.sim.mujoco import bundled_consignment_names, load_consignment

    table = Table(title="Bundled consignment types (--consignment NAME)", title_justify="left")
    for col in ("type", "mass [g]", "outer L x W x H [mm]", "content", "content L x W x H [mm]"):
        table.add_column(col)
    for name in bundled_consignment_names():
        c = load_consignment(name)
        table.add_row(
            name,
            f"{c.mass * 1e3:g}",
            " x ".join(f"{v * 1e3:g}" for v in c.outer),
            c.content_kind,
            " x ".join(f"{v * 1e3:g}" for v in c.content),
        )
    console.print(table)


@app.command()
@friendly_errors
def params(
    consignment: Annotated[
        str, typer.Option(help="Consignment type (or .yaml) whose parameters to list.")
    ] = "KPBW",
) -> None:
    """List the simulation parameters with units, screening ranges and defaults."""
    from parcelfit.sim.mujoco import load_consignment
    from parcelfit.sim.params import parameters_for

    cons = load_consignment(consignment)
    specs = parameters_for(cons.content_kind)
    table = Table(
        title=f"{len(specs)} parameters for {cons.name} ({cons.content_kind} content); "
        "* = published screening range",
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
            f"{r.default:g}",
        )
    console.print(table)


@app.command()
@friendly_errors
def calibrate(
    study_file: Annotated[Path, typer.Argument(help="Study file (YAML).")],
    out: Annotated[
        Path | None,
        typer.Option(help="Study folder (default: next to the study file, named after it)."),
    ] = None,
    executor: Annotated[
        str | None, typer.Option(help="local or dask (default: the study file's).")
    ] = None,
    scheduler: Annotated[
        str | None, typer.Option(help="Dask scheduler address, e.g. tcp://HOST:8786.")
    ] = None,
    workers: Annotated[
        int | None, typer.Option(help="Local worker processes (default: one per core).")
    ] = None,
) -> None:
    """Calibrate by batch Bayesian optimisation; rerunning the same command resumes the study."""
    from rich.live import Live

    from parcelfit.optimize.calibration import Calibration, Progress
    from parcelfit.optimize.study import load_study

    study = load_study(study_file)
    folder = out or study_file.parent / study_file.stem
    state: dict[str, Progress | None] = {"p": None}

    def render() -> Table:
        p = state["p"]
        table = Table(
            title=f"calibration {study.name} -> {folder}", title_justify="left", show_header=False
        )
        table.add_column(style="bold")
        table.add_column()
        if p is None:
            table.add_row("status", "starting (reference runs, workers)")
            return table
        verdict = {None: "not yet", True: "[green]passed[/]", False: "[red]failed[/]"}[
            p.last_validation
        ]
        table.add_row("iteration", str(p.iteration))
        table.add_row("evaluations", f"{p.done} done, {p.running} running, budget {p.budget}")
        table.add_row("best cost", "-" if p.best_cost is None else f"{p.best_cost:.4g}")
        table.add_row("last validation", verdict)
        table.add_row("last event", p.message)
        return table

    with Live(render(), console=console, refresh_per_second=4, transient=False) as live:

        def update(p: Progress) -> None:
            state["p"] = p
            live.update(render())

        result = Calibration(
            study,
            folder,
            executor=executor,
            scheduler=scheduler,
            workers=workers,
            on_progress=update,
        ).run()
    console.print()
    console.print(
        f"[bold]{result.stop_reason}[/] after {result.evaluations} evaluations in "
        f"{result.iterations} iterations; study folder {result.folder}"
    )
    if result.best_params is not None:
        _print_params(result.best_params, result.best_cost)
    from parcelfit.optimize.plots import study_figures

    with console.status("figures"):
        figures = study_figures(folder)
    console.print(f"figures in {folder / 'figures'} ({len(figures) // 2} figures, PNG and SVG)")


def _print_params(params: dict[str, float], cost: float | None) -> None:
    from parcelfit.sim.params import CATALOGUE

    table = Table(
        title=f"best parameters (cost {cost:.4g})" if cost is not None else "best parameters",
        title_justify="left",
    )
    table.add_column("parameter")
    table.add_column("value", justify="right")
    table.add_column("unit")
    specs = {p.name: p for p in CATALOGUE}
    for name, value in params.items():
        spec = specs.get(name)
        table.add_row(
            name, f"{spec.from_si(value) if spec else value:.5g}", spec.unit if spec else "SI"
        )
    console.print(table)


@app.command()
@friendly_errors
def screen(
    screen_file: Annotated[Path, typer.Argument(help="Screen file (YAML).")],
    out: Annotated[
        Path | None, typer.Option(help="Screen folder (default: next to the file, named after it).")
    ] = None,
    workers: Annotated[
        int | None, typer.Option(help="Local worker processes (default: one per core).")
    ] = None,
) -> None:
    """Screen parameters: fractional -> full factorial designs, effects, Pareto charts, a selection."""
    from parcelfit.optimize.screening import load_screen, run_screen

    spec = load_screen(screen_file)
    folder = out or screen_file.parent / screen_file.stem
    with console.status("screening") as status_line:
        stages, selection = run_screen(
            spec, folder, workers=workers, on_event=lambda m: status_line.update(m)
        )
    for k, stage in enumerate(stages, start=1):
        table = Table(
            title=f"stage {k}: {stage.kind} factorial over {len(stage.factors)} parameters "
            f"({stage.analyses[0].method} errors)",
            title_justify="left",
        )
        for col in ("response", "term", "effect", "|t|", "p", ""):
            table.add_column(col, justify="right" if col in ("effect", "|t|", "p") else "left")
        for a in stage.analyses:
            for _, r in a.table.head(6).iterrows():
                table.add_row(
                    a.response,
                    r["term"],
                    f"{r['effect']:.3g}",
                    f"{abs(r['t']):.3g}",
                    f"{r['p_value']:.2g}",
                    "*" if r["significant"] else "",
                )
        console.print(table)
    console.print(
        f"[bold]selected for calibration:[/] {', '.join(selection['selected']) or 'none'}"
    )
    console.print(f"results in {folder} (selection.yaml, stageN-effects.csv, Pareto charts)")


@app.command()
@friendly_errors
def status(
    study_dir: Annotated[Path, typer.Argument(help="Study folder (holding study.sqlite).")],
    as_json: Annotated[bool, typer.Option("--json", help="Print machine-readable JSON.")] = False,
) -> None:
    """Show the state of a running or finished calibration study."""
    from parcelfit.optimize.calibration import study_status

    info = study_status(study_dir)
    if as_json:
        sys.stdout.write(json.dumps(info, indent=1) + "\n")
        return
    name = (info["study"] or {}).get("name", "?")
    console.print(
        f"[bold]{name}[/]: {info['evaluations']} evaluations ({info['by_status']}), "
        f"{info['iterations']} iterations, reference run {info['reference_run']}, "
        f"stopped: {info['stop_reason'] or 'not yet'}"
    )
    for v in info["validations"]:
        console.print(
            f"  validation at iteration {v['iteration']}: {v['status']}, passed={v['passed']}"
        )
    if info["best"]:
        _print_params(info["best"]["params"], info["best"]["cost"])


def main() -> None:
    """Entry point of the ``parcelfit`` console script."""
    app()


if __name__ == "__main__":
    main()
