"""``imutool calibrate``: magnetometer (sphere or heading swing), deviation card, gyro, accelerometer, show.

Options and printing only; the runs (loading, fit, provenance, writing the calibration file, plots and cards) are
:mod:`imutool.calibrate`, the same routes `imutool batch 'calibrate mag'` (gyro, accel, deviation, show) and a Python
user take; the defaults live there.
"""

from __future__ import annotations

from typing import Any

import click
import numpy as np

from imutool.calibrate import (
    REF_NAMES,
    CalibrationRun,
    calibrate_accel,
    calibrate_accel_bias,
    calibrate_gyro,
    calibrate_mag,
    deviation_card,
    rest_options,
    show_calibration,
)
from imutool.cli.common import (
    default_of,
    emit_summary,
    input_options,
    note_input,
    output_options,
    reference_options,
    route_of,
    safe_outputs,
    strict_requested,
)
from imutool.routes import OnInput, RouteResult


@click.group("calibrate", epilog="Example: imutool calibrate mag sphere.csv -o cal.toml --plot cal.png")
def calibrate_group() -> None:
    """Calibrate magnetometer (sphere or ship swing), deviation card, gyro and accelerometer.

    Results go into one TOML calibration file (sections mag, gyro, accel, deviation, mounting, each with
    provenance). Every command that reads sensor data applies it with --calibration cal.toml.
    Magnetometer model: m_true = A (m_meas − b), b hard iron (µT), A soft iron (symmetric).
    """


MAG_OUTPUTS = ("output", "plot")


# -- mag -------------------------------------------------------------------------------------------------------
@calibrate_group.command(
    "mag",
    epilog="Example: imutool calibrate mag sphere.csv -o cal.toml --plot cal.png   |   "
    "imutool calibrate mag swing.csv -o cal.toml --method swing",
)
@click.argument("input_path", metavar="INPUT")
@click.option("-o", "--output", required=True, help="Calibration file (.toml).")
@click.option(
    "--method",
    type=click.Choice(["sphere", "swing"]),
    default=default_of(calibrate_mag, "method"),
    show_default=True,
    help="sphere: full 3-D rotations (bench); swing: the vessel turns in heading only (2-D fit).",
)
@click.option(
    "--kind",
    type=click.Choice(["auto", "offset", "diag", "full"]),
    default=default_of(calibrate_mag, "kind"),
    show_default=True,
    help="Sphere fit: offset = hard iron only; diag = + axis scale; full = + symmetric soft iron; auto "
    "= simplest within 5% of the best residual.",
)
@click.option(
    "--field",
    "field_ut",
    type=float,
    default=None,
    help="Expected field strength (µT) to scale A; default: det A = 1 (volume preserving).",
)
@click.option(
    "--min-coverage",
    type=float,
    default=None,
    help="Refuse below this sphere coverage (0–1); default offset 0.25, diag 0.45, full 0.60.",
)
@click.option(
    "--grid-bands",
    type=int,
    default=default_of(calibrate_mag, "grid_bands"),
    show_default=True,
    help="Equal-area coverage grid: bands in z (× twice as many longitude sectors).",
)
@click.option(
    "--horizontal-field",
    type=float,
    default=None,
    help="Swing: horizontal field (µT) to scale A; default det A_xy = 1.",
)
@click.option(
    "--bz-prior",
    type=float,
    default=default_of(calibrate_mag, "bz_prior"),
    show_default=True,
    help="Swing: vertical hard iron (µT), unobservable in a swing.",
)
@click.option("--a33-prior", type=float, default=None, help="Swing: vertical soft-iron scale; default √det A_xy.")
@click.option("--plot", default=None, help="Before/after plot (.png/.pdf).")
@click.option("--append", is_flag=True, help="Merge into an existing calibration file (else a new file).")
@click.option("--sensor", default=None, help="Sensor id for the provenance (default: from the input metadata).")
@input_options
@output_options
@safe_outputs(*MAG_OUTPUTS, append="append")
def mag_cmd(as_json: bool, quiet: bool, **options: Any) -> None:
    """Hard/soft-iron calibration of the magnetometer in INPUT."""
    run = mag_route(quiet=quiet, on_input=note_input, **options)
    fit, summary, method = run.fit, run.summary, options["method"]
    lines = [
        f"mag calibration ({method}, kind {fit.kind}) → {options['output']}",
        f"  {fit.reason}",
        "  model  m_true = A (m_meas − b)",
        f"  b (µT) = {np.array2string(fit.b, precision=3)} ± {np.array2string(fit.b_std, precision=3)}",
        "  A      = " + np.array2string(fit.A, precision=5).replace("\n", "\n           "),
        f"  field {fit.field_ut:.2f} µT, residual {fit.residual_rms_ut:.3g} µT RMS, coverage {100 * fit.coverage:.0f}%",
        f"  {'|m|' if method == 'sphere' else 'horizontal |m_h|'} relative std: raw {100 * fit.raw_rel_std:.2f}%"
        f" → calibrated {100 * fit.cal_rel_std:.2f}%",
    ]
    if method == "swing":
        lines.append(f"  not observable in a swing: {summary['unobservable']}")
    lines += [f"  absent: {a}" for a in summary.get("information_absent") or []]
    lines += [f"  warning: {w}" for w in fit.warnings]
    emit_summary(summary, as_json, quiet, lines)


