"""IEC 61162-1 (NMEA 0183) sentences and TSS1 frames out of a recording, with honest flags and a line budget.

Sentences: HRM (heel, roll period, amplitudes, peak hold), XDR (pitch/roll), HDG (compass sensor heading,
deviation, variation, E/W), HDT and THS (true heading; THS with a mode indicator), ROT (deg/min), $PASHR
(attitude + heave, Applanix POS MV layout) and TSS1 (heave/roll/pitch survey frame). Writers live in
``formats.nmea``; this module decides what each field says.

Units and signs: degrees; roll (heel) + starboard down; pitch + bow up; heading clockwise from north in
[0, 360); rate of turn deg/min, + bow to starboard; heave m, **+ up** inside imutool, sent + up or + down as
chosen (``heave_positive``).

Honesty rules:
- heading reference: ``compass`` (what the sensor reads: deviation not applied), ``magnetic`` (deviation
  applied) or ``true``. HDG carries the sensor heading and the deviation of the card (the magnetic→compass
  inverse of the card is solved, not approximated by −δ) — or null deviation when none is known;
- talkers: HDG ``HC`` (magnetic compass); HDT/THS/ROT from the heading's source: ``HE`` only for a
  north-seeking gyro, ``GN`` GNSS compass, ``IN`` integrated navigation, ``II`` a magnetic heading corrected by
  variation (or a source not stated). THS mode: ``V`` where the heading is missing, ``S`` for a simulated
  recording, else ``A``;
- heave while the estimator settles (``settled`` = 0): $PASHR heave field empty and IMU status 0 (Applanix:
  0 = IMU out / not valid, 1 = satisfactory); TSS1 status letter in lower case (settling); PASHR accuracies
  from ``roll_std``/``pitch_std``/``heading_std`` (1 σ, deg) when the recording has them. No GNSS channel
  (sog, cog, lat, lon) → PASHR aiding flag 0 (no aiding) and TSS1 ``U``/``u`` (unaided);
- UTC only from the recording's real time (:func:`formats.nmea.utc_offset_s`, or ``utc_start`` given by the
  caller); otherwise PASHR's time field is empty;
- the output rate must fit the serial line: bytes per second of the chosen set (8N1: 10 bits a character)
  against ``baud / 10``; a rate that does not fit is refused, no rate given → the highest standard rate that
  fits (:func:`plan_rate`).
"""

from __future__ import annotations

import heapq
import inspect
import math
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any

import numpy as np

from calibration.file import load_calibration
from formats import Recording
from formats.atomic import atomic_path
from formats.errors import ImutoolError
from formats.nmea import (
    hdg_sentence,
    hdt_sentence,
    hrm_sentence,
    pashr_sentence,
    rot_sentence,
    ths_sentence,
    tss1_frame,
    utc_offset_s,
    xdr_roll_pitch,
)
from imutool.routes import LOAD_OPTIONS, OnInput, RouteResult, read_source

SENTENCES = ("HRM", "XDR", "HDG", "HDT", "THS", "ROT", "PASHR", "TSS1")
HEADING_REFS = ("compass", "magnetic", "true")
HEADING_SOURCES = ("auto", "magnetic", "gyro", "gnss", "ins")
TRUE_TALKER = {"gyro": "HE", "gnss": "GN", "ins": "IN", "magnetic": "II", "auto": "II"}
STANDARD_RATES = (100.0, 50.0, 25.0, 20.0, 10.0, 5.0, 2.0, 1.0, 0.5, 0.2, 0.1)
BITS_PER_CHAR = 10  # 8N1: start + 8 data + stop
GNSS_CHANNELS = ("sog", "cog", "lat", "lon")


def _ch(rec: Recording, names: tuple[str, ...], unit: str) -> tuple[np.ndarray | None, str | None]:
    for name in names:
        if name in rec.channels and rec[name].ndim == 1:
            a = rec.get(name, unit) if rec.units.get(name) and rec.units.get(name) != unit else rec[name]
            return np.asarray(a, dtype=float), name
    return None, None


def _v(a: np.ndarray | None, i: int) -> float | None:
    if a is None:
        return None
    x = float(a[i])
    return x if math.isfinite(x) else None


def is_simulated(rec: Recording) -> bool:
    """True when the recording says it came from imutool's simulator (THS mode S)."""
    m = rec.meta
    return bool(m.get("scenario")) or "simulat" in str(m.get("sensor", "")).lower() or bool(m.get("simulated"))


def heave_sign(rec: Recording, heave_positive: str) -> float:
    """Factor from the recording's heave (meta ``heave_positive``, default up) to the requested convention."""
    if heave_positive not in ("up", "down"):
        raise ImutoolError(f"heave_positive must be 'up' or 'down', not {heave_positive!r}")
    have = str(rec.meta.get("heave_positive", "up")).lower()
    return 1.0 if have == heave_positive else -1.0


@dataclass
class Headings:
    """Per-row headings (deg, NaN where unknown): compass sensor, deviation, magnetic, true; and what is known."""

    sensor: np.ndarray | None = None
    deviation: np.ndarray | None = None
    magnetic: np.ndarray | None = None
    true: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)


