"""`imutool zvi IN -o intervals.csv`: zero-velocity interval detection (paper eq. 43, SHOE, ARE, MV, MAG).

Only option parsing and printing here; the work is :func:`imutool.routes.zvi.run_zvi`, the route `imutool batch zvi`
and a Python user take (the detectors' defaults live in :data:`imutool.zvi.DEFAULTS`).
"""

from __future__ import annotations

from typing import Any

import click

from imutool.cli.common import (
    default_of,
    emit_summary,
    input_options,
    note_input,
    output_options,
    route_of,
    safe_outputs,
    strict_requested,
)
from imutool.progress import stages
from imutool.routes import OnInput
from imutool.routes.zvi import run_zvi
from imutool.zvi import DETECTORS

OUTPUTS = ("output", "flags_path", "plot_path")


def zvi_route(
    input_path: str,
    output: str,
    sigma_g: float | None,
    b_g: float | None,
    pick_threshold: bool,
    quiet: bool = True,
    on_input: OnInput | None = None,
    **options: Any,
) -> Any:
    """Parsed options → :func:`imutool.routes.zvi.run_zvi` (progress stages on stderr unless ``quiet``)."""
    with stages("zvi", ["reading", "detecting", "writing"], quiet) as steps:
        return run_zvi(
            input_path,
            output,
            sigma_g_deg_s=sigma_g,
            b_g_deg_s=b_g,
            pick=pick_threshold,
            strict=strict_requested(),
            on_input=on_input,
            stage=steps.stage,
            **options,
        )


@click.command("zvi", epilog="Example: imutool zvi walk.csv -o intervals.csv --detector shoe --gamma 1e5 --plot z.png")
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True))
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(dir_okay=False),
    help="Interval table: .csv (start_s,end_s,duration_s) or .json (summary + table).",
)
@click.option(
    "--detector",
    type=click.Choice(DETECTORS),
    default=default_of(run_zvi, "detector"),
    show_default=True,
    help="paper = eq. 43 gyro + accel-difference windows; Skog 2010: shoe (GLRT), are, mv, mag.",
)
@click.option(
    "--gamma",
    type=float,
    default=None,
    help="Skog detectors: threshold γ (stationary when T < γ). Default shoe/are 1e5, mv/mag 1.5e4.",
)
@click.option("--window", "window_s", type=float, default=None, help="Skog detectors: window W in s [0.05].")
@click.option("--sigma-a", type=float, default=None, help="Accelerometer noise std σ_a in m/s² [0.01].")
@click.option("--sigma-g", type=float, default=None, help="Gyro noise std σ_g in deg/s [0.1].")
@click.option("--b-g", type=float, default=None, help="paper: gyro bound B_g in deg/s [34.4 = 0.6 rad/s].")
@click.option("--b-a", type=float, default=None, help="paper: accel first-difference bound B_a in m/s² [2.0].")
@click.option("--window-g", "window_g_s", type=float, default=None, help="paper: gyro window N_g in s [0.05].")
@click.option("--window-a", "window_a_s", type=float, default=None, help="paper: accel window N_a in s [0.05].")
@click.option(
    "--min-duration", "min_duration_s", type=float, default=None, help="Drop intervals shorter than this, s [0.05]."
)
@click.option(
    "--flags",
    "flags_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="Also write the per-sample recording with columns zvi (0/1) and zvi_statistic.",
)
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="Plot signal, statistic, threshold and intervals (.png/.pdf).",
)
@click.option(
    "--labels",
    "labels",
    default=None,
    metavar="COLUMN",
    help="Column with true ZVI flags to score against (default: ref_zvi if present).",
)
@click.option(
    "--pick-threshold",
    is_flag=True,
    help="Grid-search the threshold (γ, or B_g for paper) maximising F1 against the labels; use it.",
)
@input_options
@output_options
@safe_outputs(*OUTPUTS)
def zvi_cmd(as_json: bool, quiet: bool, **options: Any) -> None:
    """Detect zero-velocity intervals in INPUT (needs gyro and accel) and write the interval table."""
    res = zvi_route(quiet=quiet, on_input=note_input, **options)
    emit_summary(res.summary, as_json, quiet)


zvi_cmd = route_of(zvi_route, OUTPUTS)(zvi_cmd)
