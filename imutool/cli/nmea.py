"""`imutool nmea est.csv -o out.nmea --sentences HRM,XDR,HDG,THS [--serial PORT]`: IEC 61162-1 sentences out."""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Iterator
from datetime import datetime, timezone

import click
import numpy as np

from formats import Recording
from formats.errors import ImutoolError
from imutool.cli.common import emit_summary, input_options, load_input, output_options, safe_outputs
from imutool.cli.roll import parse_resets, parse_utc, roll_options

KNOWN = ("HRM", "XDR", "HDG", "THS")


def _v(a: np.ndarray | None, i: int) -> float | None:
    if a is None:
        return None
    x = float(a[i])
    return x if math.isfinite(x) else None


def nmea_lines(rec: Recording, sentences: list[str], rate_hz: float | None = None, *, heading_ref: str = "magnetic",
               deviation_deg: float | None = None, variation_deg: float | None = None, ths_mode: str = "A",
               xdr_roll_id: str = "ROLL", xdr_pitch_id: str = "PTCH", xdr_roll_sign: int = 1, xdr_pitch_sign: int = 1,
               talkers: dict[str, str] | None = None, roll_kw: dict | None = None) -> Iterator[tuple[float, str]]:
    """(time s, sentence) from a recording: HRM from imutool.roll statistics of ``roll``/``heel`` (deg, + stbd),
    XDR roll/pitch, HDG (sensor heading, deviation, variation E +), THS (true heading + mode).

    heading_ref says what the ``heading`` channel is: ``magnetic`` (HDG sensor = heading − deviation; THS true =
    heading + variation, needs the variation) or ``true`` (HDG sensor = heading − variation − deviation, needs the
    variation). Unknown deviation → null HDG fields and deviation 0 in the arithmetic.
    HRM status is A whenever the heel is valid; period and amplitudes are null fields until a cycle completes
    (and when the last one is older than max_period_s).
    """
    from formats.nmea import hdg_sentence, hrm_sentence, ths_sentence, xdr_roll_pitch
    from imutool.roll import roll_stats

    tk = {"HRM": "II", "XDR": "YX", "HDG": "HC", "THS": "HE", **(talkers or {})}
    sents = [s.strip().upper() for s in sentences if s.strip()]
    for s in sents:
        if s not in KNOWN:
            raise ImutoolError(f"unknown sentence {s!r}; known: {', '.join(KNOWN)}")
    n = len(rec)
    if n == 0:
        return
    t = rec.time
    heel = None
    for name in ("heel", "roll"):
        if name in rec.channels:
            heel = np.asarray(rec.get(name, "deg") if rec.units.get(name) else rec[name], float)
            break
    pitch = np.asarray(rec.get("pitch", "deg"), float) if "pitch" in rec.channels else None
    hdg = None
    for name in ("heading", "heading_mag", "heading_true"):
        if name in rec.channels:
            hdg = np.asarray(rec.get(name, "deg") if rec.units.get(name) else rec[name], float)
            if name == "heading_true":
                heading_ref = "true"
            elif name == "heading_mag":
                heading_ref = "magnetic"
            break
    if ("HRM" in sents or "XDR" in sents) and heel is None:
        raise ImutoolError(f"HRM/XDR need a 'roll' or 'heel' channel (deg); has {', '.join(rec.channels)}")
    if ("HDG" in sents or "THS" in sents) and hdg is None:
        raise ImutoolError(f"HDG/THS need a 'heading' channel (deg); has {', '.join(rec.channels)}")
    if "THS" in sents and heading_ref == "magnetic" and variation_deg is None:
        raise ImutoolError("THS carries TRUE heading: give --variation (deg, E +) or --heading-ref true")
    if "HDG" in sents and heading_ref == "true" and variation_deg is None:
        raise ImutoolError("HDG from a true heading needs --variation (deg, E +) to recover the magnetic heading")
    dev0 = deviation_deg or 0.0
    rs = None
    if "HRM" in sents:
        kw = dict(roll_kw or {})
        rs = roll_stats(t, heel, **kw)
    if rate_hz is None:
        rows = np.arange(n)
    else:
        if not (rate_hz > 0 and math.isfinite(rate_hz)):
            raise ImutoolError(f"--rate must be a positive number of Hz, not {rate_hz!r}")
        grid = np.arange(t[0], t[-1] + 1e-9, 1.0 / rate_hz)  # uniform grid within the recording
        rows = np.unique(np.clip(np.searchsorted(t, grid, side="left"), 0, n - 1))
    reset_dt: list[datetime | None] = []
    if rs is not None:
        for u in rs.resets_utc:
            reset_dt.append(datetime.fromisoformat(u.replace("Z", "+00:00")) if u else None)
        resets = sorted(set(rs.reset_time.tolist()))
    for i in rows:
        i = int(i)
        for s in sents:
            if s == "HRM":
                h = _v(heel, i)
                k = resets.index(float(rs.reset_time[i]))
                fresh = bool(rs.valid[i])
                yield float(t[i]), hrm_sentence(h, _v(rs.roll_period, i) if fresh else None,
                                                _v(rs.amp_port, i) if fresh else None,
                                                _v(rs.amp_stbd, i) if fresh else None,
                                                valid=h is not None,
                                                peak_port_deg=_v(rs.peak_port, i), peak_stbd_deg=_v(rs.peak_stbd, i),
                                                reset_utc=reset_dt[k], talker=tk["HRM"])
            elif s == "XDR":
                r, p = _v(heel, i), _v(pitch, i)
                if r is not None or p is not None:
                    yield float(t[i]), xdr_roll_pitch(r, p, roll_id=xdr_roll_id, pitch_id=xdr_pitch_id,
                                                      roll_sign=xdr_roll_sign, pitch_sign=xdr_pitch_sign,
                                                      talker=tk["XDR"])
            elif s == "HDG":
                h = _v(hdg, i)
                if h is not None:
                    mag = h if heading_ref == "magnetic" else h - (variation_deg or 0.0)
                    yield float(t[i]), hdg_sentence((mag - dev0) % 360.0, deviation_deg, variation_deg,
                                                    talker=tk["HDG"])
            elif s == "THS":
                h = _v(hdg, i)
                true = None if h is None else (h if heading_ref == "true" else h + (variation_deg or 0.0))
                yield float(t[i]), ths_sentence(None if true is None else true % 360.0,
                                                mode=ths_mode if true is not None else "V", talker=tk["THS"])


