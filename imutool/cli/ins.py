"""`imutool ins IN -o track.csv`: strapdown INS + error-state EKF with zero-velocity (and height) updates.

Only option parsing and printing here; the work is :func:`imutool.routes.ins.run_ins_track`, the route
`imutool batch ins` and a Python user take (defaults live there).
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
from imutool.routes.ins import run_ins_track
from imutool.zvi import DETECTORS

OUTPUTS = ("output", "plot_path", "strides_path")


def ins_route(
    input_path: str,
    output: str,
    order: str,
    gyro_noise: float,
    zaru_sigma: float,
    align_window: float,
    align_guard: float,
    quiet: bool = True,
    on_input: OnInput | None = None,
    **options: Any,
) -> Any:
    """Parsed options → :func:`imutool.routes.ins.run_ins_track` (progress stages on stderr unless ``quiet``)."""
    with stages("ins", ["reading", "INS", "writing"], quiet) as steps:
        return run_ins_track(
            input_path,
            output,
            order=int(order),
            gyro_noise_deg=gyro_noise,
            zaru_sigma_deg=zaru_sigma,
            align_window_s=align_window,
            align_guard_s=align_guard,
            strict=strict_requested(),
            on_input=on_input,
            stage=steps.stage,
            **options,
        )


@click.command("ins", epilog="Example: imutool ins walk.csv -o track.csv --zupt --height-update --plot track.png")
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True))
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(dir_okay=False),
    help="Track: pos_n/e/d (m), vel_n/e/d (m/s) NED from the start, roll/pitch/heading (deg), *_std, zvi.",
)
@click.option(
    "--zupt/--no-zupt",
    default=default_of(run_ins_track, "zupt"),
    show_default=True,
    help="Zero-velocity update at ZVI samples.",
)
@click.option(
    "--height-update/--no-height-update",
    default=default_of(run_ins_track, "height_update"),
    show_default=True,
    help="Height update (flat floor: the foot is at the start height in every stance).",
)
@click.option(
    "--zaru/--no-zaru",
    default=default_of(run_ins_track, "zaru"),
    show_default=True,
    help="Zero angular-rate update at ZVI samples (gyro bias; hurts when stances include foot roll).",
)
@click.option(
    "--loop/--no-loop",
    default=None,
    help="The walk ends where it started: report the end's distance from the start as the closed-loop error "
    "[default: decided from the track: end within max(5 m, 5 % of the path) and 25 % of it].",
)
@click.option(
    "--detector",
    type=click.Choice(DETECTORS),
    default=default_of(run_ins_track, "detector"),
    show_default=True,
    help="ZVI detector (see `imutool zvi --help`).",
)
@click.option("--gamma", type=float, default=None, help="ZVI threshold γ of the Skog detectors [shoe 1e5].")
@click.option(
    "--zvi-column",
    default=None,
    metavar="COLUMN",
    help="Use these 0/1 flags as ZVIs instead of detecting (e.g. zvi or ref_zvi).",
)
@click.option(
    "--order",
    type=click.Choice(["2", "3"]),
    default=str(default_of(run_ins_track, "order")),
    show_default=True,
    help="Quaternion Taylor integration order (paper eq. 17 / 18).",
)
@click.option(
    "--gyro-noise",
    type=float,
    default=default_of(run_ins_track, "gyro_noise_deg"),
    show_default=True,
    help="Gyro white-noise density of the process model, deg/s/√Hz.",
)
@click.option(
    "--accel-noise",
    type=float,
    default=default_of(run_ins_track, "accel_noise"),
    show_default=True,
    help="Accelerometer white-noise density of the process model, m/s²/√Hz.",
)
@click.option(
    "--zupt-sigma",
    type=float,
    default=default_of(run_ins_track, "zupt_sigma"),
    show_default=True,
    help="ZUPT measurement std, m/s.",
)
@click.option(
    "--height-sigma",
    type=float,
    default=default_of(run_ins_track, "height_sigma"),
    show_default=True,
    help="Height update std, m.",
)
@click.option(
    "--zaru-sigma",
    type=float,
    default=default_of(run_ins_track, "zaru_sigma_deg"),
    show_default=True,
    help="ZARU measurement std, deg/s.",
)
@click.option(
    "--bias-states/--no-bias-states",
    default=default_of(run_ins_track, "bias_states"),
    show_default=True,
    help="Estimate accelerometer and gyro biases (15-state filter) or not (9 states, as the paper).",
)
@click.option(
    "--heading",
    "heading_deg",
    type=float,
    default=default_of(run_ins_track, "heading_deg"),
    show_default=True,
    help="Initial heading, deg clockwise from north (the track's orientation).",
)
@click.option(
    "--align-window",
    type=float,
    default=default_of(run_ins_track, "align_window_s"),
    show_default=True,
    help="Alignment uses the last this-many s of the first rest interval...",
)
@click.option(
    "--align-guard",
    type=float,
    default=default_of(run_ins_track, "align_guard_s"),
    show_default=True,
    help="...ending this-many s before the interval's end.",
)
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="Top view of the track + height (.png/.pdf).",
)
@click.option(
    "--strides",
    "strides_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="Write the stride table (start_s,end_s,length_m,height_change_m,swing_s,duration_s) as CSV.",
)
@input_options
@output_options
@safe_outputs(*OUTPUTS)
def ins_cmd(as_json: bool, quiet: bool, **options: Any) -> None:
    """Dead-reckon INPUT (gyro + accel, e.g. a foot-mounted IMU) into a position track with sigmas."""
    res = ins_route(quiet=quiet, on_input=note_input, **options)
    emit_summary(res.summary, as_json, quiet)


ins_cmd = route_of(ins_route, OUTPUTS)(ins_cmd)