def heading_reference(rec: Recording, heading_ref: str = "auto") -> tuple[str, str]:
    """What the recording's heading is (compass, magnetic or true) and why: (reference, reason).

    ``heading_ref`` other than ``'auto'`` is the caller's word. Else, in order: the channel's name
    (``heading_true``, ``heading_mag``, ``heading_sensor``); ``meta['heading_reference']``; an NMEA log (its
    ``heading`` is true: HDT, THS, PASHR, or HDG with deviation and variation; ``meta['signs']`` says so, also after
    a CSV round trip); a filter's output (``meta['heading_source']``: an external true heading, or the
    magnetometer); otherwise magnetic, said to be assumed."""
    if heading_ref != "auto":
        if heading_ref not in HEADING_REFS:
            raise ImutoolError(f"heading reference {heading_ref!r}: use auto or one of {', '.join(HEADING_REFS)}")
        return heading_ref, "as given (--heading-ref)"
    named = {"heading_true": "true", "heading_mag": "magnetic", "heading_sensor": "compass"}
    if "heading" not in rec.channels:
        for ch, ref in named.items():
            if ch in rec.channels:
                return ref, f"the channel is {ch}"
    meta = rec.meta
    said = str(meta.get("heading_reference", "")).strip().lower()
    if said in HEADING_REFS:
        return said, f"the recording says so (heading_reference: {said})"
    if meta.get("format") == "nmea0183" or "heading deg true" in str(meta.get("signs", "")):
        return "true", "an NMEA log: its heading is true (HDT/THS/PASHR, or HDG with deviation and variation)"
    src = str(meta.get("heading_source", ""))
    if src.startswith("heading_true"):
        return "true", f"the filter took its heading from a true heading ({src})"
    if src.startswith("magnetometer"):
        return "magnetic", "the filter's heading is from the magnetometer"
    return "magnetic", "assumed: the recording does not say what its heading is (--heading-ref to say)"


def resolve_headings(
    h: np.ndarray,
    heading_ref: str,
    card: Any = None,
    deviation_deg: float | None = None,
    variation_deg: float | None = None,
) -> Headings:
    """Sensor / deviation / magnetic / true heading arrays from one heading channel (deg).

    ``card``: a deviation card (``deviation_deg(compass)``, ``compass_from_magnetic(magnetic)``); ``deviation_deg``
    a fixed deviation (E +) instead. magnetic = compass + δ(compass); true = magnetic + variation (E +)."""
    if heading_ref not in HEADING_REFS:
        raise ImutoolError(f"heading reference {heading_ref!r}: use one of {', '.join(HEADING_REFS)}")
    if card is not None and deviation_deg is not None:
        raise ImutoolError("give the deviation either as a card (--calibration) or as --deviation, not both")
    h = np.asarray(h, dtype=float) % 360.0
    out = Headings()
    var = variation_deg
    if heading_ref == "compass":
        out.sensor = h
        if card is not None:
            out.deviation = card.deviation_deg(h)
            out.notes.append("deviation from the card at each compass heading")
        elif deviation_deg is not None:
            out.deviation = np.full_like(h, float(deviation_deg))
        if out.deviation is not None:
            out.magnetic = (h + out.deviation) % 360.0
    else:
        out.magnetic = h if heading_ref == "magnetic" else (None if var is None else (h - var) % 360.0)
        if heading_ref == "true":
            out.true = h
        if out.magnetic is not None:
            if card is not None:
                out.sensor = card.compass_from_magnetic(out.magnetic)
                out.deviation = card.deviation_deg(out.sensor)
                out.notes.append("compass heading solved from the card's magnetic→compass inverse")
            elif deviation_deg is not None:
                out.sensor = (out.magnetic - deviation_deg) % 360.0
                out.deviation = np.full_like(h, float(deviation_deg))
            else:
                out.sensor = out.magnetic
                out.notes.append("no deviation known: HDG sensor field = magnetic heading, deviation field null")
    if out.true is None and out.magnetic is not None and var is not None:
        out.true = (out.magnetic + var) % 360.0
    return out


@dataclass
class RatePlan:
    """Output rate against the serial line: rate (Hz), bytes per output instant, bytes/s, line capacity."""

    rate_hz: float
    bytes_per_row: int
    bytes_per_s: float
    capacity_bytes_per_s: float
    baud: int
    chosen: bool  # True: picked here; False: given by the caller

    def describe(self) -> str:
        how = "picked to fit" if self.chosen else "as asked"
        return (
            f"{self.rate_hz:g} Hz ({how}): ≈{self.bytes_per_s:.0f} bytes/s of {self.capacity_bytes_per_s:.0f} "
            f"at {self.baud} Bd 8N1 ({100 * self.bytes_per_s / self.capacity_bytes_per_s:.0f} %)"
        )


def input_rate(rec: Recording, sentences: list[str] | tuple[str, ...] | None = None) -> float:
    """Median sample rate (Hz) of the recording; of a many-clock recording, that of the fastest stream that
    drives one of ``sentences`` (each sentence on its own channel's clock, :func:`clock_groups`), never the
    table's rows."""
    if rec.multi_clock and sentences:
        rates = [rec.stream_timing(key).get("rate_hz") or 0.0 for key, _, _ in clock_groups(rec, sentences) if key]
        return max(rates) if rates and max(rates) > 0 else 1.0
    if len(rec) < 2:
        return 1.0
    dt = float(np.median(np.diff(rec.time)))
    return 1.0 / dt if dt > 0 else 1.0