@click.command("nmea", epilog="Example: imutool nmea est.csv -o out.nmea --sentences HRM,XDR,HDG,THS --rate 2 "
               "--variation -3.5")
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True))
@click.option("-o", "--output", default=None, type=click.Path(), help="NMEA log (.nmea); optional with --serial.")
@click.option("--sentences", default="HRM,XDR", show_default=True, help="Comma list of HRM, XDR, HDG, THS.")
@click.option("--rate", "rate_hz", type=float, default=None, help="Output rate (Hz); default: every input row.")
@click.option("--serial", "serial_port", default=None, help="Also write to this serial port (e.g. /dev/ttyUSB0).")
@click.option("--baud", type=int, default=4800, show_default=True, help="Serial baud rate (IEC 61162-1: 4800).")
@click.option("--realtime/--no-realtime", default=True, show_default=True,
              help="Pace serial output by the recording's time stamps.")
@click.option("--time-prefix", "time_prefix", is_flag=True,
              help="Prefix each file line with its time (s), as capture logs do (read back by imutool).")
@click.option("--heading-ref", type=click.Choice(["magnetic", "true"]), default="magnetic", show_default=True,
              help="What the input `heading` channel is.")
@click.option("--deviation", "deviation_deg", type=float, default=None, help="HDG deviation (deg, E +); null if unset.")
@click.option("--variation", "variation_deg", type=float, default=None, help="HDG variation (deg, E +); null if unset.")
@click.option("--ths-mode", type=click.Choice(["A", "E", "M", "S", "V"]), default="A", show_default=True,
              help="THS mode: A autonomous, E estimated, M manual, S simulator, V not valid.")
@click.option("--xdr-roll-id", default="ROLL", show_default=True, help="XDR transducer id of roll.")
@click.option("--xdr-pitch-id", default="PTCH", show_default=True, help="XDR transducer id of pitch.")
@click.option("--xdr-roll-sign", type=click.Choice(["1", "-1"]), default="1", show_default=True,
              help="Multiply roll by this (−1 for a receiver with port-down positive).")
