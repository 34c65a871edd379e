"""`imutool report inclinometer|heading DUT --reference REF -o evidence.pdf` (+ evidence.json beside it).

Only option parsing and printing here; the work is :mod:`imutool.report.route` (``run_inclinometer_report``,
``run_heading_report``), the routes `imutool batch report ...` and a Python user take (defaults live in
:class:`~imutool.report.inclinometer.InclinometerOptions` and :class:`~imutool.report.heading.HeadingOptions`).
"""

from __future__ import annotations

import os
import sys
from typing import Any

import click

from formats.atomic import check_outputs
from imutool.cli.common import (
    ClockTime,
    FiniteFloat,
    default_of,
    emit_summary,
    input_options,
    note_input,
    output_options,
    reference_frame_options,
    reference_options,
    route_of,
    safe_outputs,
    strict_requested,
)
from imutool.loading import REF_LOAD_OPTIONS
from imutool.progress import stages
from imutool.report.common import ALIGN, CRITERION, MAX_LAG_S
from imutool.report.heading import HeadingOptions
from imutool.report.inclinometer import InclinometerOptions
from imutool.report.route import run_heading_report, run_inclinometer_report
from imutool.routes import LOAD_OPTIONS, OnInput, RouteResult

INC, HDG = InclinometerOptions, HeadingOptions  # the defaults of every option below
OUTPUTS = ("output", "json_path")
INC_NAMES = {  # option → InclinometerOptions field, where the names differ
    "angle_floor": "angle_floor_deg",
    "period_floor": "period_floor_s",
    "drift_min_s": "long_term_min_s",
    "drift_limit": "drift_limit_deg_per_h",
    "min_cycle_amp": "min_cycle_amp_deg",
    "crest_band": "crest_band_deg",
    "lat_accel_min": "lat_accel_min_ms2",
    "heel_range": "declared_heel_range_deg",
}
HDG_NAMES = {"static_limit": "static_limit_deg"}  # option → HeadingOptions field

EXIT_HELP = (
    "Exit status: 0 = PASS (every required item tested and passed), 1 = FAIL or INCOMPLETE (the PDF and "
    "JSON are written either way), 2 = usage error (bad option, unreadable input, impossible tolerance)."
)
POSITIVE = FiniteFloat(0, None, min_open=True)


@click.group(
    "report",
    epilog="Example: imutool report inclinometer dut.csv --reference table.csv -o evidence.pdf\n\n" + EXIT_HELP,
)
def report_group() -> None:
    """Certification-evidence reports (PDF + JSON): inclinometer (MSC.363(92)), heading device (MSC.116(73))."""


def _paths(output: str, json_path: str | None) -> str | None:
    """The evidence JSON's path: given, or beside the PDF (checked as an output of the command too)."""
    if json_path is None and output.lower().endswith(".pdf"):  # the JSON beside the PDF is an output too
        json_path = os.path.splitext(output)[0] + ".json"
        check_outputs([json_path])
    return json_path


def _print(res: RouteResult, as_json: bool, quiet: bool) -> None:
    """Print the summary and exit with 0 (pass) or 1 (fail / incomplete)."""
    ev, s = (res.data or {})["evidence"], res.summary
    lines = [
        f"{ev['title']}",
        f"  {ev['overall']['headline']}",
        f"  ({s['pages']} pages → {s['pdf']}, {s['json']})",
        f"  time lag DUT vs reference: {ev['alignment']['lag_s']:+.3f} s "
        f"({'removed' if ev['alignment']['applied'] else 'not removed'})",
    ]
    for it in ev["items"]:
        st = it["stats"]
        mx = (
            f"max|e| {st['max_abs']:.3f}  RMS {st['rmse']:.3f}  p95 {st['p95_abs']:.3f}"
            if st.get("max_abs") is not None
            else ""
        )
        derived = f"  (derived by imutool, would be: {it['derived_result']})" if it.get("derived_result") else ""
        lines.append(f"  {it['id']:20s} {it['status']:17s} N={st.get('n', 0):<6} {mx}{derived}")
    for name, inp in ev["inputs"].items():
        ld = (inp or {}).get("loading") or {}
        if ld.get("options") or ld.get("merged"):
            from imutool.loading import loading_text

            lines.append(f"  {name} loaded: {loading_text(ld)}")
    for w in ev["warnings"]:
        lines.append(f"  warning: {w}")
    emit_summary(s, as_json, quiet, lines)
    sys.exit(res.exit_status)


