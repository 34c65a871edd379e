"""`imutool heave IN -o OUT`: real-time and delayed heave (m, positive up) from acceleration.

Only option parsing and printing here; the work is :func:`imutool.routes.heave.run_heave`, the route
`imutool batch heave` and a Python user take (defaults live there).
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
    parse_vector,
    route_of,
    safe_outputs,
    strict_requested,
)
from imutool.heave import ATTITUDES, ROUTE_METHODS, estimate_heave
from imutool.progress import stages
from imutool.routes import OnInput
from imutool.routes.heave import run_heave

OUTPUTS = ("output", "nmea_path")


def heave_route(
    input_path: str,
    output: str,
    vertical: str | None,
    lever_arm: str | None,
    nmea_path: str | None,
    gnss_lever_arm: str | None = None,
    quiet: bool = True,
    on_input: OnInput | None = None,
    **options: Any,
) -> Any:
    """Parsed options → :func:`imutool.routes.heave.run_heave` (progress stages on stderr unless ``quiet``)."""
    with stages("heave", ["reading", "heave", "writing"], quiet) as steps:
        return run_heave(
            input_path,
            output,
            vertical=[c.strip() for c in vertical.split(",")] if vertical else None,
            lever_arm=parse_vector(lever_arm, 3, "--lever-arm") if lever_arm else None,
            gnss_lever_arm=parse_vector(gnss_lever_arm, 3, "--gnss-lever-arm") if gnss_lever_arm else None,
            nmea=nmea_path,
            strict=strict_requested(),
            on_input=on_input,
            stage=steps.stage,
            **options,
        )


@click.command("heave", epilog="Example: imutool simulate sea-state -o sea.csv && imutool heave sea.csv -o heave.csv")
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True))
@click.option("-o", "--output", required=True, type=click.Path(), help="Output (.csv, ...): heave m positive UP.")
@click.option(
    "--method",
    type=click.Choice(ROUTE_METHODS),
    default=default_of(run_heave, "method"),
    show_default=True,
    help="realtime: phase-corrected double-integrator bank (harmonic KF on line spectra); harmonic: KF "
    "observer with per-harmonic phase cancellation; paper: the heave paper's KF multi-step observer; "
    "bandpass: causal HPₙ/s² baseline; envelope: the 'traditional' envelope detrend (offline); gnss: the "
    "detrended gnss_height of an RTK receiver (offline; taken whenever INPUT has no accelerometer).",
)
@click.option(
    "--height-window",
    "height_window_s",
    type=float,
    default=None,
    help="GNSS height heave: centred detrend window (s) [default 10 × the dominant period, 60–600 s].",
)
@click.option(
    "--gnss-fix",
    type=click.Choice(["rtk", "fixed", "any"]),
    default=default_of(run_heave, "gnss_fix"),
    show_default=True,
    help="GNSS heights used: rtk = GGA quality 4 (fixed) and 5 (float); fixed = 4 only; any = every fix.",
)
@click.option(
    "--gnss-lever-arm",
    default=None,
    metavar="X,Y,Z",
    help="Monitoring point relative to the GNSS antenna, m body FRD (antenna 12 m above it: 0,0,12); "
    "applied with INPUT's roll/pitch.",
)
@click.option(
    "--gnss-reference/--no-gnss-reference",
    default=default_of(run_heave, "gnss_reference"),
    show_default=True,
    help="With an accelerometer and a gnss_height channel: the height heave as ref_heave, compared in the summary.",
)
@click.option("--harmonics", type=int, default=None, help="Oscillators in the KF model [default 3 paper, 5 realtime].")
@click.option(
    "--vertical",
    default=None,
    metavar="COL[,COL]",
    help="Single vertical accelerometer column(s), averaged (e.g. ACC_Heave_SB,ACC_HEAVE_PS). "
    "Default: 3-axis accel rotated to NED with the attitude.",
)
@click.option(
    "--vertical-sign",
    type=click.Choice(["up", "down"]),
    default=default_of(run_heave, "vertical_sign"),
    show_default=True,
    help="Where the --vertical accelerometers' positive axis points.",
)
@click.option(
    "--attitude",
    type=click.Choice(ATTITUDES),
    default=default_of(run_heave, "attitude"),
    show_default=True,
    help="Vertical from: q columns (auto if present), the attitude EKF, a "
    "complementary tilt filter, or ref_q truth (testing only).",
)
@click.option(
    "--tilt-gain",
    type=float,
    default=default_of(run_heave, "tilt_gain"),
    show_default=True,
    help="Tilt filter gain (1/s); its gyro-bias integral gain is gain²/4 (critically damped).",
)
@click.option(
    "--lever-arm",
    default=None,
    metavar="X,Y,Z",
    help="Monitoring point relative to the IMU, m body FRD (x bow, y starboard, z down).",
)
@click.option(
    "--cutoff",
    type=float,
    default=None,
    help="Causal band-pass cut-off Hz, methods bandpass/paper/harmonic only [default 0.2 × dominant].",
)
@click.option(
    "--cutoff-ratio",
    type=float,
    default=None,
    help="Corner as a fraction of the tracked heave frequency [default 0.2; realtime: its tuned value].",
)
@click.option(
    "--order",
    type=int,
    default=None,
    help="High-pass order (≥ 3) [default 3; realtime: the corrected integrator's tuned order ≥ 4].",
)
@click.option(
    "--delayed-cutoff",
    type=float,
    default=None,
    help="Zero-phase delayed heave cut-off Hz [default 0.35 × record dominant frequency].",
)
@click.option(
    "--window",
    "window_s",
    type=float,
    default=None,
    help="Frequency-tracking window (s) [default 240 realtime, 120 the KF methods].",
)
@click.option(
    "--hop",
    "hop_s",
    type=float,
    default=default_of(estimate_heave, "hop_s"),
    show_default=True,
    help="Tracking update interval (s).",
)
@click.option(
    "--min-window",
    "min_window_s",
    type=float,
    default=default_of(estimate_heave, "min_window_s"),
    show_default=True,
    help="Data (s) before the first frequency estimate.",
)
@click.option(
    "--fmin",
    type=float,
    default=default_of(estimate_heave, "fmin"),
    show_default=True,
    help="Lowest heave frequency considered (Hz).",
)
@click.option(
    "--fmax",
    type=float,
    default=default_of(estimate_heave, "fmax"),
    show_default=True,
    help="Highest heave frequency considered (Hz).",
)
@click.option(
    "--bandwidth",
    type=float,
    default=default_of(estimate_heave, "bandwidth"),
    show_default=True,
    help="KF process noise as the oscillators' relative bandwidth.",
)
@click.option(
    "--meas-noise",
    type=float,
    default=default_of(estimate_heave, "meas_noise"),
    show_default=True,
    help="KF measurement noise as a fraction of the displacement std.",
)
@click.option(
    "--residual-noise",
    type=float,
    default=default_of(estimate_heave, "residual_noise"),
    show_default=True,
    help="Residual Δh random walk (fraction of std per √s).",
)
@click.option(
    "--settle-fraction",
    type=float,
    default=default_of(estimate_heave, "settle_fraction"),
    show_default=True,
    help="Real-time heave: settled only while its error bound heave_std ≤ this × the recent significant heave.",
)
@click.option(
    "--nmea",
    "nmea_path",
    default=None,
    type=click.Path(),
    help="Also write heave sentences here ($PASHR and/or TSS1, see --nmea-sentences); settling rows are "
    "flagged (PASHR IMU status 0, empty heave; TSS1 lower-case status).",
)
@click.option(
    "--nmea-sentences",
    default=default_of(run_heave, "nmea_sentences"),
    show_default=True,
    help="PASHR and/or TSS1 (TSS1 needs roll/pitch columns in INPUT, e.g. an imutool filter output).",
)
@click.option(
    "--nmea-rate",
    type=float,
    default=None,
    help="NMEA output rate (Hz); default: the highest standard rate that fits --nmea-baud.",
)
@click.option(
    "--nmea-baud",
    type=int,
    default=default_of(run_heave, "nmea_baud"),
    show_default=True,
    help="Line speed the NMEA output must fit (8N1).",
)
@click.option(
    "--heave-positive",
    type=click.Choice(["up", "down"]),
    default=default_of(run_heave, "heave_positive"),
    show_default=True,
    help="Sign of heave in every output (CSV columns and NMEA): up (imutool, TSS1, Applanix) or down "
    "(SBG, Kongsberg native). Written into each output's header.",
)
@input_options
@output_options
@safe_outputs(*OUTPUTS)
def heave_cmd(as_json: bool, quiet: bool, **options: Any) -> None:
    """Heave (m, positive UP), heave rate, dominant period, settled flag and a delayed zero-phase heave."""
    res = heave_route(quiet=quiet, on_input=note_input, **options)
    for w in res.summary.get("warnings") or []:  # the inputs' own warnings were said as they were read
        click.echo(f"warning: {w}", err=True)
    emit_summary(res.summary, as_json, quiet)


heave_cmd = route_of(heave_route, OUTPUTS)(heave_cmd)