# the channel whose own samples time each sentence (first present name wins), for a many-clock recording
_DRIVERS: dict[str, tuple[str, ...]] = {
    "HRM": ("heel", "roll"),
    "XDR": ("heel", "roll", "pitch"),
    "HDG": ("heading", "heading_true", "heading_mag", "heading_sensor"),
    "HDT": ("heading", "heading_true", "heading_mag", "heading_sensor"),
    "THS": ("heading", "heading_true", "heading_mag", "heading_sensor"),
    "ROT": ("rot", "gyro", "heading", "heading_true", "heading_mag", "heading_sensor"),
    "PASHR": ("heel", "roll", "pitch", "heading", "heading_true", "heading_mag", "heave"),
    "TSS1": ("heave",),
}


def clock_groups(
    rec: Recording, sentences: list[str] | tuple[str, ...]
) -> list[tuple[str | None, Recording, list[str]]]:
    """The sentences grouped by the stream of the channel that drives them (:data:`_DRIVERS`), each group with
    the recording on that stream's clock (:meth:`formats.Recording.on_clock`: the stream's own samples, other
    channels held at their latest own sample): (stream, recording, sentences). A single-clock recording is one
    group (stream None)."""
    sents = [s.strip().upper() for s in sentences if s.strip()]
    if not rec.multi_clock:
        return [(None, rec, sents)]
    groups: dict[str, list[str]] = {}
    for s in sents:
        driver = next((c for c in _DRIVERS.get(s, ()) if c in rec.channels), None)
        key = (rec.stream_of(driver) or driver) if driver else None
        groups.setdefault(key or "", []).append(s)
    out = []
    for key, ss in groups.items():
        if not key:  # no channel for them: the checks of nmea_lines name what is missing
            out.append((None, rec.on_clock(next(iter(rec.stream_rows))), ss))
            continue
        out.append((key, rec.on_clock(key), ss))
    return out


def plan_rate(row_bytes: int, baud: int, rate_hz: float | None, input_hz: float, fill: float = 0.9) -> RatePlan:
    """Check (``rate_hz`` given) or choose (None) the output rate for ``row_bytes`` bytes per output instant.

    Capacity = baud / 10 bytes/s (8N1); at most ``fill`` of it is used. A given rate that needs more is refused
    (ImutoolError naming the rate that fits); None → the highest of :data:`STANDARD_RATES` (or the input rate)
    that fits. Raises when not even 0.1 Hz fits."""
    if not (isinstance(baud, int) and baud > 0):
        raise ImutoolError(f"--baud must be a positive integer, not {baud!r}")
    cap = baud / BITS_PER_CHAR
    usable = cap * fill
    max_rate = usable / max(row_bytes, 1)
    if rate_hz is not None:
        if not (rate_hz > 0 and math.isfinite(rate_hz)):
            raise ImutoolError(f"--rate must be a positive number of Hz, not {rate_hz!r}")
        need = row_bytes * rate_hz
        if need > usable:
            fit = [r for r in STANDARD_RATES if r <= max_rate]
            need_baud = next(
                (
                    b
                    for b in (4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800)
                    if b * fill / BITS_PER_CHAR >= need
                ),
                None,
            )
            raise ImutoolError(
                f"--rate {rate_hz:g} Hz does not fit the line: {row_bytes} bytes per output × {rate_hz:g} Hz = "
                f"{need:.0f} bytes/s, but {baud} Bd (8N1) carries {cap:.0f} bytes/s ({100 * fill:.0f} % usable = "
                f"{usable:.0f}); use "
                + (f"--rate {fit[0]:g} or less, " if fit else "")
                + "fewer sentences"
                + (f", or --baud {need_baud}" if need_baud else "")
            )
        return RatePlan(float(rate_hz), row_bytes, need, cap, baud, False)
    cands = [r for r in STANDARD_RATES if r <= max_rate and r <= input_hz * 1.0001]
    if input_hz <= max_rate and (not cands or input_hz < cands[0]):
        cands.insert(0, input_hz)
    if not cands:
        raise ImutoolError(
            f"the sentences need {row_bytes} bytes per output: even 0.1 Hz does not fit "
            f"{baud} Bd; choose fewer sentences or a higher --baud"
        )
    r = cands[0]
    return RatePlan(float(r), row_bytes, row_bytes * r, cap, baud, True)


def heading_rate(t: np.ndarray, heading_deg: np.ndarray, window_s: float = 1.0) -> np.ndarray:
    """Rate of turn (deg/min, + = clockwise) from a heading (deg): its unwrapped change over the last
    ``window_s`` seconds (causal); NaN before a full window and where the heading is missing."""
    h = np.asarray(heading_deg, dtype=float)
    ok = np.isfinite(h)
    out = np.full(len(h), np.nan)
    if ok.sum() < 2:
        return out
    tt = t[ok]
    u = np.degrees(np.unwrap(np.radians(h[ok])))
    t0 = t - window_s
    valid = ok & (t0 >= tt[0])
    u_then = np.interp(t0[valid], tt, u)
    u_now = np.interp(t[valid], tt, u)
    out[valid] = (u_now - u_then) / window_s * 60.0
    return out


def output_rows(t: np.ndarray, rate_hz: float | None) -> np.ndarray:
    """Row indices for a uniform output grid at ``rate_hz`` (first row at or after each grid point)."""
    n = len(t)
    if rate_hz is None:
        return np.arange(n)
    grid = t[0] + np.arange(int(np.floor((t[-1] - t[0]) * rate_hz + 1e-9)) + 1) / rate_hz
    return np.unique(np.clip(np.searchsorted(t, grid - 1e-9, side="left"), 0, n - 1))


