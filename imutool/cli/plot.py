"""`imutool plot FILE CHANNEL... -o out.png|pdf`: one subplot per channel, units on the axes.

Only option parsing and printing here; the plot (min/max decimation, CSV streamed in chunks) is
:func:`imutool.plot.run_plot`, the route `imutool batch plot` and a Python user take.
"""

from __future__ import annotations

from typing import Any

import click

from imutool.cli.common import (
    default_of,
    emit_summary,
    input_options,
    note_input,
    route_of,
    safe_outputs,
    strict_requested,
)
from imutool.plot import run_plot
from imutool.routes import OnInput, RouteResult


def plot_route(
    path: str,
    channels: tuple[str, ...],
    output: str,
    quiet: bool = True,
    on_input: OnInput | None = None,
    **options: Any,
) -> RouteResult:
    """Parsed options → :func:`imutool.plot.run_plot`."""
    return run_plot(path, channels, output, strict=strict_requested(), on_input=on_input, **options)


@click.command("plot", epilog="Example: imutool plot roll.csv gyro accel -o roll.png --start 10 --end 60")
@click.argument("path", metavar="FILE", type=click.Path(exists=True, dir_okay=True))
@click.argument("channels", nargs=-1, required=True)
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Output .png, .pdf or .svg.")
@click.option("--start", type=float, default=None, help="Start, seconds from the first sample.")
@click.option("--end", type=float, default=None, help="End, seconds from the first sample.")
@click.option(
    "--max-points",
    type=int,
    default=default_of(run_plot, "max_points"),
    show_default=True,
    help="Per line; longer series are decimated to a min/max envelope.",
)
@click.option("--title", default=None, help="Figure title (default: the file name).")
@click.option(
    "--dpi", type=int, default=default_of(run_plot, "dpi"), show_default=True, help="Resolution of PNG output."
)
@input_options
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("--quiet", "-q", is_flag=True, help="No summary output.")
@safe_outputs("output")
def plot_cmd(path: str, channels: tuple[str, ...], output: str, as_json: bool, quiet: bool, **options: Any) -> None:
    """Plot CHANNEL... of FILE (names or prefixes: `gyro accel`, `ref`) to a PNG/PDF, one subplot each,
    units in the axis labels (angular rates in deg/s, angles in deg), time in seconds from the first sample.
    Each channel is drawn through its own samples (rows where it has no value are skipped; a real gap stays
    open), so channels of a multi-sentence NMEA log that arrive at different times all show."""
    res = plot_route(path, channels, output, on_input=note_input, **options)
    emit_summary(res.summary, as_json, quiet)


plot_cmd = route_of(plot_route, ("output",))(plot_cmd)