def _common_options(f):
    opts = [
        click.option(
            "--reference",
            "-r",
            "ref_path",
            required=True,
            type=click.Path(exists=True),
            help="Reference recording (tilt/motion table, reference inclinometer, gyro compass).",
        ),
        click.option("-o", "--output", required=True, type=click.Path(), help="Evidence PDF (JSON beside it)."),
        click.option(
            "--json-out",
            "json_path",
            default=None,
            type=click.Path(),
            help="Evidence JSON path (default: the PDF name with .json).",
        ),
        click.option("--device", default=None, help="Device identification (make, model, serial, firmware)."),
        click.option(
            "--config", "config_path", default=None, help="DUT configuration file to identify by sha256 in the report."
        ),
        click.option(
            "--criterion",
            type=click.Choice(["max", "p95"]),
            default=CRITERION,
            show_default=True,
            help="max: every sample/cycle within tolerance; p95: 95 % bound (MSC.1/Circ.1575).",
        ),
        click.option(
            "--align",
            type=click.Choice(["none", "xcorr"]),
            default=ALIGN,
            show_default=True,
            help="none: common clock, latency counts as error; xcorr: remove the measured lag.",
        ),
        click.option(
            "--max-lag",
            "max_lag_s",
            type=float,
            default=MAX_LAG_S,
            show_default=True,
            help="Lag search range ± s for the cross-correlation.",
        ),
        click.option(
            "--start",
            "t_start",
            type=ClockTime(),
            default=None,
            help="Evaluate from this time: s on the recordings' clock, or a UTC time (2014-08-01T12:00:00Z) where "
            "they have a date; e.g. after the filter has settled.",
        ),
        click.option("--end", "t_end", type=ClockTime(), default=None, help="Evaluate up to this time (as --start)."),
        click.option(
            "--test-info",
            "test_info_path",
            default=None,
            type=click.Path(exists=True, dir_okay=False),
            help="Test record TOML (test house, site, date, operator, witness, DUT and reference identity, "
            "certificate, U (k=2), environment, set-up, decision rule, report number; example: "
            "sample_data/test_info.toml). Missing fields are printed blank, never invented.",
        ),
    ]
    for o in reversed(opts):
        f = o(f)
    return reference_frame_options(reference_options(f))


