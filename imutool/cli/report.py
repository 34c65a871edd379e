"""`imutool report inclinometer|heading DUT --reference REF -o evidence.pdf` (+ evidence.json beside it)."""

from __future__ import annotations

import os
import sys
from typing import Any

import click

from formats.errors import ImutoolError
from imutool.cli.common import FiniteFloat, emit_summary, input_options, load_input, output_options, safe_outputs

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


def _paths(output: str, json_path: str | None) -> tuple[str, str]:
    if not output.lower().endswith(".pdf"):
        raise ImutoolError(f"output {output!r} must end in .pdf (the JSON is written beside it)")
    if json_path is None:  # the JSON beside the PDF is an output too
        from formats.atomic import check_outputs

        json_path = os.path.splitext(output)[0] + ".json"
        check_outputs([json_path])
    return output, json_path


def _identification(device: str | None, config: str | None) -> dict[str, Any]:
    from imutool.report.common import sha256_of

    ident: dict[str, Any] = {}
    if device:
        ident["device_declared"] = device
    if config:
        if not os.path.exists(config):
            raise ImutoolError("no such configuration file", path=config)
        ident["configuration_file"] = {"path": config, "sha256": sha256_of(config)}
    return ident


def _window(rec, t_start: float | None, t_end: float | None, path: str):
    if t_start is None and t_end is None:
        return rec
    out = rec.slice_time(t_start, t_end)
    if len(out) < 10:
        raise ImutoolError(f"fewer than 10 samples between --start {t_start} and --end {t_end}", path=path)
    out.meta["evaluated_window_s"] = [t_start, t_end]
    return out


def _steps(quiet: bool):
    """Progress on stderr (interactive only): reading, evaluating, writing JSON + PDF."""
    from imutool.progress import stages

    return stages("report", ["reading", "evaluating", "writing"], quiet)


def _finish(ev: dict, plots: dict, pdf: str, jpath: str, as_json: bool, quiet: bool, steps=None) -> None:
    """Write JSON and PDF, print the summary and exit with 0 (pass) or 1 (fail / incomplete)."""
    from imutool.report.pdf import render_pdf, write_json

    if steps is not None:
        steps.stage("writing JSON + PDF")
    write_json(ev, jpath)
    pages = render_pdf(ev, plots, pdf)
    if steps is not None:
        steps.close()
    summary = {
        "report": ev["report"],
        "pdf": pdf,
        "json": jpath,
        "pages": pages,
        "overall": ev["overall"]["status"],
        "lag_s": ev["alignment"]["lag_s"],
        "items": {it["id"]: {"status": it["status"], **it["stats"]} for it in ev["items"]},
    }
    summary["headline"] = ev["overall"]["headline"]
    summary["exit_status"] = ev["overall"]["exit_status"]
    lines = [
        f"{ev['title']}",
        f"  {ev['overall']['headline']}",
        f"  ({pages} pages → {pdf}, {jpath})",
        f"  time lag DUT vs reference: {ev['alignment']['lag_s']:+.3f} s "
        f"({'removed' if ev['alignment']['applied'] else 'not removed'})",
    ]
    for it in ev["items"]:
        s = it["stats"]
        mx = (
            f"max|e| {s['max_abs']:.3f}  RMS {s['rmse']:.3f}  p95 {s['p95_abs']:.3f}"
            if s.get("max_abs") is not None
            else ""
        )
        derived = f"  (derived by imutool, would be: {it['derived_result']})" if it.get("derived_result") else ""
        lines.append(f"  {it['id']:20s} {it['status']:17s} N={s.get('n', 0):<6} {mx}{derived}")
    for w in ev["warnings"]:
        lines.append(f"  warning: {w}")
    emit_summary(summary, as_json, quiet, lines)
    sys.exit(ev["overall"]["exit_status"])


