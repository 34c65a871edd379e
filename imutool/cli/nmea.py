"""`imutool nmea est.csv -o out.nmea --sentences HRM,XDR,HDG,THS [--serial PORT]`: IEC 61162-1 sentences and TSS1
out. Only option parsing and printing here; the work is :func:`imutool.nmea_out.run_nmea`, the route `imutool batch
nmea` and a Python user take (``nmea_lines`` is re-exported here for old callers)."""

from __future__ import annotations

from typing import Any

import click

from formats.errors import ImutoolError
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
from imutool.cli.roll import parse_resets, parse_utc, roll_options
from imutool.nmea_out import (  # noqa: F401  (nmea_lines, TRUE_TALKER: re-exported for old callers)
    HEADING_REFS,
    HEADING_SOURCES,
    LINE_OPTIONS,
    SENTENCES,
    TRUE_TALKER,
    nmea_lines,
    run_nmea,
)
from imutool.routes import OnInput, RouteResult

KNOWN = SENTENCES  # kept for callers of the old name
ROLL_EXTRA = ("hysteresis_frac", "hysteresis_min_deg", "smooth_frac", "disagree_frac")  # roll_options → roll_kw


def nmea_route(
    input_path: str,
    output: str | None,
    serial_port: str | None,
    no_header: bool,
    xdr_roll_sign: str,
    xdr_pitch_sign: str,
    talker_opts: tuple[str, ...],
    hysteresis_deg: float | None,
    centre: str,
    centre_window_s: float,
    refine_frac: float,
    max_period_s: float,
    resets: str | None,
    utc_start: str | None,
    quiet: bool = True,
    on_input: OnInput | None = None,
    **options: Any,
) -> RouteResult:
    """Parsed options → :func:`imutool.nmea_out.run_nmea`."""
    if output is None and serial_port is None:
        raise ImutoolError("give -o OUTPUT.nmea and/or --serial PORT")
    talkers = {}
    for item in talker_opts:
        k, sep, v = item.partition("=")
        if not sep or len(v.strip()) != 2:
            raise ImutoolError(f"--talker {item!r}: expected TYPE=ID with a 2-character ID, e.g. HRM=II")
        talkers[k.strip().upper()] = v.strip().upper()
    utc0 = parse_utc(utc_start)
    roll_kw = {
        **{k: options.pop(k) for k in ROLL_EXTRA if k in options},
        "hysteresis_deg": hysteresis_deg,
        "centre": centre,
        "centre_window_s": centre_window_s,
        "refine_frac": refine_frac,
        "max_period_s": max_period_s,
        "resets_s": parse_resets(resets),
        "utc_start": utc0,
    }
    return run_nmea(
        input_path,
        output,
        serial_port=serial_port,
        header=not no_header,
        xdr_roll_sign=int(xdr_roll_sign),
        xdr_pitch_sign=int(xdr_pitch_sign),
        talkers=talkers,
        roll_kw=roll_kw,
        utc_start=utc0,
        strict=strict_requested(),
        on_input=on_input,
        **options,
    )