@report_group.command(
    "inclinometer",
    epilog="Example: imutool report inclinometer dut.nmea --reference table.csv "
    "--static-steps steps.csv --test-info test.toml -o evidence.pdf\n\n" + EXIT_HELP,
)
@click.argument("dut_path", metavar="DUT", type=click.Path(exists=True))
@_common_options
@click.option(
    "--static-steps",
    "steps_path",
    default=None,
    type=click.Path(exists=True),
    help="CSV 'start,end[,reference]' (s, s, deg) of the static heel steps (default: detected plateaus).",
)
@click.option(
    "--angle-floor",
    type=float,
    default=INC.angle_floor_deg,
    show_default=True,
    help="Angle tolerance floor (deg).",
)
@click.option(
    "--angle-pct", type=float, default=INC.angle_pct, show_default=True, help="Angle tolerance, % of reading."
)
@click.option(
    "--period-floor",
    type=float,
    default=INC.period_floor_s,
    show_default=True,
    help="Period tolerance floor (s).",
)
@click.option(
    "--period-pct", type=float, default=INC.period_pct, show_default=True, help="Period tolerance, % of reading."
)
@click.option(
    "--hysteresis",
    "hysteresis_deg",
    type=float,
    default=INC.hysteresis_deg,
    show_default=True,
    help="Roll-cycle hysteresis (deg).",
)
@click.option(
    "--min-cycles", type=int, default=INC.min_cycles, show_default=True, help="Cycles per side needed to judge."
)
@click.option(
    "--min-steps",
    "min_steps_per_side",
    type=int,
    default=INC.min_steps_per_side,
    show_default=True,
    help="Static steps per side needed to judge.",
)
@click.option(
    "--step-band",
    "step_band_deg",
    type=float,
    default=INC.step_band_deg,
    show_default=True,
    help="Plateau detection: reference range (deg) over 2 s.",
)
@click.option(
    "--step-min",
    "step_min_s",
    type=float,
    default=INC.step_min_s,
    show_default=True,
    help="Plateau detection: minimum duration (s).",
)
@click.option(
    "--drift-min",
    "drift_min_s",
    type=float,
    default=INC.long_term_min_s,
    show_default=True,
    help="Minimum static hold (s) for the long-term test; shorter holds cannot resolve drift and are "
    "refused (insufficient data).",
)
@click.option(
    "--drift-limit",
    "drift_limit",
    type=POSITIVE,
    default=INC.drift_limit_deg_per_h,
    help="Optional drift-rate limit (°/h); the hold must resolve it (95 % half-width ≤ half the limit).",
)
@click.option(
    "--min-cycle-amp",
    "min_cycle_amp",
    type=POSITIVE,
    default=INC.min_cycle_amp_deg,
    show_default=True,
    help="Roll cycles whose reference maximum is smaller (deg) are not judged.",
)
@click.option(
    "--crest-band",
    "crest_band",
    type=POSITIVE,
    default=INC.crest_band_deg,
    show_default=True,
    help="Crest width = time within this (deg) of a maximum; periods whose crests are wider than the "
    "period tolerance are not judged (time of the maximum not resolved).",
)
@click.option(
    "--lat-accel-channel",
    default=INC.lat_accel_channel,
    show_default=True,
    help="Reference channel with the applied lateral acceleration (m/s², + starboard).",
)
@click.option(
    "--lat-accel-min",
    "lat_accel_min",
    type=POSITIVE,
    default=INC.lat_accel_min_ms2,
    show_default=True,
    help="|lateral acceleration| (m/s²) from which samples belong to the acceleration item.",
)
@click.option(
    "--heel-range",
    "heel_range",
    type=POSITIVE,
    default=INC.declared_heel_range_deg,
    help="Declared heel range ± (deg) the static steps must cover (default: test record [dut]).",
)
@click.option(
    "--guard-band",
    is_flag=True,
    default=INC.guard_band,
    help="Decision rule with guard band: acceptance limit = tolerance − U (k = 2) of the reference.",
)
@click.option("--dut-channel", default=None, help="DUT heel channel (default: heel, else roll).")
@click.option("--ref-channel", default=None, help="Reference heel channel (default: heel, else roll; e.g. ref_roll).")
@input_options
@output_options
@safe_outputs(*OUTPUTS)
def inclinometer_cmd(as_json: bool, quiet: bool, **options: Any) -> None:
    """Electronic-inclinometer evidence (IMO MSC.363(92), ISO 19697 clauses) of DUT against --reference.

    DUT: a recording with `roll` (deg, + starboard down; e.g. `imutool filter` output) or an NMEA capture with
    HRM (its own period, amplitude and peak-hold fields are then tested, plus the interface). Amplitude, period
    and peak hold pass only on values the device reported (HRM); values imutool derives from a CSV heel are
    shown but leave those items not tested, so the result is then INCOMPLETE (exit status 1).
    """
    _print(inclinometer_route(quiet=quiet, on_input=note_input, **options), as_json, quiet)