def mag_route(
    input_path: str, output: str, quiet: bool = True, on_input: OnInput | None = None, **options: Any
) -> CalibrationRun:
    """Parsed options → :func:`imutool.calibrate.calibrate_mag` (progress on stderr unless ``quiet``)."""
    with _steps(quiet) as steps:
        return calibrate_mag(
            input_path, output, strict=strict_requested(), on_input=on_input, stage=steps.stage, **options
        )


mag_cmd = route_of(mag_route, MAG_OUTPUTS, append="append")(mag_cmd)


# -- deviation -------------------------------------------------------------------------------------------------
@calibrate_group.command(
    "deviation",
    epilog="Example: imutool calibrate deviation swing.csv --reference gnss.nmea "
    "-o card.pdf -o card.txt -o cal.toml --vessel 'MV Aurora'",
)
@click.argument("input_path", metavar="INPUT")
@click.option(
    "-o",
    "--output",
    "outputs",
    multiple=True,
    required=True,
    help="Card (.pdf/.png/.svg plot + text; .txt text card) and/or calibration file (.toml, section "
    "[deviation]). Repeatable.",
)
@click.option(
    "--reference",
    default=None,
    type=click.Path(exists=True),
    help="Reference headings: NMEA log (HDT/THS/HDM...), CSV (heading, cog or bearing column). "
    "Default: a reference column of INPUT (ref_heading).",
)
@click.option(
    "--reference-column",
    default=None,
    help=f"Column with the reference heading (deg); default the first of {', '.join(REF_NAMES)}.",
)
@click.option(
    "--reference-kind",
    type=click.Choice(["auto", "true", "magnetic"]),
    default=default_of(deviation_card, "reference_kind"),
    show_default=True,
    help="Whether the reference is true or magnetic heading (auto: magnetic for "
    "heading_mag / ref_heading_mag, else true).",
)
@click.option(
    "--variation",
    type=float,
    default=None,
    help="Magnetic variation (declination), deg, east positive: magnetic = true − variation. A true "
    "reference without it is refused unless --position (or a position in the reference log) and "
    "a date give it from the World Magnetic Model (needs imutool[wmm]).",
)
@click.option(
    "--position",
    default=None,
    metavar="LAT,LON",
    help="Where the swing was done (decimal deg, N/E +): latitude for the card, and the WMM variation "
    "when --variation is not given. Default: first RMC/GGA fix of the reference log.",
)
@click.option(
    "--date",
    "date_opt",
    default=None,
    metavar="YYYY-MM-DD",
    help="Date of the swing (card header, WMM). Default: the recording's real start time.",
)
@click.option("--vessel", default=None, help="Card header: vessel name.")
@click.option("--compass", "compass_name", default=None, help="Card header: compass (make, model, serial).")
@click.option("--place", default=None, help="Card header: place of the swing.")
@click.option("--conditions", default=None, help="Card header: swing conditions (loading, trim, heel, weather...).")
@click.option(
    "--adjuster", default=None, help="Card header: compass adjuster's name (the card keeps a signature line)."
)
@click.option(
    "--card-info",
    default=None,
    type=click.Path(exists=True, dir_okay=False),
    help="TOML with the header fields (vessel, compass, place, date, latitude, longitude, conditions, "
    "adjuster); options override it.",
)
@click.option(
    "--max-deviation",
    type=float,
    default=default_of(deviation_card, "max_deviation"),
    show_default=True,
    help="Warn above this |deviation| (deg): compass to be adjusted (ISO 25862 as quoted: 5° in service).",
)
@click.option(
    "--time-offset",
    type=float,
    default=default_of(deviation_card, "time_offset"),
    show_default=True,
    help="Seconds added to the reference times to align them with INPUT.",
)
@click.option(
    "--heading-column",
    default=None,
    help="Compass heading column of INPUT (deg); default: 'heading' if present, else from mag (+ accel "
    "tilt compensation, after --calibration).",
)
@click.option(
    "--min-speed",
    type=float,
    default=default_of(deviation_card, "min_speed"),
    show_default=True,
    help="With a GNSS course-over-ground reference and a 'sog' column (kn): use rows at or above this.",
)
@click.option(
    "--min-span",
    type=float,
    default=default_of(deviation_card, "min_span"),
    show_default=True,
    help="Refuse if the compass headings cover less of the circle (deg). Whatever it says, headings "
    "that cannot separate the A–E harmonics are refused.",
)
@click.option(
    "--append/--new",
    default=default_of(deviation_card, "append"),
    show_default=True,
    help="Merge [deviation] into an existing .toml (or write a new one).",
)
@click.option("--sensor", default=None, help="Sensor id for the provenance.")
@input_options
@reference_options
@output_options
@safe_outputs("outputs", append="append")
def deviation_cmd(as_json: bool, quiet: bool, **options: Any) -> None:
    """Deviation card δ(ψ) = A + B sinψ + C cosψ + D sin2ψ + E cos2ψ from compass vs reference headings.

    The card: header (vessel, compass, place, date, latitude, variation, reference, conditions), coefficients
    and both tables at 15° (compass → magnetic; magnetic → compass, the course to steer) in E/W notation,
    residuals per heading, warnings, adjuster's signature line.
    """
    from calibration.deviation import ew

    run = deviation_route(quiet=quiet, on_input=note_input, **options)
    card, summary, d = run.fit, run.summary, run.details
    src, rsrc, rname, kind = d["compass_source"], d["reference_source"], d["reference_column"], d["reference_kind"]
    variation, var_src = d["variation"], d["variation_source"]
    lines = [
        f"deviation card ({card.quality['n']} samples; compass from {src}; reference {rsrc}:{rname}, {kind})",
        "  δ(ψ) = A + B sinψ + C cosψ + D sin2ψ + E cos2ψ   (magnetic = compass + δ; E add, W subtract)",
        "  " + "  ".join(f"{n} = {ew(getattr(card, n), 2)} ± {card.std.get(n, float('nan')):.2f}°" for n in "ABCDE"),
    ]
    if kind == "true":
        lines.append(f"  variation {ew(variation, 2)} ({var_src})")
    lines += [
        f"  residual {card.quality['residual_rms_deg']:.3f}° RMS, max {card.quality['residual_max_deg']:.2f}°; "
        f"largest deviation {card.max_abs_deg():.1f}°",
        "  compass → deviation:",
    ]
    tab = card.table(15.0)
    for i in range(0, len(tab), 6):
        lines.append("   " + "  ".join(f"{p:03.0f}° {ew(d):>7s}" for p, d, _ in tab[i : i + 6]))
    if card.invertible():
        lines.append("  magnetic → compass (course to steer):")
        tm = card.table_magnetic(15.0)
        for i in range(0, len(tm), 6):
            lines.append("   " + "  ".join(f"{m:03.0f}°→{p:05.1f}°" for m, _, p in tm[i : i + 6]))
    lines.append(f"  written: {', '.join(options['outputs'])}")
    for w in card.warnings:
        click.echo(f"warning: {w}", err=True)
    emit_summary(summary, as_json, quiet, lines)