def nmea_lines(
    rec: Recording,
    sentences: list[str] | tuple[str, ...],
    rate_hz: float | None = None,
    *,
    heading_ref: str = "auto",
    heading_source: str = "auto",
    deviation_deg: float | None = None,
    card: Any = None,
    variation_deg: float | None = None,
    ths_mode: str = "auto",
    heave_positive: str = "up",
    xdr_roll_id: str = "ROLL",
    xdr_pitch_id: str = "PTCH",
    xdr_roll_sign: int = 1,
    xdr_pitch_sign: int = 1,
    talkers: dict[str, str] | None = None,
    roll_kw: dict | None = None,
    utc_start: datetime | None = None,
    rot_window_s: float = 1.0,
) -> Iterator[tuple[float, str]]:
    """(time s, sentence or TSS1 frame without CR/LF) for each output row; see the module docstring.

    Channels: ``roll``/``heel`` and ``pitch`` (deg), a heading (``heading`` as ``heading_ref``;
    ``heading_mag`` = magnetic, ``heading_true`` = true, ``heading_sensor`` = compass), ``rot`` (deg/min) or
    ``gyro`` (z ≈ rate of turn), ``heave`` (m, + up unless meta ``heave_positive`` = down), ``heave_rate``,
    ``accel`` (for TSS1's horizontal acceleration), ``settled`` (heave validity), GNSS channels. ``utc_start``:
    UTC of the first row (else from the recording's metadata/time, else no UTC).
    """
    sents = [s.strip().upper() for s in sentences if s.strip()]
    for s in sents:
        if s not in SENTENCES:
            raise ImutoolError(f"unknown sentence {s!r}; known: {', '.join(SENTENCES)}")
    if not sents:
        raise ImutoolError("no sentence chosen")
    if heading_source not in HEADING_SOURCES:
        raise ImutoolError(f"heading source {heading_source!r}: use one of {', '.join(HEADING_SOURCES)}")
    if ths_mode != "auto" and (len(ths_mode) != 1 or ths_mode not in "AEMSV"):
        raise ImutoolError(f"THS mode {ths_mode!r}: use auto or one of A, E, M, S, V")
    n = len(rec)
    if n == 0:
        return
    if rec.multi_clock:  # each sentence on its own channel's clock, then all of them in time order
        off = utc_start.timestamp() - float(rec.time[0]) if utc_start is not None else utc_offset_s(rec)
        opts = {k: v for k, v in locals().items() if k in LINE_OPTIONS}
        gens = []
        for _, sub, ss in clock_groups(rec, sents):
            o = dict(opts, utc_start=None if off is None else datetime.fromtimestamp(sub.time[0] + off, timezone.utc))
            gens.append(nmea_lines(sub, ss, rate_hz, **o))
        yield from heapq.merge(*gens, key=lambda x: x[0])
        return
    t = rec.time
    tk = {
        "HRM": "II",
        "XDR": "YX",
        "HDG": "HC",
        "HDT": TRUE_TALKER[heading_source],
        "THS": TRUE_TALKER[heading_source],
        "ROT": TRUE_TALKER[heading_source],
        **(talkers or {}),
    }
    heel, _ = _ch(rec, ("heel", "roll"), "deg")
    pitch, _ = _ch(rec, ("pitch",), "deg")
    hdg, hname = _ch(rec, ("heading", "heading_true", "heading_mag", "heading_sensor"), "deg")
    ref = {"heading_true": "true", "heading_mag": "magnetic", "heading_sensor": "compass"}.get(hname or "") or (
        heading_reference(rec, heading_ref)[0]
    )
    need_heading = [s for s in sents if s in ("HDG", "HDT", "THS")]
    if ("HRM" in sents or "XDR" in sents) and heel is None:
        raise ImutoolError(f"HRM/XDR need a 'roll' or 'heel' channel (deg); has {', '.join(rec.channels)}")
    if "TSS1" in sents and (heel is None or pitch is None):
        raise ImutoolError(
            "TSS1 needs roll and pitch (deg) as well as heave: the recording has "
            f"{', '.join(rec.channels)} (run imutool filter and pass its roll/pitch along)"
        )
    hs = None
    if need_heading:
        if hdg is None:
            raise ImutoolError(f"{'/'.join(need_heading)} need a heading channel (deg); has {', '.join(rec.channels)}")
        hs = resolve_headings(hdg, ref, card, deviation_deg, variation_deg)
        if ("THS" in sents or "HDT" in sents) and hs.true is None:
            what = (
                "the deviation (--calibration with a [deviation] card, or --deviation) and "
                if ref == "compass" and hs.magnetic is None
                else ""
            )
            raise ImutoolError(
                f"THS/HDT carry TRUE heading: the {ref} heading needs {what}the variation (--variation, deg, E +)"
            )
        if "HDG" in sents and hs.sensor is None:
            raise ImutoolError("HDG from a true heading needs --variation (deg, E +) to recover the magnetic heading")
    heave, _ = _ch(rec, ("heave",), "m")
    if ("PASHR" in sents or "TSS1" in sents) and heave is not None:
        heave = heave * heave_sign(rec, heave_positive)
    if "TSS1" in sents and heave is None:
        raise ImutoolError(f"TSS1 needs a 'heave' channel (m); has {', '.join(rec.channels)}")
    if "PASHR" in sents and all(x is None for x in (hdg, heel, pitch, heave)):
        raise ImutoolError(f"PASHR needs heading, roll, pitch or heave; has {', '.join(rec.channels)}")
    settled, _ = _ch(rec, ("settled",), "1")
    stds = [_ch(rec, (name,), "deg")[0] for name in ("roll_std", "pitch_std", "heading_std")]
    gnss = np.zeros(n, dtype=bool)
    for name in GNSS_CHANNELS:
        a, _ = _ch(rec, (name,), rec.units.get(name) or "1")
        if a is not None:
            gnss |= np.isfinite(a)
    # PASHR heading is true heading: only when it is known
    true_arr = hs.true if hs is not None else None
    if "PASHR" in sents and true_arr is None and hdg is not None:
        true_arr = resolve_headings(hdg, ref, card, deviation_deg, variation_deg).true
    # rate of turn (deg/min): rot channel, else gyro z (body z down: + = bow to starboard), else the heading's
    # change over the last rot_window_s (causal; V before a full window)
    rot = None
    if "ROT" in sents:
        rot, _ = _ch(rec, ("rot",), "deg/min")
        if rot is None and "gyro" in rec.channels and rec["gyro"].ndim == 2:
            g = rec.get("gyro", "rad/s") if rec.units.get("gyro") else rec["gyro"]
            rot = np.degrees(np.asarray(g, float)[:, 2]) * 60.0
        if rot is None and hdg is not None and n >= 2:
            rot = heading_rate(t, hdg, rot_window_s)
        if rot is None:
            raise ImutoolError("ROT needs 'rot' (deg/min), 'gyro' or a heading channel")
    # TSS1 accelerations: vertical from d(heave rate)/dt (same sign as heave), horizontal from accel x/y
    vacc = hacc = None
    if "TSS1" in sents:
        hr, _ = _ch(rec, ("heave_rate",), "m/s")
        if n >= 3:
            vacc = (
                np.gradient(hr * heave_sign(rec, heave_positive), t)
                if hr is not None
                else np.gradient(np.gradient(heave, t), t)
            )
        if "accel" in rec.channels and rec["accel"].ndim == 2:
            a = np.asarray(rec.get("accel", "m/s^2") if rec.units.get("accel") else rec["accel"], float)
            hacc = np.hypot(a[:, 0], a[:, 1])
    off = utc_start.timestamp() - float(t[0]) if utc_start is not None else utc_offset_s(rec)
    rs = None
    if "HRM" in sents:
        from imutool.roll import roll_stats

        kw = dict(roll_kw or {})
        if kw.get("utc_start") is None and off not in (None, 0.0):
            kw["utc_start"] = datetime.fromtimestamp(off, tz=timezone.utc)
        rs = roll_stats(t, heel, **kw)
        reset_dt = [datetime.fromisoformat(u.replace("Z", "+00:00")) if u else None for u in rs.resets_utc]
        resets = sorted(set(rs.reset_time.tolist()))
    sim = is_simulated(rec)
    for i in output_rows(t, rate_hz):
        i = int(i)
        ti = float(t[i])
        ok_heave = settled is None or (_v(settled, i) or 0.0) >= 0.5
        for s in sents:
            if s == "HRM":
                h = _v(heel, i)
                k = resets.index(float(rs.reset_time[i]))
                fresh = bool(rs.valid[i])
                yield (
                    ti,
                    hrm_sentence(
                        h,
                        _v(rs.roll_period, i) if fresh else None,
                        _v(rs.amp_port, i) if fresh else None,
                        _v(rs.amp_stbd, i) if fresh else None,
                        valid=h is not None,
                        peak_port_deg=_v(rs.peak_port, i),
                        peak_stbd_deg=_v(rs.peak_stbd, i),
                        reset_utc=reset_dt[k],
                        talker=tk["HRM"],
                    ),
                )
            elif s == "XDR":
                r, p = _v(heel, i), _v(pitch, i)
                if r is not None or p is not None:
                    yield (
                        ti,
                        xdr_roll_pitch(
                            r,
                            p,
                            roll_id=xdr_roll_id,
                            pitch_id=xdr_pitch_id,
                            roll_sign=xdr_roll_sign,
                            pitch_sign=xdr_pitch_sign,
                            talker=tk["XDR"],
                        ),
                    )
            elif s == "HDG":
                sh = _v(hs.sensor, i)
                if sh is not None:
                    yield ti, hdg_sentence(sh, _v(hs.deviation, i), variation_deg, talker=tk["HDG"])
            elif s == "HDT":
                tr = _v(hs.true, i)
                if tr is not None:
                    yield ti, hdt_sentence(tr, talker=tk["HDT"])
            elif s == "THS":
                tr = _v(hs.true, i)
                mode = ths_mode if ths_mode != "auto" else ("S" if sim else "A")
                yield ti, ths_sentence(tr, mode=mode if tr is not None else "V", talker=tk["THS"])
            elif s == "ROT":
                r = _v(rot, i)
                yield ti, rot_sentence(r, valid=r is not None, talker=tk["ROT"])
            elif s == "PASHR":
                hv = _v(heave, i) if ok_heave else None
                sd = [_v(a, i) for a in stds]
                yield (
                    ti,
                    pashr_sentence(
                        None if off is None else ti + off,
                        _v(true_arr, i),
                        _v(heel, i),
                        _v(pitch, i),
                        hv,
                        sd[0],
                        sd[1],
                        sd[2] if _v(true_arr, i) is not None else None,
                        aiding=1 if gnss[i] else 0,
                        imu_status=1 if ok_heave else 0,
                    ),
                )
            elif s == "TSS1":
                hv, r, p = _v(heave, i), _v(heel, i), _v(pitch, i)
                if hv is None or r is None or p is None:
                    continue  # a fixed-length frame has no empty field: no frame rather than a made-up value
                q = "G" if gnss[i] else "U"
                yield ti, tss1_frame(hv, r, p, q if ok_heave else q.lower(), _v(hacc, i) or 0.0, _v(vacc, i) or 0.0)


