"""`imutool filter INPUT -o OUTPUT`: roll/pitch/heading by quaternion EKF, compass KF or low-pass baseline.

Option parsing and printing here; :func:`filter_route` maps the parsed options onto
:func:`imutool.filtering.run_filter` (the work: loading, streaming, GNSS, smoother summary), and is what
`imutool batch filter` calls; a Python user calls ``run_filter`` directly.
"""

from __future__ import annotations

import os
from typing import Any

import click
import numpy as np

from formats.atomic import atomic_path
from formats.errors import ImutoolError
from imutool.cli.common import (
    emit_summary,
    input_options,
    lazy_bar,
    note_input,
    output_options,
    parse_vector,
    route_of,
    safe_outputs,
    strict_requested,
)
from imutool.routes import OnInput, RouteResult


@click.command(
    "filter", epilog="Example: imutool simulate ship-roll -o roll.csv && imutool filter roll.csv -o est.csv --smooth"
)
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True))
@click.option("-o", "--output", required=True, type=click.Path(), help="Output file (.csv, .bag, ...).")
@click.option(
    "--method",
    type=click.Choice(["ekf", "lpf", "accel", "compass"]),
    default="ekf",
    show_default=True,
    help="ekf: quaternion EKF with gyro bias; lpf: Butterworth low-passed accel tilt + magnetic heading "
    "(paper baseline); accel: unfiltered accelerometer tilt; compass: heading Kalman filter.",
)
@click.option(
    "--params",
    "params_file",
    type=click.Path(exists=True, dir_okay=False),
    default=None,
    help="EKF: TOML file with tuning parameters (every constant, its unit and default: "
    "`--save-params FILE` writes the full set).",
)
@click.option(
    "--param",
    "param_items",
    multiple=True,
    metavar="NAME=VALUE",
    help="EKF: override one tuning parameter (repeatable), e.g. --param mag_noise_deg=10.",
)
@click.option(
    "--save-params",
    type=click.Path(dir_okay=False),
    default=None,
    help="EKF: write the parameters used (TOML, with units) to this file.",
)
@click.option(
    "--update-every",
    type=int,
    default=None,
    help="EKF: covariance propagation + accel/mag updates every N samples (paper: 40 at 200 Hz). Default "
    "(or 0): N = ⌊sample rate / update_rate_hz⌋ (50 Hz: 4 at 200 Hz; 1 with the raw accelerometer, "
    "accel_lp_tau 0). The noise figures are per sample, so N sets the speed, not the filter.",
)
@click.option(
    "--mag-mode",
    type=click.Choice(["heading", "full", "off"]),
    default=None,
    help="EKF magnetometer use: heading only (default; never touches roll/pitch), full 3-D vector (paper), off.",
)
@click.option(
    "--smooth",
    is_flag=True,
    help="EKF: add the offline smoother (the accelerometer low-pass run forwards and backwards, a second "
    "filter pass, the RTS backward pass: zero-lag estimates).",
)
@click.option(
    "--lever-arm",
    default=None,
    metavar="X,Y,Z",
    help="EKF: sensor position relative to the vessel's centre of rotation, m, body FRD (x bow, "
    "y starboard, z down; a bridge 20 m above the roll centre is z = -20): the tangential and "
    "centripetal accelerations ω̇×r + ω×(ω×r) are removed before the accelerometer update.",
)
@click.option(
    "--antenna-arm",
    default=None,
    metavar="X,Y,Z",
    help="EKF: the GNSS antenna's position relative to the centre of rotation, m, body FRD, when its velocity "
    "(sog/cog or vel_n/vel_e) is the antenna's own; default: the receiver gives the centre's velocity.",
)
@click.option(
    "--gnss",
    "gnss_path",
    type=click.Path(exists=True, dir_okay=False),
    default=None,
    help="EKF: NMEA or CSV file with sog (m/s) and cog (deg): velocity aiding (the velocity's change between "
    "fixes removes turn, surge and sway from the accelerometer). sog/cog or vel_n/vel_e (m/s) columns of INPUT "
    "are used automatically.",
)
@click.option("--no-gnss", is_flag=True, help="EKF: ignore sog/cog and vel_n/vel_e even when present.")
@click.option(
    "--speed",
    default=None,
    metavar="SPEED",
    help="EKF: the ship's speed through the water from its log, m/s or with a unit ('15kn'), taken as constant for "
    "the whole run: where the input has no GNSS velocity, a turn's centripetal acceleration (speed × rate of turn, "
    "along the bow) is removed.",
)
@click.option(
    "--heading",
    "heading_path",
    type=click.Path(exists=True, dir_okay=False),
    default=None,
    help="EKF: NMEA (HDT/THS) or CSV file with heading_true (deg) from a gyrocompass: the filter's heading "
    "measurement instead of the magnetometer (a heading_true column of INPUT is used "
    "automatically); its delay: --param heading_input_latency=SECONDS.",
)
@click.option("--cutoff", type=float, default=0.5, show_default=True, help="lpf: cutoff frequency, Hz.")
@click.option("--order", type=int, default=2, show_default=True, help="lpf: Butterworth order.")
@click.option(
    "--compass-model",
    type=click.Choice(["auto", "scalar", "gyro"]),
    default="auto",
    show_default=True,
    help="compass: scalar KF (paper) or two-state with the gyro rate of turn (auto: gyro if present).",
)
@click.option("--q", "comp_q", type=float, default=0.003, show_default=True, help="compass: Q, deg² per sample.")
@click.option("--r", "comp_r", type=float, default=2.0, show_default=True, help="compass: R, deg².")
@click.option(
    "--variation",
    type=float,
    default=0.0,
    show_default=True,
    help="compass: magnetic variation, deg east positive (true = magnetic + variation).",
)
@click.option("--paper-init", is_flag=True, help="compass: x0 = 0, P0 = 0 as in the paper.")
@click.option(
    "--chunk-rows",
    type=int,
    default=250_000,  # imutool.filtering.STREAM_CHUNK_ROWS (not imported here: it loads numba)
    show_default=True,
    help="EKF on CSV/Parquet: stream the file in chunks of this many rows when larger than --stream-mb.",
)
@click.option(
    "--stream-mb",
    type=float,
    default=300.0,
    show_default=True,
    help="EKF on CSV/Parquet: stream (bounded memory) when the input is larger than this (MB; Parquet: "
    "its data as float64 in memory).",
)
@input_options
@output_options
@safe_outputs("output", "save_params")
def filter_cmd(as_json: bool, quiet: bool, **options: Any) -> None:
    """Estimate roll, pitch and heading (deg) from INPUT (gyro/accel/mag, or an NMEA heading for compass).

    Output columns: roll, pitch, heading (deg), qw..qz (body→NED), gyro_bias_x..z (rad/s), roll_std,
    pitch_std, heading_std (deg, one sigma), accel_rejected, mag_rejected, rest, inconsistent (0/1: the
    self-check of roll and pitch), heading_inconsistent (0/1: the heading's, from the magnetometer or heading
    input); ref_* and label columns of the input are carried over so `imutool evaluate OUTPUT`
    works directly. EKF tuning: --params FILE / --param NAME=VALUE (list and units: --save-params).
    """
    with lazy_bar("filter", unit="samples", quiet=quiet) as b:
        res = filter_route(quiet=quiet, on_input=note_input, progress=b, **options)
    _warn(res.summary)
    emit_summary(res.summary, as_json, quiet)