def deviation_route(
    input_path: str,
    outputs: tuple[str, ...],
    date_opt: str | None = None,
    compass_name: str | None = None,
    card_info: str | None = None,
    quiet: bool = True,
    on_input: OnInput | None = None,
    **options: Any,
) -> CalibrationRun:
    """Parsed options → :func:`imutool.calibrate.deviation_card` (progress on stderr unless ``quiet``)."""
    with _steps(quiet) as steps:
        return deviation_card(
            input_path,
            outputs,
            date=date_opt,
            compass=compass_name,
            info=card_info,
            strict=strict_requested(),
            on_input=on_input,
            stage=steps.stage,
            **options,
        )


deviation_cmd = route_of(deviation_route, ("outputs",), append="append")(deviation_cmd)


def _steps(quiet: bool):
    """Progress on stderr (interactive only): reading, fitting (+ writing)."""
    from imutool.progress import stages

    return stages("calibrate", ["reading", "fitting"], quiet)


# -- gyro ------------------------------------------------------------------------------------------------------
def _rest_options(f):
    opts = [
        click.option(
            "--window",
            "window_s",
            type=float,
            default=default_of(rest_options, "window_s"),
            show_default=True,
            help="Rest detection: moving-std window (s).",
        ),
        click.option(
            "--gyro-std",
            "gyro_std_deg",
            type=float,
            default=default_of(rest_options, "gyro_std_deg"),
            show_default=True,
            help="Rest detection: gyro moving std below this (deg/s).",
        ),
        click.option(
            "--accel-std",
            type=float,
            default=default_of(rest_options, "accel_std"),
            show_default=True,
            help="Rest detection: accel moving std below this (m/s²).",
        ),
        click.option(
            "--min-rest",
            "min_rest_s",
            type=float,
            default=default_of(rest_options, "min_rest_s"),
            show_default=True,
            help="Rest detection: shortest rest interval kept (s).",
        ),
    ]
    for o in reversed(opts):
        f = o(f)
    return f