def row_bytes(rec: Recording, sentences: list[str] | tuple[str, ...], sample_rows: int = 400, **kw: Any) -> int:
    """Largest number of bytes (with CR/LF) one output instant takes, over about ``sample_rows`` instants spread
    evenly over the whole recording (fields fill in as it goes: HRM's period and peak hold, ...), + 2 bytes a
    sentence of margin for wider numbers."""
    if rec.multi_clock:  # sentences on different clocks may fall on one instant: count them all together
        return sum(row_bytes(sub, ss, sample_rows, **kw) for _, sub, ss in clock_groups(rec, sentences))
    dur = float(rec.time[-1] - rec.time[0]) if len(rec) > 1 else 0.0
    probe = None if len(rec) <= sample_rows or dur <= 0 else sample_rows / dur
    per: dict[float, int] = {}
    count: dict[float, int] = {}
    for ti, s in nmea_lines(rec, sentences, probe, **{k: v for k, v in kw.items() if k != "card_from"}):
        per[ti] = per.get(ti, 0) + len(s) + 2
        count[ti] = count.get(ti, 0) + 1
    if not per:
        return 0
    k = max(per, key=lambda x: per[x])
    return int(per[k] + 2 * count[k])


def header_lines(
    *,
    source: str,
    sentences: list[str],
    plan: RatePlan | None,
    heading_ref: str,
    heading_source: str,
    heave_positive: str,
    card_from: str | None,
    deviation_deg: float | None,
    variation_deg: float | None,
    utc: str | None,
    talkers: dict[str, str],
    clocks: str | None = None,
) -> list[str]:
    """The ``#`` header block of an NMEA log written by imutool (conventions, flags, rate; read back as
    comments by imutool's reader)."""

    def ew(v: float | None) -> str:
        return "null (unknown)" if v is None else f"{abs(v):.1f}° {'E' if v >= 0 else 'W'}"

    lines = [
        f"imutool nmea from {source}",
        f"sentences: {','.join(sentences)}" + (f" at {plan.describe()}" if plan else ""),
        "angles deg; roll + starboard down; pitch + bow up; heading clockwise from north; ROT deg/min + to starboard",
        f"heave: m, positive {heave_positive.upper()} (--heave-positive {heave_positive}; TSS1 defines + up)",
    ]
    if clocks:
        lines.append(f"clocks (many-clock input: each sentence on its channel's own samples): {clocks}")
    if any(s in sentences for s in ("HDG", "HDT", "THS", "PASHR")):
        dev = f"card {card_from}" if card_from else ew(deviation_deg)
        lines.append(
            f"heading input: {heading_ref}; deviation {dev}; variation {ew(variation_deg)}; "
            f"source {heading_source} (HDT/THS/ROT talker {talkers.get('THS', '?')}, HDG talker "
            f"{talkers.get('HDG', '?')})"
        )
    lines.append(
        "UTC: "
        + (
            utc
            or "not known (no start time in the recording)"
            + (": PASHR time fields empty" if "PASHR" in sentences else "")
        )
    )
    if "PASHR" in sentences:
        lines.append(
            "PASHR: heave empty and IMU status 0 while the heave settles (settled = 0); aiding flag "
            "1 only with GNSS in the recording"
        )
    if "TSS1" in sentences:
        lines.append(
            "TSS1: status U/G unaided/GNSS-aided, lower case while settling; vertical acceleration from "
            "the heave rate, horizontal from accel x/y (00 without it)"
        )
    table = str.maketrans({"°": " deg", "≈": "~", "−": "-", "×": "x", "→": "->"})
    return [("# " + x).translate(table).encode("ascii", "replace").decode("ascii") for x in lines]