def filter_route(
    input_path: str,
    output: str,
    method: str,
    params_file: str | None,
    param_items: tuple[str, ...],
    save_params: str | None,
    update_every: int | None,
    mag_mode: str | None,
    smooth: bool,
    lever_arm: str | None,
    antenna_arm: str | None,
    gnss_path: str | None,
    no_gnss: bool,
    heading_path: str | None,
    speed: str | None,
    cutoff: float,
    order: int,
    compass_model: str,
    comp_q: float,
    comp_r: float,
    variation: float,
    paper_init: bool,
    chunk_rows: int,
    stream_mb: float,
    quiet: bool = True,
    on_input: OnInput | None = None,
    progress: Any = None,
    **io: Any,
) -> RouteResult:
    """Parsed options → :func:`imutool.filtering.run_filter` (the same for the command and ``imutool batch``):
    the EKF's parameters from --params/--param (the file's migration notes on stderr unless ``quiet``), the
    lever arm, the compass model, --save-params written."""
    if method == "ekf" and os.path.isfile(input_path):
        from imutool.filter_warm import warm_filter_kernels  # light: numba, not the filter

        # a cold cache: the second process starts before the filter's modules are imported here (~1 s), not after
        warm_filter_kernels(smooth, output.lower().endswith(".csv"), heading_path is not None)
    from imutool.attitude.params import params_from_options  # here, not at the top: `--help` loads no numba
    from imutool.compass import CompassParams
    from imutool.filtering import parse_speed, run_filter

    params, notes = params_from_options(params_file, param_items, update_every=update_every, mag_mode=mag_mode)
    if not quiet:
        for note in notes:  # what changed in meaning since an older parameters file was saved (the library's)
            click.echo(f"note: {note}", err=True)
    lever = parse_vector(lever_arm, 3, "--lever-arm") if lever_arm else None
    if lever is not None and not np.all(np.isfinite(lever)):
        raise ImutoolError(f"--lever-arm {lever_arm!r}: expected three finite numbers (m)")
    antenna = parse_vector(antenna_arm, 3, "--antenna-arm") if antenna_arm else None
    if antenna is not None and not np.all(np.isfinite(antenna)):
        raise ImutoolError(f"--antenna-arm {antenna_arm!r}: expected three finite numbers (m)")
    try:
        speed_mps = parse_speed(speed)
    except ImutoolError as e:
        raise ImutoolError(f"--{e}") from None
    if save_params:
        with atomic_path(save_params) as tmp:
            tmp.write_text(params.to_toml(), encoding="utf-8")
    inputs: list[dict[str, Any]] = []

    def seen(path: str, report: dict[str, Any]) -> None:
        if on_input is not None:
            on_input(path, report)
        inputs.append({"input": path, **report})

    res = run_filter(
        input_path,
        output,
        method=method,
        params=params,
        smooth=smooth,
        lever_arm=lever,
        antenna_arm=antenna,
        gnss=gnss_path if gnss_path and not no_gnss else None,
        use_gnss=not no_gnss,
        speed=speed_mps,
        heading=heading_path,
        cutoff_hz=cutoff,
        order=order,
        compass=CompassParams(q=comp_q, r=comp_r, model=compass_model, variation_deg=variation, paper_init=paper_init),
        params_file=params_file,
        chunk_rows=chunk_rows,
        stream_mb=stream_mb,
        progress=progress,
        strict=strict_requested(),
        on_input=seen,
        **io,
    )
    return RouteResult(res.summary, inputs, res.recording)


filter_cmd = route_of(filter_route, ("output", "save_params"))(filter_cmd)


def _warn(summary: dict[str, Any]) -> None:
    for w in summary.get("warnings") or []:
        click.echo(f"warning: {w}", err=True)