def _test_info(path: str | None) -> dict:
    from imutool.report.testinfo import load_test_info

    return load_test_info(path)


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
            default="max",
            show_default=True,
            help="max: every sample/cycle within tolerance; p95: 95 % bound (MSC.1/Circ.1575).",
        ),
        click.option(
            "--align",
            type=click.Choice(["none", "xcorr"]),
            default="none",
            show_default=True,
            help="none: common clock, latency counts as error; xcorr: remove the measured lag.",
        ),
        click.option(
            "--max-lag",
            "max_lag_s",
            type=float,
            default=5.0,
            show_default=True,
            help="Lag search range ± s for the cross-correlation.",
        ),
        click.option(
            "--start",
            "t_start",
            type=float,
            default=None,
            help="Evaluate from this time (s, recording clock), e.g. after the filter has settled.",
        ),
        click.option("--end", "t_end", type=float, default=None, help="Evaluate up to this time (s)."),
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
    return f


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
@click.option("--angle-floor", type=float, default=1.0, show_default=True, help="Angle tolerance floor (deg).")
@click.option("--angle-pct", type=float, default=5.0, show_default=True, help="Angle tolerance, % of reading.")
@click.option("--period-floor", type=float, default=1.0, show_default=True, help="Period tolerance floor (s).")
@click.option("--period-pct", type=float, default=5.0, show_default=True, help="Period tolerance, % of reading.")
@click.option(
    "--hysteresis", "hysteresis_deg", type=float, default=0.5, show_default=True, help="Roll-cycle hysteresis (deg)."
)
@click.option("--min-cycles", type=int, default=3, show_default=True, help="Cycles per side needed to judge.")
@click.option(
    "--min-steps",
    "min_steps_per_side",
    type=int,
    default=2,
    show_default=True,
    help="Static steps per side needed to judge.",
)
@click.option(
    "--step-band",
    "step_band_deg",
    type=float,
    default=0.2,
    show_default=True,
    help="Plateau detection: reference range (deg) over 2 s.",
)
@click.option(
    "--step-min",
    "step_min_s",
    type=float,
    default=10.0,
    show_default=True,
    help="Plateau detection: minimum duration (s).",
)
@click.option(
    "--drift-min",
    "drift_min_s",
    type=float,
    default=3600.0,
    show_default=True,
    help="Minimum static hold (s) for the long-term test; shorter holds cannot resolve drift and are "
    "refused (insufficient data).",
)
@click.option(
    "--drift-limit",
    "drift_limit",
    type=POSITIVE,
    default=None,
    help="Optional drift-rate limit (°/h); the hold must resolve it (95 % half-width ≤ half the limit).",
)
@click.option(
    "--min-cycle-amp",
    "min_cycle_amp",
    type=POSITIVE,
    default=1.0,
    show_default=True,
    help="Roll cycles whose reference maximum is smaller (deg) are not judged.",
)
@click.option(
    "--crest-band",
    "crest_band",
    type=POSITIVE,
    default=0.05,
    show_default=True,
    help="Crest width = time within this (deg) of a maximum; periods whose crests are wider than the "
    "period tolerance are not judged (time of the maximum not resolved).",
)
@click.option(
    "--lat-accel-channel",
    default="lat_accel",
    show_default=True,
    help="Reference channel with the applied lateral acceleration (m/s², + starboard).",
)
@click.option(
    "--lat-accel-min",
    "lat_accel_min",
    type=POSITIVE,
    default=0.2,
    show_default=True,
    help="|lateral acceleration| (m/s²) from which samples belong to the acceleration item.",
)
@click.option(
    "--heel-range",
    "heel_range",
    type=POSITIVE,
    default=None,
    help="Declared heel range ± (deg) the static steps must cover (default: test record [dut]).",
)
@click.option(
    "--guard-band",
    is_flag=True,
    default=False,
    help="Decision rule with guard band: acceptance limit = tolerance − U (k = 2) of the reference.",
)
@click.option("--dut-channel", default=None, help="DUT heel channel (default: heel, else roll).")
@click.option("--ref-channel", default=None, help="Reference heel channel (default: heel, else roll; e.g. ref_roll).")
@input_options
@output_options
@safe_outputs("output", "json_path")
def inclinometer_cmd(
    dut_path: str,
    ref_path: str,
    output: str,
    json_path: str | None,
    device: str | None,
    config_path: str | None,
    criterion: str,
    align: str,
    max_lag_s: float,
    steps_path: str | None,
    angle_floor: float,
    angle_pct: float,
    period_floor: float,
    period_pct: float,
    hysteresis_deg: float,
    min_cycles: int,
    min_steps_per_side: int,
    step_band_deg: float,
    step_min_s: float,
    drift_min_s: float,
    drift_limit: float | None,
    min_cycle_amp: float,
    crest_band: float,
    lat_accel_channel: str,
    lat_accel_min: float,
    heel_range: float | None,
    guard_band: bool,
    dut_channel: str | None,
    ref_channel: str | None,
    t_start: float | None,
    t_end: float | None,
    test_info_path: str | None,
    as_json: bool,
    quiet: bool,
    **io,
) -> None:
    """Electronic-inclinometer evidence (IMO MSC.363(92), ISO 19697 clauses) of DUT against --reference.

    DUT: a recording with `roll` (deg, + starboard down; e.g. `imutool filter` output) or an NMEA capture with
    HRM (its own period, amplitude and peak-hold fields are then tested, plus the interface). Amplitude, period
    and peak hold pass only on values the device reported (HRM); values imutool derives from a CSV heel are
    shown but leave those items not tested, so the result is then INCOMPLETE (exit status 1).
    """
    from imutool.report.inclinometer import InclinometerOptions, inclinometer_evidence

    pdf, jpath = _paths(output, json_path)
    ident = _identification(device, config_path)
    info = _test_info(test_info_path)
    steps = _steps(quiet)
    steps.stage("reading")
    dut, _ = load_input(dut_path, **io)
    ref, _ = load_input(ref_path, **{**io, "mounting": None, "calibration_file": None})
    dut, ref = _window(dut, t_start, t_end, dut_path), _window(ref, t_start, t_end, ref_path)
    o = InclinometerOptions(
        angle_floor_deg=angle_floor,
        angle_pct=angle_pct,
        period_floor_s=period_floor,
        period_pct=period_pct,
        criterion=criterion,
        align=align,
        max_lag_s=max_lag_s,
        hysteresis_deg=hysteresis_deg,
        min_cycles=min_cycles,
        min_steps_per_side=min_steps_per_side,
        step_band_deg=step_band_deg,
        step_min_s=step_min_s,
        long_term_min_s=drift_min_s,
        drift_limit_deg_per_h=drift_limit,
        min_cycle_amp_deg=min_cycle_amp,
        crest_band_deg=crest_band,
        lat_accel_channel=lat_accel_channel,
        lat_accel_min_ms2=lat_accel_min,
        declared_heel_range_deg=heel_range,
        guard_band=guard_band,
    )
    steps.stage("evaluating")
    ev, plots = inclinometer_evidence(
        dut,
        ref,
        dut_path=dut_path,
        ref_path=ref_path,
        steps_path=steps_path,
        options=o,
        identification=ident,
        dut_channel=dut_channel,
        ref_channel=ref_channel,
        test_info=info,
    )
    _finish(ev, plots, pdf, jpath, as_json, quiet, steps)


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
    default=0.0,
    show_default=True,
    help="Added to the DUT heading first (deg; e.g. magnetic variation, E +).",
)
@click.option("--static-limit", type=float, default=1.0, show_default=True, help="Static error limit (deg).")
@click.option("--min-headings", type=int, default=4, show_default=True, help="Equidistant headings needed.")
@click.option(
    "--turn-min",
    "turn_min_dps",
    type=float,
    default=1.0,
    show_default=True,
    help="Rate of turn (°/s) above which the device is turning (follow-up test).",
)
@input_options
@output_options
@safe_outputs("output", "json_path")
def heading_cmd(
    dut_path: str,
    ref_path: str,
    output: str,
    json_path: str | None,
    device: str | None,
    config_path: str | None,
    criterion: str,
    align: str,
    max_lag_s: float,
    dut_channel: str | None,
    ref_channel: str | None,
    correction_deg: float,
    static_limit: float,
    min_headings: int,
    turn_min_dps: float,
    t_start: float | None,
    t_end: float | None,
    test_info_path: str | None,
    as_json: bool,
    quiet: bool,
    **io,
) -> None:
    """Heading-device evidence (ISO 22090-2 / IMO MSC.116(73)): static, dynamic and follow-up error."""
    from imutool.report.heading import HeadingOptions, heading_evidence

    pdf, jpath = _paths(output, json_path)
    ident = _identification(device, config_path)
    info = _test_info(test_info_path)
    steps = _steps(quiet)
    steps.stage("reading")
    dut, _ = load_input(dut_path, **io)
    ref, _ = load_input(ref_path, **{**io, "mounting": None, "calibration_file": None})
    dut, ref = _window(dut, t_start, t_end, dut_path), _window(ref, t_start, t_end, ref_path)
    o = HeadingOptions(
        criterion=criterion,
        align=align,
        max_lag_s=max_lag_s,
        static_limit_deg=static_limit,
        min_headings=min_headings,
        turn_min_dps=turn_min_dps,
    )
    steps.stage("evaluating")
    ev, plots = heading_evidence(
        dut,
        ref,
        dut_path=dut_path,
        ref_path=ref_path,
        dut_channel=dut_channel,
        ref_channel=ref_channel,
        dut_correction_deg=correction_deg,
        options=o,
        identification=ident,
        test_info=info,
    )
    _finish(ev, plots, pdf, jpath, as_json, quiet, steps)