LINE_OPTIONS: dict[str, Any] = {
    k: p.default
    for k, p in inspect.signature(nmea_lines).parameters.items()
    if p.kind is inspect.Parameter.KEYWORD_ONLY
}  # nmea_lines' keyword options and their defaults (the one place they are written)
BAUD = 4800  # Bd: IEC 61162-1's line speed, the default an output must fit


@dataclass
class LogPlan:
    """What a log will hold before a line is written: the sentences, the rate plan, the UTC it states and its
    ``#`` header block."""

    sentences: list[str]
    rate: RatePlan
    utc: str | None
    header: list[str]
    clocks: str | None = None  # a many-clock input: which stream each sentence was taken on


def plan_log(
    rec: Recording,
    sentences: list[str] | tuple[str, ...],
    *,
    rate_hz: float | None = None,
    baud: int = BAUD,
    source: str = "",
    **kw: Any,
) -> LogPlan | None:
    """Plan a log of ``rec`` (not empty): the rate against ``baud`` (:func:`plan_rate`), the UTC of the first row
    (``utc_start``, else the recording's clock) and the header; None when no sentence could be written (the
    recording lacks the channels). ``kw`` as :func:`nmea_lines`, plus ``card_from`` (where the deviation card
    came from, for the header)."""
    sents = [s.strip().upper() for s in sentences if s.strip()]
    opts = {**LINE_OPTIONS, **kw}
    nb = row_bytes(rec, sents, **kw)
    if nb == 0:
        return None
    plan = plan_rate(nb, baud, rate_hz, input_rate(rec, sents))
    us = opts["utc_start"]
    off = us.timestamp() - float(rec.time[0]) if us is not None else utc_offset_s(rec)
    utc = (
        None
        if off is None
        else "recording time + offset, first row "
        + datetime.fromtimestamp(float(rec.time[0]) + off, tz=timezone.utc).isoformat().replace("+00:00", "Z")
    )
    src = opts["heading_source"]
    talkers = {"HDG": "HC", "THS": TRUE_TALKER[src], **(opts["talkers"] or {})}
    clocks = None
    if rec.multi_clock:
        clocks = "; ".join(f"{','.join(ss)} on {key or 'all rows'}" for key, _, ss in clock_groups(rec, sents))
    header = header_lines(
        source=source,
        sentences=sents,
        plan=plan,
        heading_ref=opts["heading_ref"],
        heading_source=src,
        heave_positive=opts["heave_positive"],
        card_from=kw.get("card_from"),
        deviation_deg=opts["deviation_deg"],
        variation_deg=opts["variation_deg"],
        utc=utc,
        talkers=talkers,
        clocks=clocks,
    )
    return LogPlan(sents, plan, utc, header, clocks)