@click.command(
    "nmea", epilog="Example: imutool nmea est.csv -o out.nmea --sentences HRM,XDR,HDG,THS --rate 2 --variation -3.5"
)
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True))
@click.option("-o", "--output", default=None, type=click.Path(), help="NMEA log (.nmea); optional with --serial.")
@click.option(
    "--sentences",
    default=default_of(run_nmea, "sentences"),
    show_default=True,
    help=f"Comma list of {', '.join(SENTENCES)}.",
)
@click.option(
    "--rate",
    "rate_hz",
    type=float,
    default=None,
    help="Output rate (Hz); refused when the sentences do not fit --baud. Default: the highest standard "
    "rate (≤ the input rate) that fits.",
)
@click.option("--serial", "serial_port", default=None, help="Also write to this serial port (e.g. /dev/ttyUSB0).")
@click.option(
    "--baud",
    type=int,
    default=default_of(run_nmea, "baud"),
    show_default=True,
    help="Line speed the output must fit (8N1, 10 bits a character; IEC 61162-1: 4800), for the file too.",
)
@click.option(
    "--realtime/--no-realtime",
    default=default_of(run_nmea, "realtime"),
    show_default=True,
    help="Pace serial output by the recording's time stamps.",
)
@click.option(
    "--time-prefix",
    "time_prefix",
    is_flag=True,
    help="Prefix each file line with its time (s), as capture logs do (read back by imutool).",
)
@click.option("--no-header", is_flag=True, help="Leave out the '#' header block of the file (conventions, flags).")
@click.option(
    "--heading-ref",
    type=click.Choice(("auto", *HEADING_REFS)),
    default=LINE_OPTIONS["heading_ref"],
    show_default=True,
    help="What the input `heading` channel is: compass (sensor reading, deviation not applied), magnetic "
    "(deviation applied) or true; auto: what the recording says (an NMEA log's heading is true, a filter's "
    "from the magnetometer magnetic, meta heading_reference), else magnetic (said in the summary).",
)
@click.option(
    "--heading-source",
    type=click.Choice(HEADING_SOURCES),
    default=LINE_OPTIONS["heading_source"],
    show_default=True,
    help="Where the heading comes from, for the HDT/THS/ROT talker: gyro (north-seeking: HE), gnss (GN), "
    "ins (IN), magnetic or auto (II: a magnetic heading corrected by variation).",
)
@click.option(
    "--deviation",
    "deviation_deg",
    type=float,
    default=None,
    help="Fixed HDG deviation (deg, E +). Default: the card of --calibration's [deviation] section, else null.",
)
@click.option("--variation", "variation_deg", type=float, default=None, help="Variation (deg, E +); null if unset.")
@click.option(
    "--ths-mode",
    type=click.Choice(["auto", "A", "E", "M", "S", "V"]),
    default=LINE_OPTIONS["ths_mode"],
    show_default=True,
    help="THS mode: auto (V without a heading, S for a simulated recording, else A), or force one.",
)
@click.option(
    "--heave-positive",
    type=click.Choice(["up", "down"]),
    default=LINE_OPTIONS["heave_positive"],
    show_default=True,
    help="Heave sign in PASHR/TSS1 (imutool, TSS1, Applanix: up; SBG, Kongsberg native: down).",
)
@click.option(
    "--xdr-roll-id", default=LINE_OPTIONS["xdr_roll_id"], show_default=True, help="XDR transducer id of roll."
)
@click.option(
    "--xdr-pitch-id", default=LINE_OPTIONS["xdr_pitch_id"], show_default=True, help="XDR transducer id of pitch."
)
@click.option(
    "--xdr-roll-sign",
    type=click.Choice(["1", "-1"]),
    default=str(LINE_OPTIONS["xdr_roll_sign"]),
    show_default=True,
    help="Multiply roll by this (−1 for a receiver with port-down positive).",
)
@click.option(
    "--xdr-pitch-sign",
    type=click.Choice(["1", "-1"]),
    default=str(LINE_OPTIONS["xdr_pitch_sign"]),
    show_default=True,
    help="Multiply pitch by this.",
)
@click.option(
    "--talker",
    "talker_opts",
    multiple=True,
    metavar="TYPE=ID",
    help="Talker per sentence, e.g. --talker HRM=II --talker THS=HE (defaults: HRM II, XDR YX, HDG HC, "
    "HDT/THS/ROT from --heading-source).",
)
@roll_options
@input_options(rate_flag="--input-rate")
@output_options
@safe_outputs("output")
def nmea_cmd(as_json: bool, quiet: bool, **options: Any) -> None:
    """IEC 61162-1 (NMEA 0183) sentences and TSS1 frames from a recording: HRM, XDR, HDG (deviation from the
    card of --calibration), HDT, THS (mode), ROT, $PASHR (attitude + heave, Applanix layout) and TSS1.

    Angles deg; roll + starboard down, pitch + bow up; heading clockwise from north; heave m (sign:
    --heave-positive). Flags say what is known: heave settling → PASHR IMU status 0 (empty heave) / TSS1 lower
    case; no GNSS → aiding 0 / TSS1 U; UTC only from the recording's real time (or --utc-start), else empty.
    """
    res = nmea_route(on_input=note_input, **options)
    s, plan = res.summary, (res.data or {})["plan"]
    for w in s.get("warnings") or []:
        click.echo(f"warning: {s['input']}: {w}", err=True)
    counts, output, serial_port = s["sentences"], s["output"], s["serial"]
    lines = [
        f"{s['input']}: {sum(counts.values())} sentences ({', '.join(f'{k} {v}' for k, v in counts.items())})"
        + (f" → {output}" if output else "")
        + (f" → {serial_port}" if serial_port else ""),
        f"  rate {plan.rate.describe()}",
    ]
    if any(x in plan.sentences for x in ("HDG", "HDT", "THS", "PASHR")):
        hr = s["heading_reference"]
        lines.append(f"  heading input {hr['reference']}: {hr['why']}")
    if "PASHR" in plan.sentences or "TSS1" in plan.sentences:
        lines.append(
            f"  heave positive {s['heave_positive']}; UTC "
            + (s["utc"] or "not known (no start time in the recording): PASHR time fields empty")
        )
    emit_summary(s, as_json, quiet, lines)


nmea_cmd = route_of(nmea_route)(nmea_cmd)