@calibrate_group.command("gyro", epilog="Example: imutool calibrate gyro static.csv -o cal.toml --append")
@click.argument("input_path", metavar="INPUT")
@click.option("-o", "--output", required=True, help="Calibration file (.toml).")
@click.option(
    "--turns-deg",
    type=float,
    default=None,
    help="Each motion between rests is a turn of this many degrees about one axis: fit scale and "
    "misalignment (needs turns about all three axes).",
)
@click.option(
    "--min-temp-range",
    type=float,
    default=default_of(calibrate_gyro, "min_temp_range"),
    show_default=True,
    help="Fit a temperature slope only if the rest samples span this many °C.",
)
@_rest_options
@click.option("--append", is_flag=True, help="Merge into an existing calibration file (else a new file).")
@click.option("--sensor", default=None, help="Sensor id for the provenance.")
@input_options
@output_options
@safe_outputs("output", append="append")
def gyro_cmd(as_json: bool, quiet: bool, **options: Any) -> None:
    """Gyro bias over automatically detected rest intervals (+ temperature slope, + scale from known turns)."""
    run = gyro_route(quiet=quiet, on_input=note_input, **options)
    cal, summary = run.fit, run.summary
    lines = [
        f"gyro calibration → {options['output']}",
        f"  rest: {cal.n_rest} intervals, {cal.rest_s:.1f} s",
        f"  bias (deg/s) = {np.array2string(np.degrees(cal.bias), precision=4)}",
    ]
    if cal.temp_slope is not None:
        lines.append(
            f"  temperature slope (deg/s/°C) = {np.array2string(np.degrees(cal.temp_slope), precision=5)}"
            f" about {cal.temp_ref:.2f} °C"
        )
    elif "temp_note" in cal.quality:
        lines.append(f"  {cal.quality['temp_note']}")
    if cal.scale is not None:
        lines.append("  S = " + np.array2string(cal.scale, precision=5).replace("\n", "\n      "))
    emit_summary(summary, as_json, quiet, lines)