def inclinometer_route(
    dut_path: str,
    ref_path: str,
    output: str,
    json_path: str | None,
    steps_path: str | None,
    dut_channel: str | None,
    ref_channel: str | None,
    device: str | None,
    config_path: str | None,
    test_info_path: str | None,
    t_start: float | str | None,
    t_end: float | str | None,
    ref_frame: str | None = None,
    ref_mounting: str | None = None,
    quiet: bool = True,
    on_input: OnInput | None = None,
    **options: Any,
) -> RouteResult:
    """Parsed options → :func:`imutool.report.route.run_inclinometer_report`."""
    json_path = _paths(output, json_path)
    load = {k: options.pop(k) for k in (*LOAD_OPTIONS, *REF_LOAD_OPTIONS)}
    with stages("report", ["reading", "evaluating", "writing"], quiet) as steps:
        return run_inclinometer_report(
            dut_path,
            ref_path,
            output,
            json_path=json_path,
            options=InclinometerOptions(**{INC_NAMES.get(k, k): v for k, v in options.items()}),
            steps_path=steps_path,
            dut_channel=dut_channel,
            ref_channel=ref_channel,
            device=device,
            config=config_path,
            test_info=test_info_path,
            t_start=t_start,
            t_end=t_end,
            ref_frame=ref_frame,
            ref_mounting=ref_mounting,
            strict=strict_requested(),
            on_input=on_input,
            stage=steps.stage,
            **load,
        )


inclinometer_cmd = route_of(inclinometer_route, OUTPUTS)(inclinometer_cmd)


@report_group.command(
    "heading", epilog="Example: imutool report heading dmc.nmea --reference gyro.nmea -o heading.pdf\n\n" + EXIT_HELP
)
@click.argument("dut_path", metavar="DUT", type=click.Path(exists=True))
@_common_options
@click.option("--dut-channel", default=None, help="DUT heading channel (default: heading, heading_true, heading_mag).")
@click.option("--ref-channel", default=None, help="Reference heading channel (same default).")
@click.option(
    "--correction",
    "correction_deg",
    type=float,
    default=default_of(run_heading_report, "correction_deg"),
    show_default=True,
    help="Added to the DUT heading first (deg; e.g. magnetic variation, E +).",
)
@click.option(
    "--static-limit",
    type=float,
    default=HDG.static_limit_deg,
    show_default=True,
    help="Static error limit (deg).",
)
@click.option(
    "--min-headings", type=int, default=HDG.min_headings, show_default=True, help="Equidistant headings needed."
)
@click.option(
    "--turn-min",
    "turn_min_dps",
    type=float,
    default=HDG.turn_min_dps,
    show_default=True,
    help="Rate of turn (°/s) above which the device is turning (follow-up test).",
)
@input_options
@output_options
@safe_outputs(*OUTPUTS)
def heading_cmd(as_json: bool, quiet: bool, **options: Any) -> None:
    """Heading-device evidence (ISO 22090-2 / IMO MSC.116(73)): static, dynamic and follow-up error."""
    _print(heading_route(quiet=quiet, on_input=note_input, **options), as_json, quiet)


def heading_route(
    dut_path: str,
    ref_path: str,
    output: str,
    json_path: str | None,
    correction_deg: float,
    dut_channel: str | None,
    ref_channel: str | None,
    device: str | None,
    config_path: str | None,
    test_info_path: str | None,
    t_start: float | str | None,
    t_end: float | str | None,
    ref_frame: str | None = None,
    ref_mounting: str | None = None,
    quiet: bool = True,
    on_input: OnInput | None = None,
    **options: Any,
) -> RouteResult:
    """Parsed options → :func:`imutool.report.route.run_heading_report`."""
    json_path = _paths(output, json_path)
    load = {k: options.pop(k) for k in (*LOAD_OPTIONS, *REF_LOAD_OPTIONS)}
    with stages("report", ["reading", "evaluating", "writing"], quiet) as steps:
        return run_heading_report(
            dut_path,
            ref_path,
            output,
            json_path=json_path,
            options=HeadingOptions(**{HDG_NAMES.get(k, k): v for k, v in options.items()}),
            correction_deg=correction_deg,
            dut_channel=dut_channel,
            ref_channel=ref_channel,
            device=device,
            config=config_path,
            test_info=test_info_path,
            t_start=t_start,
            t_end=t_end,
            ref_frame=ref_frame,
            ref_mounting=ref_mounting,
            strict=strict_requested(),
            on_input=on_input,
            stage=steps.stage,
            **load,
        )


heading_cmd = route_of(heading_route, OUTPUTS)(heading_cmd)
