"""The ``parcelfit`` command: a thin layer over the package's functions. Each command parses its
options, calls the library and prints what it returns; the commands live by family in the
modules of this package (`data`, `demo`, `tracking`, `simulation`, `study`, `screening`,
`prediction`), what they share in `options` (option types and checks) and `output` (consoles,
the command group's error handling, progress). Here they are registered, in the order that
``parcelfit --help`` lists them."""

from __future__ import annotations

import typer

from parcelfit import __version__
from parcelfit.cli import data, demo, prediction, screening, simulation, study, tracking
from parcelfit.cli.output import Commands, console

app = typer.Typer(
    name="parcelfit",
    help="Calibrate physics simulations of parcels with flexible packaging against tracked experiments.",
    cls=Commands,
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # help texts are plain text: units such as [s] or [mm] must not be read as Rich markup
    rich_markup_mode=None,
)


@app.command()
def version() -> None:
    """Print parcelfit's version."""
    console.print(f"parcelfit {__version__}")


app.command()(data.reference)
app.command()(data.stats)
app.command()(demo.demo)
app.command()(study.report)
app.command()(simulation.synth)
app.command()(tracking.track)
app.command("track-all")(tracking.track_all_command)
app.command("camera-calibrate")(tracking.camera_calibrate)
app.command()(simulation.simulate)
app.command()(simulation.rigs)
app.command()(simulation.params)
app.command()(study.calibrate)
app.command()(screening.screen)
app.command()(screening.precision)
app.command()(study.status)
app.command()(prediction.predict)
app.command()(prediction.design)


def main() -> None:
    """Entry point of the ``parcelfit`` console script."""
    app()


__all__ = ["app", "main"]