def write_planned(
    rec: Recording,
    plan: LogPlan,
    path: str | os.PathLike | None,
    *,
    header: bool = True,
    time_prefix: bool = False,
    port: Any = None,
    realtime: bool = True,
    **kw: Any,
) -> dict[str, int]:
    """Write the lines of ``plan`` (CR/LF): to ``path`` (atomic; the header block first unless ``header`` is
    False; each line prefixed with its time in s with ``time_prefix``) and/or to ``port`` (an open serial port,
    paced by the recording's time stamps when ``realtime``). ``kw`` as :func:`nmea_lines`. Returns the count of
    each sentence type written, in order of first appearance."""
    gen = nmea_lines(rec, plan.sentences, plan.rate.rate_hz, **{k: v for k, v in kw.items() if k != "card_from"})
    counts: dict[str, int] = {}
    t_wall0 = time.monotonic()
    t_rec0 = None
    if path is not None:
        with atomic_path(path) as tmp, open(tmp, "w", encoding="ascii", newline="") as fh:
            if header:
                fh.write("".join(h + "\r\n" for h in plan.header))
            for ts, s in gen:
                fh.write((f"{ts:.3f} " if time_prefix else "") + s + "\r\n")
                k = sentence_kind(s)
                counts[k] = counts.get(k, 0) + 1
                if port is not None:
                    t_rec0 = ts if t_rec0 is None else t_rec0
                    send(port, s, ts - t_rec0, t_wall0, realtime)
    elif port is not None:
        for ts, s in gen:
            k = sentence_kind(s)
            counts[k] = counts.get(k, 0) + 1
            t_rec0 = ts if t_rec0 is None else t_rec0
            send(port, s, ts - t_rec0, t_wall0, realtime)
    return counts


def send(port: Any, sentence: str, t_rel: float, t_wall0: float, realtime: bool) -> None:
    """Write one sentence + CR/LF to ``port``; with ``realtime`` not before ``t_wall0 + t_rel`` (monotonic s)."""
    if realtime:
        wait = t_wall0 + t_rel - time.monotonic()
        if wait > 0:
            time.sleep(wait)
    port.write((sentence + "\r\n").encode("ascii"))


def open_port(name: str, baud: int) -> Any:
    """An open serial port (pyserial, imported here: an optional dependency only this output needs)."""
    import serial

    try:
        return serial.Serial(name, baudrate=baud, timeout=1, write_timeout=5)
    except (serial.SerialException, OSError) as e:
        raise ImutoolError(f"cannot open serial port: {e}", path=name) from None


def _written(plan: LogPlan, counts: dict[str, int]) -> dict[str, Any]:
    """The summary's part on what was written: sentences per type, total, the rate (Hz; chosen how) and the line
    use against the baud rate (bytes/s)."""
    return {
        "sentences": counts,
        "total": int(sum(counts.values())),
        "rate_hz": plan.rate.rate_hz,
        "rate_chosen": plan.rate.chosen,
        "bytes_per_s": round(plan.rate.bytes_per_s, 1),
        "line_bytes_per_s": plan.rate.capacity_bytes_per_s,
    }


def write_log(
    rec: Recording,
    path: str,
    sentences: list[str] | tuple[str, ...],
    *,
    rate_hz: float | None = None,
    baud: int = BAUD,
    source: str = "",
    header: bool = True,
    time_prefix: bool = False,
    **kw: Any,
) -> dict[str, Any]:
    """Plan the rate against ``baud`` (:func:`plan_log`), then write the '#' header block and the sentences
    (CR/LF, atomic) to ``path`` (:func:`write_planned`). ``kw`` as :func:`nmea_lines`. Returns counts, rate and
    line use."""
    sents = [s.strip().upper() for s in sentences if s.strip()]
    if len(rec) == 0:
        raise ImutoolError("the recording has no rows", path=path)
    href, why = heading_reference(rec, kw.get("heading_ref", LINE_OPTIONS["heading_ref"]))
    kw["heading_ref"] = href
    plan = plan_log(rec, sents, rate_hz=rate_hz, baud=baud, source=source, **kw)
    if plan is None:
        raise ImutoolError(
            f"no sentence could be written: the recording lacks the channels for {','.join(sents)} "
            f"(has {', '.join(rec.channels)})",
            path=path,
        )
    counts = write_planned(rec, plan, path, header=header, time_prefix=time_prefix, **kw)
    return {
        "path": path,
        **_written(plan, counts),
        "baud": baud,
        "heave_positive": kw.get("heave_positive", LINE_OPTIONS["heave_positive"]),
        "heading_reference": {"reference": href, "why": why},
        "utc": plan.utc,
    }


