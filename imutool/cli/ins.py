"""`imutool ins IN -o track.csv`: strapdown INS + error-state EKF with zero-velocity (and height) updates."""

from __future__ import annotations

import click
import numpy as np

from formats.errors import ImutoolError
from imutool.cli.common import emit_summary, input_options, load_input, output_options, require_channels, safe_outputs


@click.command("ins", epilog="Example: imutool ins walk.csv -o track.csv --zupt --height-update --plot track.png")
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True))
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(dir_okay=False),
    help="Track: pos_n/e/d (m), vel_n/e/d (m/s) NED from the start, roll/pitch/heading (deg), *_std, zvi.",
)
@click.option("--zupt/--no-zupt", default=True, show_default=True, help="Zero-velocity update at ZVI samples.")
@click.option(
    "--height-update/--no-height-update",
    default=False,
    show_default=True,
    help="Height update (flat floor: the foot is at the start height in every stance).",
)
@click.option(
    "--zaru/--no-zaru",
    default=False,
    show_default=True,
    help="Zero angular-rate update at ZVI samples (gyro bias; hurts when stances include foot roll).",
)
@click.option(
    "--detector",
    type=click.Choice(["paper", "shoe", "are", "mv", "mag"]),
    default="shoe",
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
    default="3",
    show_default=True,
    help="Quaternion Taylor integration order (paper eq. 17 / 18).",
)
@click.option(
    "--gyro-noise",
    type=float,
    default=0.3,
    show_default=True,
    help="Gyro white-noise density of the process model, deg/s/√Hz.",
)
@click.option(
    "--accel-noise",
    type=float,
    default=0.3,
    show_default=True,
    help="Accelerometer white-noise density of the process model, m/s²/√Hz.",
)
@click.option("--zupt-sigma", type=float, default=0.01, show_default=True, help="ZUPT measurement std, m/s.")
@click.option("--height-sigma", type=float, default=0.01, show_default=True, help="Height update std, m.")
@click.option("--zaru-sigma", type=float, default=1.0, show_default=True, help="ZARU measurement std, deg/s.")
@click.option(
    "--bias-states/--no-bias-states",
    default=True,
    show_default=True,
    help="Estimate accelerometer and gyro biases (15-state filter) or not (9 states, as the paper).",
)
@click.option(
    "--heading",
    "heading_deg",
    type=float,
    default=0.0,
    show_default=True,
    help="Initial heading, deg clockwise from north (the track's orientation).",
)
@click.option(
    "--align-window",
    type=float,
    default=4.0,
    show_default=True,
    help="Alignment uses the last this-many s of the first rest interval...",
)
@click.option(
    "--align-guard", type=float, default=1.0, show_default=True, help="...ending this-many s before the interval's end."
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
@safe_outputs("output", "plot_path", "strides_path")
def ins_cmd(
    input_path: str,
    output: str,
    zupt: bool,
    height_update: bool,
    zaru: bool,
    detector: str,
    gamma: float | None,
    zvi_column: str | None,
    order: str,
    gyro_noise: float,
    accel_noise: float,
    zupt_sigma: float,
    height_sigma: float,
    zaru_sigma: float,
    bias_states: bool,
    heading_deg: float,
    align_window: float,
    align_guard: float,
    plot_path: str | None,
    strides_path: str | None,
    as_json: bool,
    quiet: bool,
    **input_kw,
) -> None:
    """Dead-reckon INPUT (gyro + accel, e.g. a foot-mounted IMU) into a position track with sigmas."""
    import formats
    from imutool.ins import InsConfig, evaluate_position, ins, plot_track, strides
    from imutool.progress import stages

    steps = stages("ins", ["reading", "INS", "writing"], quiet)
    steps.stage("reading")
    rec, report = load_input(input_path, **input_kw)
    require_channels(rec, ["gyro", "accel"], input_path)
    for name, v in (
        ("--gyro-noise", gyro_noise),
        ("--accel-noise", accel_noise),
        ("--zupt-sigma", zupt_sigma),
        ("--height-sigma", height_sigma),
        ("--zaru-sigma", zaru_sigma),
    ):
        if not np.isfinite(v) or v <= 0:
            raise ImutoolError(f"{name} must be > 0; got {v}")
    cfg = InsConfig(
        gyro_noise=float(np.radians(gyro_noise)),
        accel_noise=accel_noise,
        zupt_sigma=zupt_sigma,
        height_sigma=height_sigma,
        zaru=zaru,
        zaru_sigma=float(np.radians(zaru_sigma)),
        order=int(order),
        zupt=zupt,
        height_update=height_update,
        accel_bias_states=bias_states,
        gyro_bias_states=bias_states,
        heading_deg=heading_deg,
        align_window_s=align_window,
        align_guard_s=align_guard,
    )
    flags = None
    if zvi_column:
        if zvi_column not in rec.channels:
            raise ImutoolError(f"ZVI column {zvi_column!r} not found", path=input_path)
        flags = rec[zvi_column] > 0.5
    params = {"gamma": gamma} if gamma is not None and detector != "paper" else {}
    if gamma is not None and detector == "paper":
        raise ImutoolError("--gamma does not apply to the paper detector (use `imutool zvi` to tune B_g, B_a)")
    steps.stage("INS + zero-velocity updates")
    try:
        out, res = ins(rec, zvi=flags, detector=detector, detector_params=params, config=cfg)
    except ImutoolError as e:
        raise ImutoolError(str(e), path=input_path) from None
    out.meta["source"] = input_path
    out.meta["ins_config"] = (
        f"zupt={zupt} height_update={height_update} zaru={zaru} detector="
        f"{zvi_column or detector} order={order} gyro_noise={gyro_noise}deg/s/rtHz "
        f"accel_noise={accel_noise}m/s2/rtHz zupt_sigma={zupt_sigma}m/s"
    )
    steps.stage("writing")
    formats.write(out, output)
    loop = evaluate_position(out)
    st = strides(out.time, out["pos"], out["zvi"])
    ok = np.flatnonzero(np.all(np.isfinite(out["pos"]), axis=1))
    summary: dict = {
        "input": input_path,
        "output": output,
        "samples": len(out),
        "duration_s": round(out.duration, 3),
        "aligned_from_s": round(res.info["alignment_start_s"], 3),
        "gravity_m_s2": round(res.gravity, 4),
        "distance_m": round(loop["distance_m"], 3),
        "final_position_ned_m": np.round(out["pos"][ok[-1]], 3).tolist() if len(ok) else None,
        "closed_loop_error_m": round(loop["final_error_m"], 4),
        "closed_loop_error_percent": (
            round(loop["final_error_percent_of_distance"], 3)
            if loop["final_error_percent_of_distance"] is not None
            else None
        ),
        "strides": {
            "count": st["count"],
            "mean_length_m": st["mean_length_m"] and round(st["mean_length_m"], 3),
            "mean_duration_s": st["mean_duration_s"] and round(st["mean_duration_s"], 3),
        },
        "final_sigma_pos_m": np.round(np.sqrt(np.maximum(res.p_diag[-1, 3:6], 0)), 4).tolist(),
        "final_sigma_heading_deg": round(float(np.degrees(np.sqrt(max(res.heading_var[-1], 0)))), 3),
    }
    if "ref_pos" in rec.channels:
        ev = evaluate_position(out, rec)
        summary["vs_reference"] = {
            k: (round(v, 4) if isinstance(v, float) else v)
            for k, v in ev.items()
            if k in ("final_error_m", "rmse_m", "rmse_sum_axes_m", "distance_error_percent")
        }
    if strides_path:
        from formats.atomic import atomic_path

        with atomic_path(strides_path) as tmp:
            lines = ["start_s,end_s,length_m,height_change_m,swing_s,duration_s"]
            lines += [
                f"{r['start_s']:.4f},{r['end_s']:.4f},{r['length_m']:.4f},{r['height_change_m']:.4f},"
                f"{r['swing_s']:.4f},{r['duration_s']:.4f}"
                for r in st["table"]
            ]
            tmp.write_text("\n".join(lines) + "\n")
        summary["strides_file"] = strides_path
    if plot_path:
        ref = None
        if "ref_pos" in rec.channels:
            ref = rec.get("ref_pos")
        title = (
            f"{input_path.rsplit('/', 1)[-1]}: {loop['distance_m']:.1f} m walked, "
            f"closed-loop error {1000 * loop['final_error_m']:.0f} mm"
        )
        plot_track(out, plot_path, title=title, ref=ref)
        summary["plot"] = plot_path
    if report.get("actions"):
        summary["input_fixes"] = report["actions"]
    steps.close()
    emit_summary(summary, as_json, quiet)