def gyro_route(
    input_path: str,
    output: str,
    window_s: float,
    gyro_std_deg: float,
    accel_std: float,
    min_rest_s: float,
    quiet: bool = True,
    on_input: OnInput | None = None,
    **options: Any,
) -> CalibrationRun:
    """Parsed options → :func:`imutool.calibrate.calibrate_gyro` (progress on stderr unless ``quiet``)."""
    with _steps(quiet) as steps:
        return calibrate_gyro(
            input_path,
            output,
            rest=rest_options(window_s, gyro_std_deg, accel_std, min_rest_s),
            strict=strict_requested(),
            on_input=on_input,
            stage=steps.stage,
            **options,
        )


gyro_cmd = route_of(gyro_route, ("output",), append="append")(gyro_cmd)


# -- accel -----------------------------------------------------------------------------------------------------
@calibrate_group.command(
    "accel", epilog="Example: imutool calibrate accel sixpos.csv -o cal.toml --append --latitude 59.4"
)
@click.argument("input_path", metavar="INPUT")
@click.option("-o", "--output", required=True, help="Calibration file (.toml).")
@click.option(
    "--kind",
    type=click.Choice(["auto", "offset", "diag", "full"]),
    default=default_of(calibrate_accel, "kind"),
    show_default=True,
    help="offset: bias; diag: + scale; full: + misalignment (≥ 9 poses); auto by pose count.",
)
@click.option("--gravity", type=float, default=None, help="Local gravity (m/s²); default from --latitude.")
@click.option(
    "--latitude",
    type=float,
    default=None,
    help="Latitude (deg) for WGS-84 normal gravity; default: standard gravity 9.80665.",
)
@click.option(
    "--height",
    type=float,
    default=default_of(calibrate_accel, "height"),
    show_default=True,
    help="Height (m) for the gravity formula.",
)
@click.option(
    "--min-poses",
    type=int,
    default=default_of(calibrate_accel, "min_poses"),
    show_default=True,
    help="Fewest distinct static poses accepted.",
)
@_rest_options
@click.option("--append", is_flag=True, help="Merge into an existing calibration file (else a new file).")
@click.option("--sensor", default=None, help="Sensor id for the provenance.")
@input_options
@output_options
@safe_outputs("output", append="append")
def accel_cmd(as_json: bool, quiet: bool, **options: Any) -> None:
    """Accelerometer bias, scale and misalignment from six or more static poses (detected automatically)."""
    run = accel_route(quiet=quiet, on_input=note_input, **options)
    cal, summary = run.fit, run.summary
    gravity = summary["gravity_m_s2"]
    lines = [
        f"accel calibration ({cal.kind}, {cal.quality['poses']} poses, g = {gravity:.5f} m/s²) → {options['output']}",
        "  model f = T (f_meas − b)",
        f"  b (m/s²) = {np.array2string(cal.bias, precision=4)} ± {np.array2string(cal.bias_std, precision=4)}",
        "  T = " + np.array2string(cal.T, precision=5).replace("\n", "\n      "),
        f"  residual {cal.residual_rms:.4g} m/s² RMS over the poses",
    ]
    if "note" in cal.quality:
        lines.append(f"  note: {cal.quality['note']}")
    emit_summary(summary, as_json, quiet, lines)