def run_nmea(
    source: str | os.PathLike | Recording,
    output: str | os.PathLike | None = None,
    *,
    sentences: str | list[str] | tuple[str, ...] = "HRM,XDR",
    rate_hz: float | None = None,
    serial_port: str | None = None,
    baud: int = BAUD,
    realtime: bool = True,
    time_prefix: bool = False,
    header: bool = True,
    strict: bool = False,
    on_input: OnInput | None = None,
    **options: Any,
) -> RouteResult:
    """IEC 61162-1 sentences and TSS1 frames of ``source`` (a path or a Recording) to the log ``output`` and/or
    the serial port ``serial_port`` (paced by the time stamps when ``realtime``): the route behind ``imutool
    nmea`` and ``imutool batch nmea``.

    ``sentences`` (a comma list or a sequence of :data:`SENTENCES`) at ``rate_hz`` (default: the highest standard
    rate that fits ``baud``); ``header``: the '#' block of conventions first; ``time_prefix``: each line starts
    with its time (s). ``options``: those of :func:`nmea_lines` (:data:`LINE_OPTIONS`: heading_ref,
    heading_source, deviation_deg, variation_deg, ths_mode, heave_positive, xdr_*, talkers, roll_kw, utc_start
    ...) and, for a path, how to load it (columns, ..., calibration_file: its [deviation] card gives HDG's
    deviation). Returns the summary: sentences written per type, rate, line use, UTC, deviation.
    """
    if output is None and serial_port is None:
        raise ImutoolError("give -o OUTPUT.nmea and/or --serial PORT")
    kw = {k: options.pop(k) for k in list(options) if k in LINE_OPTIONS}
    unknown = set(options) - set(LOAD_OPTIONS)
    if unknown:
        raise TypeError(f"run_nmea() got unexpected keyword argument(s) {', '.join(sorted(unknown))}")
    inputs: list[dict[str, Any]] = []
    rec, name, _ = read_source(source, inputs, strict=strict, on_input=on_input, **options)
    card = None
    card_from = None
    if options.get("calibration_file"):
        card = load_calibration(options["calibration_file"]).deviation
        card_from = options["calibration_file"] if card is not None else None
    if card is not None and kw.get("deviation_deg") is not None:
        raise ImutoolError("--deviation and a --calibration with a [deviation] card: give one of them")
    if card is not None:
        kw["card"] = card
    names = sentences.split(",") if isinstance(sentences, str) else list(sentences)
    listed = sentences if isinstance(sentences, str) else ",".join(sentences)
    sents = [x.strip().upper() for x in names if x.strip()]
    if len(rec) == 0:
        raise ImutoolError("the recording has no rows", path=name)
    href, why = heading_reference(rec, kw.get("heading_ref", LINE_OPTIONS["heading_ref"]))
    kw["heading_ref"] = href
    plan = plan_log(rec, sents, rate_hz=rate_hz, baud=baud, source=name, card_from=card_from, **kw)
    if plan is None:
        raise ImutoolError("no sentence written: the input lacks the channels for " + listed, path=name)
    port = open_port(serial_port, baud) if serial_port else None
    try:
        counts = write_planned(
            rec,
            plan,
            None if output is None else os.fspath(output),
            header=header,
            time_prefix=time_prefix,
            port=port,
            realtime=realtime,
            **kw,
        )
    finally:
        if port is not None:
            port.flush()
            port.close()
    if not counts:
        raise ImutoolError("no sentence written: the input lacks the channels for " + listed, path=name)
    deviation = kw.get("deviation_deg", LINE_OPTIONS["deviation_deg"])
    summary = {
        "input": name,
        "output": None if output is None else os.fspath(output),
        "serial": serial_port,
        "baud": baud,
        **_written(plan, counts),
        "heave_positive": kw.get("heave_positive", LINE_OPTIONS["heave_positive"]),
        "heading_reference": {"reference": href, "why": why},
        "utc": plan.utc,
        **({"clocks": plan.clocks} if plan.clocks else {}),
        "deviation": card_from or deviation,
        "generated_utc": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }
    if "HRM" in counts:
        summary.update(hrm_period_check(rec, kw.get("roll_kw")))
    return RouteResult(summary, inputs, data={"plan": plan})


def hrm_period_check(rec: Recording, roll_kw: dict | None) -> dict[str, Any]:
    """The three roll period estimates of the heel HRM's periods come from (:func:`imutool.roll.roll_stats` with
    the same settings) and, when they disagree, the warning: ``{"hrm_period_estimates": ..., "warnings": [...]}``."""
    from imutool.roll import roll_stats

    heel, _ = _ch(rec, ("heel", "roll"), "deg")
    kw = {k: v for k, v in (roll_kw or {}).items() if k not in ("resets_s", "utc_start")}
    rs = roll_stats(rec.time, heel, **kw)
    return {"hrm_period_estimates": rs.periods, "warnings": [f"HRM roll period: {w}" for w in rs.warnings]}


def sentence_kind(s: str) -> str:
    """Type of an output line: 'HRM', 'PASHR', 'TSS1'."""
    if s.startswith(":"):
        return "TSS1"
    addr = s[1:].split(",", 1)[0]
    return "P" + addr[1:] if addr.startswith("P") else addr[2:]