@click.option("--xdr-pitch-sign", type=click.Choice(["1", "-1"]), default="1", show_default=True,
              help="Multiply pitch by this.")
@click.option("--talker", "talker_opts", multiple=True, metavar="TYPE=ID",
              help="Talker per sentence, e.g. --talker HRM=II --talker THS=HE (defaults II, YX, HC, HE).")
@roll_options
@input_options
@output_options
@safe_outputs("output")
def nmea_cmd(input_path: str, output: str | None, sentences: str, rate_hz: float | None, serial_port: str | None,
             baud: int, realtime: bool, time_prefix: bool, heading_ref: str, deviation_deg: float | None,
             variation_deg: float | None, ths_mode: str, xdr_roll_id: str, xdr_pitch_id: str, xdr_roll_sign: str,
             xdr_pitch_sign: str, talker_opts: tuple[str, ...], hysteresis_deg: float, centre: str,
             centre_window_s: float, refine_frac: float, max_period_s: float, resets: str | None,
             utc_start: str | None, as_json: bool, quiet: bool, **io) -> None:
    """IEC 61162-1 (NMEA 0183) sentences from a recording: HRM (heel + starboard, roll period, amplitudes, peak
    hold with reset UTC), XDR roll/pitch, HDG (deviation/variation), THS (true heading + mode).

    Angles deg; roll + starboard down, pitch + bow up; heading clockwise from north.
    """
    from formats.atomic import atomic_path

    if output is None and serial_port is None:
        raise ImutoolError("give -o OUTPUT.nmea and/or --serial PORT")
    talkers = {}
    for item in talker_opts:
        k, sep, v = item.partition("=")
        if not sep or len(v.strip()) != 2:
            raise ImutoolError(f"--talker {item!r}: expected TYPE=ID with a 2-character ID, e.g. HRM=II")
        talkers[k.strip().upper()] = v.strip().upper()
    rec, _ = load_input(input_path, **io)
    roll_kw = {"hysteresis_deg": hysteresis_deg, "centre": centre, "centre_window_s": centre_window_s,
               "refine_frac": refine_frac, "max_period_s": max_period_s, "resets_s": parse_resets(resets),
               "utc_start": parse_utc(utc_start)}
    gen = nmea_lines(rec, sentences.split(","), rate_hz, heading_ref=heading_ref, deviation_deg=deviation_deg,
                     variation_deg=variation_deg, ths_mode=ths_mode, xdr_roll_id=xdr_roll_id,
                     xdr_pitch_id=xdr_pitch_id, xdr_roll_sign=int(xdr_roll_sign), xdr_pitch_sign=int(xdr_pitch_sign),
                     talkers=talkers, roll_kw=roll_kw)
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
                for ts, s in gen:
                    fh.write((f"{ts:.3f} " if time_prefix else "") + s + "\r\n")
                    counts[s[3:6]] += 1
                    if port is not None:
                        t_rec0 = ts if t_rec0 is None else t_rec0
                        _send(port, s, ts - t_rec0, t_wall0, realtime)
        else:
            for ts, s in gen:
                counts[s[3:6]] += 1
                t_rec0 = ts if t_rec0 is None else t_rec0
                _send(port, s, ts - t_rec0, t_wall0, realtime)
    finally:
        if port is not None:
            port.flush()
            port.close()
    if not counts:
        raise ImutoolError("no sentence written: the input lacks the channels for " + sentences, path=input_path)
    summary = {"input": input_path, "output": output, "serial": serial_port, "baud": baud if serial_port else None,
               "sentences": dict(counts), "total": int(sum(counts.values())), "rate_hz": rate_hz,
               "generated_utc": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")}
    lines = [f"{input_path}: {sum(counts.values())} sentences ({', '.join(f'{k} {v}' for k, v in counts.items())})"
             + (f" → {output}" if output else "") + (f" → {serial_port} @ {baud} Bd" if serial_port else "")]
    emit_summary(summary, as_json, quiet, lines)


def _send(port, sentence: str, t_rel: float, t_wall0: float, realtime: bool) -> None:
    if realtime:
        wait = t_wall0 + t_rel - time.monotonic()
        if wait > 0:
            time.sleep(wait)
    port.write((sentence + "\r\n").encode("ascii"))