def accel_route(
    input_path: str,
    output: str,
    window_s: float,
    gyro_std_deg: float,
    accel_std: float,
    min_rest_s: float,
    quiet: bool = True,
    on_input: OnInput | None = None,
    **options: Any,
) -> CalibrationRun:
    """Parsed options → :func:`imutool.calibrate.calibrate_accel` (progress on stderr unless ``quiet``)."""
    with _steps(quiet) as steps:
        return calibrate_accel(
            input_path,
            output,
            rest=rest_options(window_s, gyro_std_deg, accel_std, min_rest_s),
            strict=strict_requested(),
            on_input=on_input,
            stage=steps.stage,
            **options,
        )


accel_cmd = route_of(accel_route, ("output",), append="append")(accel_cmd)


# -- accel-bias ------------------------------------------------------------------------------------------------
@calibrate_group.command(
    "accel-bias",
    epilog="Example: imutool filter voyage.csv -o est.csv --lever-arm=-12,0,-20 && "
    "imutool calibrate accel-bias est.csv -o cal.toml",
)
@click.argument("input_path", metavar="FILTERED")
@click.option("-o", "--output", required=True, help="Calibration file (.toml).")
@click.option(
    "--at",
    type=float,
    default=None,
    help="Take the estimate at this time (s from the start; default: the last row, which a whole-recording "
    "run smooths over the voyage).",
)
@click.option(
    "--append",
    is_flag=True,
    help="Merge into an existing calibration file (needed when the filter run applied that file's [accel]: the "
    "estimate is then folded into it).",
)
@click.option("--sensor", default=None, help="Sensor id for the provenance.")
@input_options
@output_options
@safe_outputs("output", append="append")
def accel_bias_cmd(as_json: bool, quiet: bool, **options: Any) -> None:
    """The accelerometer bias a GNSS-aided `imutool filter` run estimated (its accel_bias_x/y/z), as [accel]."""
    run = accel_bias_route(quiet=quiet, on_input=note_input, **options)
    s = run.summary
    lines = [
        f"accel bias from {options['input_path']} at {s['row_time_s']} s → {options['output']}",
        "  model f = T (f_meas − b), sensor axes",
        f"  b (m/s²) = {np.array2string(np.array(s['bias_m_s2']), precision=5)} "
        f"± {np.array2string(np.array(s['bias_std_m_s2']), precision=5)}",
    ]
    if "note" in s:
        lines.append(f"  note: {s['note']}")
    emit_summary(s, as_json, quiet, lines)


def accel_bias_route(
    input_path: str, output: str, quiet: bool = True, on_input: OnInput | None = None, **options: Any
) -> CalibrationRun:
    """Parsed options → :func:`imutool.calibrate.calibrate_accel_bias` (progress on stderr unless ``quiet``)."""
    with _steps(quiet) as steps:
        return calibrate_accel_bias(
            input_path, output, strict=strict_requested(), on_input=on_input, stage=steps.stage, **options
        )


accel_bias_cmd = route_of(accel_bias_route, ("output",), append="append")(accel_bias_cmd)


# -- show ------------------------------------------------------------------------------------------------------
@calibrate_group.command("show", epilog="Example: imutool calibrate show cal.toml --as c > cal.h")
@click.argument("path", metavar="CAL.toml", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "--as",
    "form",
    type=click.Choice(["text", "c", "fusion", "matlab", "python", "json", "magneto"]),
    default=default_of(show_calibration, "form"),
    show_default=True,
    help="text: the file and the deviation card; c (= fusion): x-io Fusion C; matlab: magcal A, b, "
    "expmfs; python: numpy; json: every section; magneto: Magneto's printout. Code forms paste and "
    "compile/run as printed.",
)
def show_cmd(path: str, form: str) -> None:
    """Print a calibration file, or paste-ready code: C (x-io Fusion), MATLAB, Python/numpy, JSON, Magneto."""
    click.echo(show_route(path, form).summary["text"], nl=False)


def show_route(path: str, form: str = "text") -> RouteResult:
    """Parsed options → :func:`imutool.calibrate.show_calibration`; the text is the summary's ``text``."""
    return RouteResult({"input": path, "form": form, "text": show_calibration(path, form)})


show_cmd = route_of(show_route, ())(show_cmd)
