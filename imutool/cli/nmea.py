"""`imutool nmea est.csv -o out.nmea --sentences HRM,XDR,HDG,THS [--serial PORT]`: IEC 61162-1 sentences and TSS1
out. The library is :mod:`imutool.nmea_out` (``nmea_lines`` is re-exported here for old callers)."""

from __future__ import annotations

import time
from collections import Counter
from datetime import datetime, timezone

import click

from formats.errors import ImutoolError
from imutool.cli.common import emit_summary, input_options, load_input, output_options, safe_outputs
from imutool.cli.roll import parse_resets, parse_utc, roll_options
from imutool.nmea_out import HEADING_REFS, HEADING_SOURCES, SENTENCES, TRUE_TALKER, nmea_lines  # noqa: F401

KNOWN = SENTENCES  # kept for callers of the old name


@click.command(
    "nmea", epilog="Example: imutool nmea est.csv -o out.nmea --sentences HRM,XDR,HDG,THS --rate 2 --variation -3.5"
)
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True))
@click.option("-o", "--output", default=None, type=click.Path(), help="NMEA log (.nmea); optional with --serial.")
@click.option("--sentences", default="HRM,XDR", show_default=True, help=f"Comma list of {', '.join(SENTENCES)}.")
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
    default=4800,
    show_default=True,
    help="Line speed the output must fit (8N1, 10 bits a character; IEC 61162-1: 4800), for the file too.",
)
@click.option(
    "--realtime/--no-realtime",
    default=True,
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
    type=click.Choice(HEADING_REFS),
    default="magnetic",
    show_default=True,
    help="What the input `heading` channel is: compass (sensor reading, deviation not applied), magnetic "
    "(deviation applied) or true.",
)
@click.option(
    "--heading-source",
    type=click.Choice(HEADING_SOURCES),
    default="auto",
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
    default="auto",
    show_default=True,
    help="THS mode: auto (V without a heading, S for a simulated recording, else A), or force one.",
)
@click.option(
    "--heave-positive",
    type=click.Choice(["up", "down"]),
    default="up",
    show_default=True,
    help="Heave sign in PASHR/TSS1 (imutool, TSS1, Applanix: up; SBG, Kongsberg native: down).",
)
@click.option("--xdr-roll-id", default="ROLL", show_default=True, help="XDR transducer id of roll.")
@click.option("--xdr-pitch-id", default="PTCH", show_default=True, help="XDR transducer id of pitch.")
@click.option(
    "--xdr-roll-sign",
    type=click.Choice(["1", "-1"]),
    default="1",
    show_default=True,
    help="Multiply roll by this (−1 for a receiver with port-down positive).",
)
@click.option(
    "--xdr-pitch-sign", type=click.Choice(["1", "-1"]), default="1", show_default=True, help="Multiply pitch by this."
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
@input_options
@output_options
@safe_outputs("output")
def nmea_cmd(
    input_path: str,
    output: str | None,
    sentences: str,
    rate_hz: float | None,
    serial_port: str | None,
    baud: int,
    realtime: bool,
    time_prefix: bool,
    no_header: bool,
    heading_ref: str,
    heading_source: str,
    deviation_deg: float | None,
    variation_deg: float | None,
    ths_mode: str,
    heave_positive: str,
    xdr_roll_id: str,
    xdr_pitch_id: str,
    xdr_roll_sign: str,
    xdr_pitch_sign: str,
    talker_opts: tuple[str, ...],
    hysteresis_deg: float,
    centre: str,
    centre_window_s: float,
    refine_frac: float,
    max_period_s: float,
    resets: str | None,
    utc_start: str | None,
    as_json: bool,
    quiet: bool,
    **io,
) -> None:
    """IEC 61162-1 (NMEA 0183) sentences and TSS1 frames from a recording: HRM, XDR, HDG (deviation from the
    card of --calibration), HDT, THS (mode), ROT, $PASHR (attitude + heave, Applanix layout) and TSS1.

    Angles deg; roll + starboard down, pitch + bow up; heading clockwise from north; heave m (sign:
    --heave-positive). Flags say what is known: heave settling → PASHR IMU status 0 (empty heave) / TSS1 lower
    case; no GNSS → aiding 0 / TSS1 U; UTC only from the recording's real time (or --utc-start), else empty.
    """
    from formats.atomic import atomic_path
    from imutool.nmea_out import header_lines, input_rate, plan_rate, row_bytes

    if output is None and serial_port is None:
        raise ImutoolError("give -o OUTPUT.nmea and/or --serial PORT")
    talkers = {}
    for item in talker_opts:
        k, sep, v = item.partition("=")
        if not sep or len(v.strip()) != 2:
            raise ImutoolError(f"--talker {item!r}: expected TYPE=ID with a 2-character ID, e.g. HRM=II")
        talkers[k.strip().upper()] = v.strip().upper()
    rec, _ = load_input(input_path, **io)
    card = None
    card_from = None
    if io.get("calibration_file"):
        from calibration.file import load_calibration

        card = load_calibration(io["calibration_file"]).deviation
        card_from = io["calibration_file"] if card is not None else None
    if card is not None and deviation_deg is not None:
        raise ImutoolError("--deviation and a --calibration with a [deviation] card: give one of them")
    sents = [x.strip().upper() for x in sentences.split(",") if x.strip()]
    utc0 = parse_utc(utc_start)
    roll_kw = {
        "hysteresis_deg": hysteresis_deg,
        "centre": centre,
        "centre_window_s": centre_window_s,
        "refine_frac": refine_frac,
        "max_period_s": max_period_s,
        "resets_s": parse_resets(resets),
        "utc_start": utc0,
    }
    kw = dict(
        heading_ref=heading_ref,
        heading_source=heading_source,
        deviation_deg=deviation_deg,
        card=card,
        variation_deg=variation_deg,
        ths_mode=ths_mode,
        heave_positive=heave_positive,
        xdr_roll_id=xdr_roll_id,
        xdr_pitch_id=xdr_pitch_id,
        xdr_roll_sign=int(xdr_roll_sign),
        xdr_pitch_sign=int(xdr_pitch_sign),
        talkers=talkers,
        roll_kw=roll_kw,
        utc_start=utc0,
    )
    if len(rec) == 0:
        raise ImutoolError("the recording has no rows", path=input_path)
    nb = row_bytes(rec, sents, **kw)
    if nb == 0:
        raise ImutoolError("no sentence written: the input lacks the channels for " + sentences, path=input_path)
    plan = plan_rate(nb, baud, rate_hz, input_rate(rec))
    from formats.nmea import utc_offset_s

    off = utc0.timestamp() - float(rec.time[0]) if utc0 is not None else utc_offset_s(rec)
    utc_txt = (
        None
        if off is None
        else "recording time + offset, first row "
        + datetime.fromtimestamp(float(rec.time[0]) + off, tz=timezone.utc).isoformat().replace("+00:00", "Z")
    )
    tk_all = {"HDG": "HC", "THS": TRUE_TALKER[heading_source], **talkers}
    header = header_lines(
        source=input_path,
        sentences=sents,
        plan=plan,
        heading_ref=heading_ref,
        heading_source=heading_source,
        heave_positive=heave_positive,
        card_from=card_from,
        deviation_deg=deviation_deg,
        variation_deg=variation_deg,
        utc=utc_txt,
        talkers=tk_all,
    )
    gen = nmea_lines(rec, sents, plan.rate_hz, **kw)
    counts: Counter[str] = Counter()
    port = None
    if serial_port:
        import serial

        try:
            port = serial.Serial(serial_port, baudrate=baud, timeout=1, write_timeout=5)
        except (serial.SerialException, OSError) as e:
            raise ImutoolError(f"cannot open serial port: {e}", path=serial_port) from None
    t_wall0 = time.monotonic()
    t_rec0 = None
    try:
        if output:
            with atomic_path(output) as tmp, open(tmp, "w", encoding="ascii", newline="") as fh:
                if not no_header:
                    fh.write("".join(h + "\r\n" for h in header))
                for ts, s in gen:
                    fh.write((f"{ts:.3f} " if time_prefix else "") + s + "\r\n")
                    counts[_kind(s)] += 1
                    if port is not None:
                        t_rec0 = ts if t_rec0 is None else t_rec0
                        _send(port, s, ts - t_rec0, t_wall0, realtime)
        else:
            for ts, s in gen:
                counts[_kind(s)] += 1
                t_rec0 = ts if t_rec0 is None else t_rec0
                _send(port, s, ts - t_rec0, t_wall0, realtime)
    finally:
        if port is not None:
            port.flush()
            port.close()
    if not counts:
        raise ImutoolError("no sentence written: the input lacks the channels for " + sentences, path=input_path)
    summary = {
        "input": input_path,
        "output": output,
        "serial": serial_port,
        "baud": baud,
        "sentences": dict(counts),
        "total": int(sum(counts.values())),
        "rate_hz": plan.rate_hz,
        "rate_chosen": plan.chosen,
        "bytes_per_s": round(plan.bytes_per_s, 1),
        "line_bytes_per_s": plan.capacity_bytes_per_s,
        "heave_positive": heave_positive,
        "utc": utc_txt,
        "deviation": card_from or deviation_deg,
        "generated_utc": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }
    lines = [
        f"{input_path}: {sum(counts.values())} sentences ({', '.join(f'{k} {v}' for k, v in counts.items())})"
        + (f" → {output}" if output else "")
        + (f" → {serial_port}" if serial_port else ""),
        f"  rate {plan.describe()}",
    ]
    if "PASHR" in sents or "TSS1" in sents:
        lines.append(
            f"  heave positive {heave_positive}; UTC "
            + (utc_txt or "not known (no start time in the recording): PASHR time fields empty")
        )
    emit_summary(summary, as_json, quiet, lines)


def _kind(s: str) -> str:
    """Sentence type of an output line: 'HRM', 'PASHR', 'TSS1'."""
    if s.startswith(":"):
        return "TSS1"
    addr = s[1:].split(",", 1)[0]
    return "P" + addr[1:] if addr.startswith("P") else addr[2:]


def _send(port, sentence: str, t_rel: float, t_wall0: float, realtime: bool) -> None:
    if realtime:
        wait = t_wall0 + t_rel - time.monotonic()
        if wait > 0:
            time.sleep(wait)
    port.write((sentence + "\r\n").encode("ascii"))
