"""NMEA 0183 / IEC 61162-1 sentences: checksum, framing, decoding, writing, and whole-log reading.

The package: :mod:`.framing` (the checksum — imutool's one implementation — framing and the errors),
:mod:`.motion` (the motion sensors' proprietary sentences and the TSS1 frame), :mod:`.em3000` (Kongsberg's
binary attitude frames), and this module (standard sentences, writers, whole logs). Every public name is
importable from ``formats.nmea``.

Units and signs at this surface (docs/nmea.md, standards.md §2):

- angles in degrees; heading clockwise from north in [0, 360); rate of turn in deg/min (+ = bow to starboard);
- roll (= heel) positive **starboard down**, pitch positive **bow up**, heave in metres positive **up**;
- HRM: heel + = starboard, port/starboard amplitudes and peak-hold values sent as positive numbers.

Framing (``$``/``!`` + address + fields + ``*hh``) and checksums are done in :mod:`.framing`; field decoding
uses pynmea2's sentence classes where pynmea2 has the type (HDT, HDG, HDM, ROT, XDR; the field layouts of PASHR,
PSXN, PRDID and PTNL,AVR are pynmea2's) and classes defined here, registered with pynmea2, where it lacks them
(HRM, THS); SkyTraq ``$PSTI,036`` is decoded here, the motion sensors' sentences in :mod:`.motion`. One decoder
per sentence type.
"""

from __future__ import annotations

import dataclasses
import heapq
import math
import os
import re
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from datetime import datetime, timezone
from typing import Any

import numpy as np
from pynmea2 import TalkerSentence

from ..atomic import atomic_path
from ..columns import load_profile
from ..errors import ImutoolError
from ..recording import Recording
from ..timing import stream_timing
from . import gnss, motion
from .em3000 import em3000_frame, read_em3000, scan_frames
from .framing import (
    _ADDR_RE,
    CHECKSUM_POLICIES,
    MAX_SENTENCE_LENGTH,
    NmeaChecksumError,
    NmeaFieldError,
    NmeaParseError,
    NmeaSentence,
    NmeaUnsupportedError,
    _num,
    checksum,
    checksum_value,
    parse_sentence,
)
from .motion import (
    HEAVE_SIGNS,
    TSS1_LENGTH,
    TSS1_STATUS,
    MotionOptions,
    decode_tss1,
    euler_roll_to_tss,
    parse_tss1,
    tss1_frame,
    tss_roll_to_euler,
)

__all__ = [
    "NmeaSentence",
    "NmeaParseError",
    "NmeaChecksumError",
    "NmeaUnsupportedError",
    "NmeaFieldError",
    "XdrMapping",
    "DEFAULT_XDR_MAP",
    "SUPPORTED_TYPES",
    "MAX_SENTENCE_LENGTH",
    "checksum",
    "checksum_value",
    "format_sentence",
    "hrm_sentence",
    "xdr_sentence",
    "xdr_roll_pitch",
    "hdg_sentence",
    "hdt_sentence",
    "ths_sentence",
    "rot_sentence",
    "pashr_sentence",
    "tss1_frame",
    "parse_tss1",
    "decode_tss1",
    "tss_roll_to_euler",
    "euler_roll_to_tss",
    "MotionOptions",
    "HEAVE_SIGNS",
    "TSS1_LENGTH",
    "TSS1_STATUS",
    "read_em3000",
    "em3000_frame",
    "scan_frames",
    "sentence_summary",
    "utc_offset_s",
    "parse_sentence",
    "decode",
    "decode_checked",
    "decode_fast",
    "read_nmea",
    "write_nmea",
    "iter_sentences",
]

TIME_SOURCES = ("auto", "stamp", "nmea", "index")
THS_MODES = "AEMSV"  # autonomous, estimated (DR), manual, simulator, not valid
_RESERVED = set("$!*,\\^~\r\n")


# -- pynmea2 types it lacks (standards.md §2.2, §2.4) -----------------------------------------------------------
class HRM(TalkerSentence):
    """IEC 61162-1 HRM: heel angle, roll period and roll amplitude (standards.md §2.2)."""

    fields = (
        ("Actual heel angle (deg, + starboard)", "heel", float),
        ("Roll period (s)", "roll_period", float),
        ("Roll amplitude port (deg, positive)", "amp_port", float),
        ("Roll amplitude starboard (deg)", "amp_stbd", float),
        ("Status A/V", "status"),
        ("Roll peak hold port (deg)", "peak_port", float),
        ("Roll peak hold starboard (deg)", "peak_stbd", float),
        ("Peak hold reset time UTC hhmmss", "reset_time"),
        ("Peak hold reset day", "reset_day", int),
        ("Peak hold reset month", "reset_month", int),
    )


class THS(TalkerSentence):
    """IEC 61162-1 THS: true heading and status (mode A/E/M/S/V; standards.md §2.4)."""

    fields = (
        ("Heading (deg true)", "heading", float),
        ("Mode indicator", "mode"),
    )


# -- decoding -------------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class XdrMapping:
    """One XDR transducer ID → imutool quantity ('roll' or 'pitch') with a sign (+1 or −1)."""

    quantity: str
    sign: float = 1.0


# Transducer IDs are not standardised (standards.md §2.3). Keys are compared upper-case with spaces kept.
DEFAULT_XDR_MAP: dict[str, XdrMapping] = {
    "ROLL": XdrMapping("roll"),
    "HEEL": XdrMapping("roll"),
    "HEEL ANGLE": XdrMapping("roll"),
    "PTCH": XdrMapping("pitch"),
    "PITCH": XdrMapping("pitch"),
    "TRIM": XdrMapping("pitch"),  # NMEA 0183 v4.11 XDR table lists "Trim" as an angular displacement id
}


def _normalise_xdr_map(xdr_map: dict[str, Any] | None) -> dict[str, XdrMapping]:
    """Accept {id: XdrMapping | 'roll' | '-roll' | ('roll', -1)}. A map given replaces the defaults entirely
    (the map used is exactly the map given, and is recorded in the Recording's meta)."""
    if xdr_map is None:
        return DEFAULT_XDR_MAP
    if all(
        isinstance(v, XdrMapping) and k == k.strip().upper() and v.quantity in XDR_QUANTITIES and v.sign in (1.0, -1.0)
        for k, v in xdr_map.items()
    ):
        return xdr_map  # already normalised (read_nmea normalises once per file)
    out: dict[str, XdrMapping] = {}
    for k, v in xdr_map.items():
        if isinstance(v, XdrMapping):
            m = v
        elif isinstance(v, str):
            q = v.strip()
            sign = -1.0 if q.startswith("-") else 1.0
            m = XdrMapping(q.lstrip("+-"), sign)
        else:
            q, sign = v
            m = XdrMapping(str(q), float(sign))
        if m.quantity not in XDR_QUANTITIES or m.sign not in (1.0, -1.0):
            raise ImutoolError(f"XDR map {k!r}: quantity must be one of {', '.join(XDR_QUANTITIES)} with sign ±1")
        out[str(k).strip().upper()] = m
    return out


XDR_QUANTITIES = ("roll", "pitch", "heave")


def _ew(value: float | None, letter: str | None, what: str, stype: str) -> float | None:
    if value is None:
        return None
    letter = (letter or "").strip().upper()
    if letter == "E":
        return value
    if letter == "W":
        return -value
    raise NmeaFieldError(f"{stype}: {what} direction {letter!r} is not E or W", sentence_type=stype)


def _dec_hdt(s: NmeaSentence, xmap: dict[str, XdrMapping], problems: list[str]) -> dict[str, float]:
    h = _num(s.fields[0] if s.fields else None, "heading", "HDT")
    return {} if h is None else {"heading_true": h}


def _dec_hdm(s: NmeaSentence, xmap: dict[str, XdrMapping], problems: list[str]) -> dict[str, float]:
    h = _num(s.fields[0] if s.fields else None, "heading", "HDM")
    return {} if h is None else {"heading_mag": h}


def _dec_hdg(s: NmeaSentence, xmap: dict[str, XdrMapping], problems: list[str]) -> dict[str, float]:
    """HDG: magnetic = sensor + deviation (E +); true = magnetic + variation (E +). Null fields = unknown."""
    d = s.fields + [""] * (5 - len(s.fields))
    h = _num(d[0], "heading", "HDG")
    dev = _ew(_num(d[1], "deviation", "HDG"), d[2], "deviation", "HDG")
    var = _ew(_num(d[3], "variation", "HDG"), d[4], "variation", "HDG")
    out: dict[str, float] = {}
    if h is not None:
        out["heading_sensor"] = h
    if dev is not None:
        out["deviation"] = dev
    if var is not None:
        out["variation"] = var
    if h is not None and dev is not None:
        out["heading_mag"] = (h + dev) % 360.0
        if var is not None:
            out["heading_true"] = (h + dev + var) % 360.0
    return out


def _dec_rot(s: NmeaSentence, xmap: dict[str, XdrMapping], problems: list[str]) -> dict[str, float]:
    """ROT: deg/min, negative = bow turns to port; status V (invalid) drops the value."""
    r = _num(s.fields[0] if s.fields else None, "rate of turn", "ROT")
    status = (s.fields[1] if len(s.fields) > 1 else "").strip().upper()
    if r is None or status == "V":
        return {}
    return {"rot": r}


def _dec_ths(s: NmeaSentence, xmap: dict[str, XdrMapping], problems: list[str]) -> dict[str, float]:
    """THS: true heading + mode. ``ths_mode`` is the mode letter's code point (chr(int(v)) gives it back);
    mode V (not valid) drops the heading."""
    d = s.fields + [""] * (2 - len(s.fields))
    h = _num(d[0], "heading", "THS")
    mode = d[1].strip().upper()
    if mode and (len(mode) != 1 or mode not in THS_MODES):
        raise NmeaFieldError(f"THS: mode {mode[:8]!r} is not one of {THS_MODES}", sentence_type="THS")
    out: dict[str, float] = {}
    if mode:
        out["ths_mode"] = float(ord(mode))
    if h is not None and mode != "V":
        out["heading_true"] = h
    return out


def _dec_xdr(s: NmeaSentence, xmap: dict[str, XdrMapping], problems: list[str]) -> dict[str, float]:
    """XDR: groups of (type, value, unit, id); angular groups (type A, unit D or empty) whose id is in the map
    become roll/pitch with the mapped sign (heave: type D, unit M). Unmapped ids are ignored.

    A field count that is not a multiple of 4 (some devices emit a stray field, e.g. ``C,C,10.7,C,AIRTEMP``)
    is re-aligned on the mapped ids (type, value, unit precede the id) and noted in ``problems``; a non-numeric
    value of a mapped group (``-1.-3``) is noted in ``problems`` and skipped, other groups still decode.
    """
    f = s.fields
    if len(f) % 4 == 0:  # the layout of pynmea2's XDR.get_transducer(i), without building the object
        groups = [tuple(f[i : i + 4]) for i in range(0, len(f), 4)]
    else:
        groups = [tuple(f[j - 3 : j + 1]) for j in range(3, len(f)) if f[j].strip().upper() in xmap]
        problems.append(f"XDR: {len(f)} fields is not a multiple of 4; groups re-aligned on transducer ids")
    out: dict[str, float] = {}
    for ttype, value, unit, tid in groups:
        key = (tid or "").strip().upper()
        mp = xmap.get(key)
        if mp is None:
            continue
        ttype = (ttype or "").strip().upper()
        unit = (unit or "").strip().upper()
        if mp.quantity in ("roll", "pitch") and (ttype != "A" or unit not in ("D", "")):
            problems.append(f"XDR: transducer {key} is type {ttype!r} unit {unit!r}, not an angle in degrees")
            continue
        if mp.quantity == "heave" and (ttype != "D" or unit not in ("M", "")):
            problems.append(f"XDR: transducer {key} is type {ttype!r} unit {unit!r}, not a displacement in m")
            continue
        try:
            v = _num(value, f"transducer {key}", "XDR")
        except NmeaFieldError as e:
            problems.append(str(e))
            continue
        if v is not None:
            out[mp.quantity] = mp.sign * v
    return out


def _dec_psti(s: NmeaSentence, xmap: dict[str, XdrMapping], problems: list[str]) -> dict[str, float]:
    """SkyTraq $PSTI,036 (dual-antenna attitude): time, date, true heading, pitch, roll (deg, as transmitted:
    the antenna baseline's angles), mode (N = not valid drops the values). Other $PSTI variants: unsupported."""
    f = list(s.fields) + [""] * 7
    if f[0].strip() != "036":
        raise NmeaUnsupportedError(f"PSTI,{f[0][:4]}: only PSTI,036 (attitude) is decoded", sentence_type="PSTI")
    if f[6].strip().upper() == "N":
        return {}
    out: dict[str, float] = {}
    for idx, key in ((3, "heading_true"), (4, "pitch"), (5, "roll")):
        v = _num(f[idx], key, "PSTI")
        if v is not None:
            out[key] = v
    return out


def _dec_hrm(s: NmeaSentence, xmap: dict[str, XdrMapping], problems: list[str]) -> dict[str, float]:
    """HRM (standards.md §2.2): status V drops the heel/period/amplitude values (peak hold kept)."""
    d = s.fields + [""] * (10 - len(s.fields))
    vals = {
        k: _num(d[i], k, "HRM")
        for i, k in (
            (0, "heel"),
            (1, "roll_period"),
            (2, "amp_port"),
            (3, "amp_stbd"),
            (5, "peak_port"),
            (6, "peak_stbd"),
        )
    }
    status = d[4].strip().upper()
    if status not in ("A", "V", ""):
        raise NmeaFieldError(f"HRM: status {status[:8]!r} is not A or V", sentence_type="HRM")
    out: dict[str, float] = {}
    for k, v in vals.items():
        if v is None:
            continue
        if status == "V" and k in ("heel", "roll_period", "amp_port", "amp_stbd"):
            continue
        out[k] = v
    rt = d[7].strip()
    if rt:
        if not re.fullmatch(r"\d{6}(\.\d*)?", rt):
            raise NmeaFieldError(f"HRM: reset time {rt[:12]!r} is not hhmmss", sentence_type="HRM")
        hh, mm, ss = int(rt[:2]), int(rt[2:4]), float(rt[4:])
        out["peak_reset_time"] = hh * 3600.0 + mm * 60.0 + ss
    day = _num(d[8], "reset day", "HRM")
    mon = _num(d[9], "reset month", "HRM")
    if day is not None:
        out["peak_reset_day"] = day
    if mon is not None:
        out["peak_reset_month"] = mon
    return out


_KNOT = 1852.0 / 3600.0  # m/s per knot


def _dec_rmc(s: NmeaSentence, xmap: dict[str, XdrMapping], problems: list[str]) -> dict[str, float]:
    """RMC: speed over ground (knots → ``sog`` m/s) and course over ground (``cog``, deg true). Status V (void)
    or FAA mode N (not valid) drops both; empty fields are unknown."""
    d = list(s.fields) + [""] * (12 - len(s.fields))
    status = d[1].strip().upper()
    mode = d[11].strip().upper()[:1]
    if status == "V" or mode == "N":
        return {}
    sog = _num(d[6], "speed over ground", "RMC")
    cog = _num(d[7], "course over ground", "RMC")
    out: dict[str, float] = {}
    if sog is not None:
        out["sog"] = sog * _KNOT
    if cog is not None:
        out["cog"] = cog % 360.0
    return out


def _dec_vtg(s: NmeaSentence, xmap: dict[str, XdrMapping], problems: list[str]) -> dict[str, float]:
    """VTG: course (deg true → ``cog``) and speed over ground (knots, else km/h → ``sog`` m/s). Handles the
    NMEA 2.3+ layout (``cog,T,cogm,M,kn,N,kmh,K[,mode]``) and the old one without unit letters; mode N drops."""
    f = [x.strip() for x in s.fields]
    if len(f) >= 2 and f[1].upper() == "T":
        d = f + [""] * (9 - len(f))
        cog_s, kn_s, kmh_s, mode = d[0], d[4], d[6], d[8].upper()[:1]
    else:  # pre-2.3: cog true, cog magnetic, knots, km/h
        d = f + [""] * (4 - len(f))
        cog_s, kn_s, kmh_s, mode = d[0], d[2], d[3], ""
    if mode == "N":
        return {}
    out: dict[str, float] = {}
    cog = _num(cog_s, "course over ground", "VTG")
    kn = _num(kn_s, "speed (knots)", "VTG")
    if kn is not None:
        out["sog"] = kn * _KNOT
    else:
        kmh = _num(kmh_s, "speed (km/h)", "VTG")
        if kmh is not None:
            out["sog"] = kmh / 3.6
    if cog is not None:
        out["cog"] = cog % 360.0
    return out


_DECODERS: dict[str, Callable[[NmeaSentence, dict[str, XdrMapping], list[str]], dict[str, float]]] = {
    "HDT": _dec_hdt,
    "HDM": _dec_hdm,
    "HDG": _dec_hdg,
    "ROT": _dec_rot,
    "THS": _dec_ths,
    "XDR": _dec_xdr,
    "HRM": _dec_hrm,
    "PSTI": _dec_psti,
    "RMC": _dec_rmc,
    "VTG": _dec_vtg,
}
# decoders that take the per-device settings: the motion sensors' sentences and the GNSS heights (GGA, GST)
_OPT_DECODERS = {**motion.DECODERS, **gnss.DECODERS}
SUPPORTED_TYPES = tuple(_DECODERS) + tuple(_OPT_DECODERS)


def decode(
    sentence: NmeaSentence | str, xdr_map: dict[str, Any] | None = None, options: MotionOptions | None = None
) -> dict[str, float]:
    """Named values of one sentence (degrees, deg/min, metres, seconds; signs as in the module docstring).

    Keys: heading_true, heading_mag, heading_sensor, deviation, variation (E +), rot, roll, pitch, heave, heel,
    roll_period, amp_port, amp_stbd, peak_port, peak_stbd, peak_reset_time (s of day), peak_reset_day,
    peak_reset_month, ths_mode (code point of the letter), sog (m/s, RMC/VTG), cog (deg true, RMC/VTG), and
    the motion sentences' keys (:data:`formats.nmea.motion.CHANNELS`: rates, surge/sway, σ, status channels).
    Only values present in the sentence are returned. ``options``: the per-device settings of the motion
    sentences (PASHR heave sign, TSS rolls; :class:`MotionOptions`, default heave + up, TSS1 roll converted).
    Raises NmeaUnsupportedError for other types and NmeaFieldError for a non-numeric value field (XDR: only
    when no mapped group decoded; see :func:`decode_checked` for the partial case).
    """
    values, problems = decode_checked(sentence, xdr_map, options)
    if problems and not values:
        raise NmeaFieldError(problems[0], sentence_type=sentence.type if isinstance(sentence, NmeaSentence) else None)
    return values


def decode_checked(
    sentence: NmeaSentence | str, xdr_map: dict[str, Any] | None = None, options: MotionOptions | None = None
) -> tuple[dict[str, float], list[str]]:
    """Like :func:`decode`, but returns (values, problems) where problems lists what was skipped (XDR)."""
    if isinstance(sentence, str):
        sentence = parse_sentence(sentence)
    return _decode_with(sentence, _normalise_xdr_map(xdr_map), options or motion.DEFAULT_OPTIONS)


def _decode_with(
    sentence: NmeaSentence, xmap: dict[str, XdrMapping], opts: MotionOptions = motion.DEFAULT_OPTIONS
) -> tuple[dict[str, float], list[str]]:
    problems: list[str] = []
    fn = _DECODERS.get(sentence.type)
    if fn is not None:
        return fn(sentence, xmap, problems), problems
    mfn = _OPT_DECODERS.get(sentence.type)
    if mfn is None:
        key = motion.count_key(sentence)
        raise NmeaUnsupportedError(f"sentence type {key} is not decoded", sentence_type=key)
    return mfn(sentence, opts, problems), problems


# -- fast path (live capture) -------------------------------------------------------------------------------------
# decode_fast() gives the same values as decode(parse_sentence(line)) for the common case — a well-formed
# sentence with a correct upper-case checksum that decodes cleanly — with plain str operations and no pynmea2
# objects. For anything else it returns None and the caller takes the full path, which does the error reporting.
_ADDR_TYPES: dict[str, str | None] = {}  # address field → sentence type (None: not a valid address)


def _addr_type(addr: str) -> str | None:
    t = _ADDR_TYPES.get(addr, "")
    if t == "":
        t = ("P" + addr[1:] if addr[0] == "P" else addr[2:]) if _ADDR_RE.match(addr) else None
        if len(_ADDR_TYPES) < 4096:  # garbage addresses must not grow the cache without bound
            _ADDR_TYPES[addr] = t
    return t


def decode_fast(line: str, xdr_map: dict[str, Any] | None = None) -> dict[str, float] | None:
    """``decode(parse_sentence(line))`` for a clean sentence, fast; None when the full path must decide.

    Returns the same dict as :func:`decode` when ``line`` is ``$`` + valid address + fields + ``*HH`` (correct,
    upper-case checksum; no surrounding whitespace), every character printable ASCII, and the decoder finds
    nothing to complain about — such a sentence is accepted under every checksum policy. Returns None for
    anything else (bad or missing checksum, '!' sentences, unsupported types, bad fields, XDR problems...):
    the caller then runs :func:`parse_sentence` and :func:`decode`, which raise the usual errors. The values
    come from the very decoders :func:`decode` uses; only the general framing work is skipped.
    """
    n = len(line)
    if n < 7 or line[0] != "$" or line[-3] != "*":
        return None
    body = line[1:-3]
    if (
        checksum(body) != line[-2:]
        or not (body.isascii() and body.isprintable())
        or "$" in body
        or "!" in body
        or "*" in body
    ):
        return None
    f = body.split(",")
    if len(f) < 2:
        return None
    addr = f[0]
    stype = _addr_type(addr)
    if stype is None:
        return None
    fn = _DECODERS.get(stype)
    mfn = _OPT_DECODERS.get(stype) if fn is None else None
    if fn is None and mfn is None:
        return None
    xmap = DEFAULT_XDR_MAP if xdr_map is None else _normalise_xdr_map(xdr_map)
    del f[0]
    talker, formatter = ("P", addr[1:]) if addr[0] == "P" else (addr[:2], addr[2:])
    s = NmeaSentence(talker, formatter, f, True, line)
    problems: list[str] = []
    try:  # the same decoders as decode(): only the framing checks are skipped
        values = fn(s, xmap, problems) if fn is not None else mfn(s, motion.DEFAULT_OPTIONS, problems)
    except Exception:  # NmeaFieldError, NmeaUnsupportedError...: the full path reports it
        return None
    return None if problems else values  # anything the decoder notes (XDR) is left to the full path


# -- writing single sentences -------------------------------------------------------------------------------------
def _fmt(v: Any, d: int | None) -> str:
    if type(v) is float or type(v) is np.float64:  # the usual field: straight to the number's text
        x = float(v)
    elif v is None:
        return ""
    elif isinstance(v, str):
        return v
    elif isinstance(v, (bool, np.bool_)):
        return "A" if v else "V"
    elif isinstance(v, (int, np.integer)):
        return str(int(v))
    else:
        x = float(v)
    if not math.isfinite(x):
        return ""
    if d is None:
        s = f"{x:.6f}".rstrip("0")
        s = s + "0" if s.endswith(".") else s
    else:
        s = f"{x:.{d}f}"
    if s.startswith("-") and float(s) == 0.0:
        s = s[1:]
    return s


def format_sentence(
    talker: str,
    formatter: str,
    fields: Sequence[str | float | int | None],
    decimals: int | Sequence[int | None] | None = None,
) -> str:
    """``$TTFFF,f1,f2,...*HH`` (no CR/LF). None/NaN → empty field; floats with ``decimals`` places (one int for
    all or one per field; None → up to 6 places, trailing zeros trimmed). Raises ImutoolError if a field holds a
    reserved character or the sentence would exceed 82 characters including CR/LF."""
    addr = f"{talker}{formatter}"
    if not (_ADDR_RE.match(addr)):
        raise ImutoolError(f"bad NMEA address {addr!r} (talker 2 characters + 3-letter formatter, or P...)")
    if decimals is None or isinstance(decimals, int):
        decs: list[int | None] = [decimals] * len(fields)  # type: ignore[list-item]
    else:
        decs = list(decimals)
        if len(decs) != len(fields):
            raise ImutoolError(f"{addr}: {len(decs)} decimals for {len(fields)} fields")
    parts = [_fmt(v, d) for v, d in zip(fields, decs, strict=True)]
    for v, p in zip(fields, parts, strict=True):  # a number's text is digits, '.' and '-': only text is checked
        if isinstance(v, str) and any(c in _RESERVED or not (" " <= c <= "~") for c in p):
            raise ImutoolError(f"{addr}: field {p[:20]!r} holds a reserved or non-printable character")
    body = ",".join([addr] + parts)
    out = f"${body}*{checksum(body)}"
    if len(out) + 2 > MAX_SENTENCE_LENGTH:
        raise ImutoolError(f"{addr}: sentence is {len(out) + 2} characters with CR/LF (limit 82)")
    return out


def _wrap360(h: float | None, decimals: int = 1) -> float | None:
    """A heading (deg) in [0, 360) as it will be printed with ``decimals``: wrapped, and 0 where it would print as
    360 (359.96 with one decimal; 359.996 with two — not 359.97, which prints as itself)."""
    if h is None or not math.isfinite(h):
        return None
    w = math.fmod(h, 360.0)
    w = w + 360.0 if w < 0 else w
    return 0.0 if round(w, decimals) >= 360.0 else w


def _absnone(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(v) else abs(v)


def hrm_sentence(
    heel_deg: float | None,
    period_s: float | None,
    amp_port_deg: float | None,
    amp_stbd_deg: float | None,
    valid: bool,
    peak_port_deg: float | None = None,
    peak_stbd_deg: float | None = None,
    reset_utc: datetime | None = None,
    talker: str = "II",
) -> str:
    """HRM (standards.md §2.2): heel + = starboard (deg), roll period (s), port and starboard amplitudes and
    peak-hold values sent positive (deg; a negative port value is taken by magnitude), status A/V, peak-hold
    reset time UTC as ``hhmmss`` (no fraction), day, month (no year). Naive datetimes are taken as UTC."""
    if reset_utc is not None:
        if reset_utc.tzinfo is not None:
            reset_utc = reset_utc.astimezone(timezone.utc)
        rt, rd, rm = reset_utc.strftime("%H%M%S"), f"{reset_utc.day:02d}", f"{reset_utc.month:02d}"
    else:
        rt = rd = rm = None
    fields = [
        heel_deg,
        period_s,
        _absnone(amp_port_deg),
        _absnone(amp_stbd_deg),
        "A" if valid else "V",
        _absnone(peak_port_deg),
        _absnone(peak_stbd_deg),
        rt,
        rd,
        rm,
    ]
    return format_sentence(talker, "HRM", fields, [1, 1, 1, 1, None, 1, 1, None, None, None])


def xdr_sentence(
    measurements: Sequence[tuple[str, float | None, str, str]], talker: str = "YX", decimals: int = 1
) -> str:
    """XDR with one group (type, value, unit, id) per measurement, e.g. ('A', -1.2, 'D', 'PTCH')."""
    fields: list[Any] = []
    decs: list[int | None] = []
    for m in measurements:
        if len(m) != 4:
            raise ImutoolError(f"XDR measurement {m!r}: need (type, value, unit, id)")
        fields.extend(m)
        decs.extend([None, decimals, None, None])
    return format_sentence(talker, "XDR", fields, decs)


def xdr_roll_pitch(
    roll_deg: float | None,
    pitch_deg: float | None,
    roll_id: str = "ROLL",
    pitch_id: str = "PTCH",
    roll_sign: int = 1,
    pitch_sign: int = 1,
    talker: str = "YX",
    decimals: int = 1,
) -> str:
    """XDR pitch + roll angular groups (Airmar layout: PTCH first, roll + starboard down, pitch + bow up),
    each multiplied by its sign (use −1 for a receiver with the opposite convention)."""

    def sg(v: float | None, s: int) -> float | None:
        return None if v is None else s * v

    return xdr_sentence(
        [("A", sg(pitch_deg, pitch_sign), "D", pitch_id), ("A", sg(roll_deg, roll_sign), "D", roll_id)],
        talker=talker,
        decimals=decimals,
    )


def _ew_fields(v: float | None) -> tuple[float | None, str | None]:
    if v is None or not math.isfinite(v):
        return None, None
    return abs(v), ("E" if v >= 0 else "W")


def hdg_sentence(
    sensor_heading_deg: float | None,
    deviation_deg: float | None = None,
    variation_deg: float | None = None,
    talker: str = "HC",
) -> str:
    """HDG: magnetic sensor heading (deg), deviation and variation with E/W (E positive; null when unknown).
    Magnetic heading = sensor + E deviation; true = magnetic + E variation."""
    dv, dd = _ew_fields(deviation_deg)
    vv, vd = _ew_fields(variation_deg)
    return format_sentence(talker, "HDG", [_wrap360(sensor_heading_deg), dv, dd, vv, vd], [1, 1, None, 1, None])


def hdt_sentence(heading_deg: float | None, talker: str = "HE") -> str:
    """HDT: true heading (deg) — still current, but THS carries validity and is preferred."""
    return format_sentence(talker, "HDT", [_wrap360(heading_deg), "T"], [1, None])


def ths_sentence(heading_deg: float | None, mode: str = "A", talker: str = "HE") -> str:
    """THS: true heading (deg) + mode A/E/M/S/V (a missing heading forces V)."""
    if mode not in THS_MODES or len(mode) != 1:
        raise ImutoolError(f"THS mode {mode!r} must be one of {', '.join(THS_MODES)}")
    h = _wrap360(heading_deg)
    return format_sentence(talker, "THS", [h, mode if h is not None else "V"], [1, None])


def rot_sentence(rate_deg_per_min: float | None, valid: bool = True, talker: str = "TI") -> str:
    """ROT: rate of turn in deg/min (negative = bow to port), status A/V (a missing rate forces V)."""
    ok = valid and rate_deg_per_min is not None and math.isfinite(rate_deg_per_min)
    return format_sentence(talker, "ROT", [rate_deg_per_min, "A" if ok else "V"], [1, None])


def pashr_sentence(
    time_utc_s: float | None,
    heading_deg: float | None,
    roll_deg: float | None,
    pitch_deg: float | None,
    heave_m: float | None,
    roll_std_deg: float | None = None,
    pitch_std_deg: float | None = None,
    heading_std_deg: float | None = None,
    aiding: int | None = 0,
    imu_status: int | None = 1,
) -> str:
    """$PASHR attitude (Applanix POS MV / OxTS layout): UTC time of day (s) as hhmmss.sss (empty when the time
    is not known — never invent one), true heading and 'T' (both empty without a heading), roll (+ starboard
    down), pitch (+ bow up), heave (m, sign as the caller chose; + up is the Applanix convention), 1-σ
    accuracies (deg), aiding flag (Applanix: 0 no aiding, 1 GNSS, 2 GNSS + GAMS) and IMU status (0 IMU out /
    not valid, 1 satisfactory). Empty fields for unknown values."""
    if time_utc_s is not None and math.isfinite(time_utc_s):
        tod = time_utc_s % 86400.0
        ms = int(round(tod * 1000.0)) % 86_400_000
        hh, rem = divmod(ms, 3_600_000)
        mm, rem = divmod(rem, 60_000)
        ts = f"{hh:02d}{mm:02d}{rem / 1000.0:06.3f}"
    else:
        ts = None
    h = _wrap360(heading_deg, 2)  # printed with two decimals
    fields = [
        ts,
        h,
        "T" if h is not None else None,
        roll_deg,
        pitch_deg,
        heave_m,
        roll_std_deg,
        pitch_std_deg,
        heading_std_deg,
        aiding,
        imu_status,
    ]
    return format_sentence("P", "ASHR", fields, [None, 2, None, 2, 2, 2, 3, 3, 3, None, None])


def utc_offset_s(rec: Recording) -> float | None:
    """Seconds to add to ``rec.time`` for Unix UTC, or None when the recording carries no real time.

    Real time comes from metadata (``start_utc`` / ``utc_start`` / ``start_time_utc``, ISO 8601; the time of the
    first row) or from a time axis that is already Unix seconds (after 2000-01-01, as NMEA logs read here are)."""
    if len(rec) == 0:
        return None
    for key in ("start_utc", "utc_start", "start_time_utc"):
        v = rec.meta.get(key)
        if not v:
            continue
        if isinstance(v, datetime):
            d = v
        else:
            try:
                d = datetime.fromisoformat(str(v).strip().replace("Z", "+00:00"))
            except ValueError:
                raise ImutoolError(f"metadata {key}: {str(v)[:40]!r} is not an ISO 8601 time") from None
        d = d if d.tzinfo else d.replace(tzinfo=timezone.utc)
        return d.timestamp() - float(rec.time[0])
    if float(rec.time[0]) > 946_684_800.0:
        return 0.0
    return None


# -- reading whole logs -------------------------------------------------------------------------------------------
_TAG_BLOCK_RE = re.compile(r"^\\([^\\]*)\\")
_ISO_RE = re.compile(r"^(\d{4}-\d{2}-\d{2})[T ](\d{2}:\d{2}:\d{2}(?:\.\d+)?)(Z|[+-]\d{2}:?\d{2})?$")
_TOD_RE = re.compile(r"^(\d{2})(\d{2})(\d{2}(?:\.\d+)?)$")


def _parse_stamp(prefix: str) -> float | None:
    """Seconds from a line prefix: Unix seconds or milliseconds, ISO 8601, or an NMEA 4 tag block ``c:``."""
    p = prefix.strip().rstrip(";,: \t").strip()
    if not p:
        return None
    m = _TAG_BLOCK_RE.match(p + ("\\" if p.startswith("\\") and not p.endswith("\\") else ""))
    if p.startswith("\\"):
        inner = p.strip("\\").split("*", 1)[0]
        for part in inner.split(","):
            if part.startswith("c:"):
                try:
                    v = float(part[2:])
                except ValueError:
                    return None
                return v / 1000.0 if v > 1e11 else v
        return None
    del m
    # Signal K multiplexed log: "1455631040123;N;$GPRMC..."  or "<stamp>;A;..."
    p = p.split(";", 1)[0].strip()
    try:
        v = float(p)
    except ValueError:
        pass
    else:
        if not math.isfinite(v) or v < 0:
            return None
        return v / 1000.0 if v > 1e11 else v
    mi = _ISO_RE.match(p)
    if mi:
        try:
            tz = mi.group(3) or "+00:00"
            tz = "+00:00" if tz == "Z" else tz
            return datetime.fromisoformat(f"{mi.group(1)}T{mi.group(2)}{tz}").timestamp()
        except ValueError:
            return None
    return None


def _tod(field: str) -> float | None:
    m = _TOD_RE.match(field.strip())
    if not m:
        return None
    hh, mm, ss = int(m.group(1)), int(m.group(2)), float(m.group(3))
    if hh > 23 or mm > 59 or ss >= 61:
        return None
    return hh * 3600.0 + mm * 60.0 + ss


def _date_epoch(day: int, month: int, year: int) -> float | None:
    try:
        return datetime(year, month, day, tzinfo=timezone.utc).timestamp()
    except (ValueError, OverflowError):
        return None


def _nmea_time(s: NmeaSentence) -> tuple[float | None, float | None]:
    """(UTC time of day s, date epoch s at 00:00 UTC) carried by RMC, GGA, GLL, ZDA, PASHR, PSTI,036, or a
    motion sentence with a valid UTC field (PSBGA, PSBGB, PHOCT, PTNL,AVR)."""
    f = s.fields
    t = s.type
    try:
        if t == "RMC" and len(f) >= 9:
            d = f[8].strip()
            de = (
                _date_epoch(int(d[:2]), int(d[2:4]), 2000 + int(d[4:6]) if int(d[4:6]) < 80 else 1900 + int(d[4:6]))
                if re.fullmatch(r"\d{6}", d)
                else None
            )
            return _tod(f[0]), de
        if t == "ZDA" and len(f) >= 4:
            de = None
            if f[1].strip().isdigit() and f[2].strip().isdigit() and f[3].strip().isdigit():
                year = int(f[3])
                if year < 100:  # some devices (B&G GoFree) send a 2-digit year in ZDA
                    year += 2000 if year < 80 else 1900
                de = _date_epoch(int(f[1]), int(f[2]), year)
            return _tod(f[0]), de
        if t == "GGA" and f:
            return _tod(f[0]), None
        if t == "GLL" and len(f) >= 5:
            return _tod(f[4]), None
        if t == "PASHR" and f:
            return _tod(f[0]), None
        if t == "PSTI" and len(f) >= 3 and f[0] == "036" and re.fullmatch(r"\d{6}", f[2].strip()):
            d = f[2].strip()
            return _tod(f[1]), _date_epoch(int(d[:2]), int(d[2:4]), 2000 + int(d[4:6]))
        if t in _OPT_DECODERS:
            u = motion.utc_field(s)
            return (_tod(u), None) if u else (None, None)
    except ValueError:
        pass
    return None, None


# Recording channels produced by read_nmea: decode key → (channel, unit)
_CHANNELS: dict[str, tuple[str, str]] = {
    "heading_true": ("heading", "deg"),
    "heading_mag": ("heading_mag", "deg"),
    "heading_sensor": ("heading_sensor", "deg"),
    "deviation": ("deviation", "deg"),
    "variation": ("variation", "deg"),
    "rot": ("rot", "deg/min"),
    "roll": ("roll", "deg"),
    "heel": ("roll", "deg"),
    "pitch": ("pitch", "deg"),
    "heave": ("heave", "m"),
    "roll_period": ("roll_period", "s"),
    "amp_port": ("amp_port", "deg"),
    "amp_stbd": ("amp_stbd", "deg"),
    "peak_port": ("peak_port", "deg"),
    "peak_stbd": ("peak_stbd", "deg"),
    "ths_mode": ("ths_mode", "1"),
    "sog": ("sog", "m/s"),
    "cog": ("cog", "deg"),
    **motion.CHANNELS,
    **gnss.CHANNELS,
}
_MAX_BAD_LINES = 10


def _empty_counts() -> dict[str, int]:
    return {"parsed": 0, "partial": 0, "no_data": 0, "bad_checksum": 0, "malformed": 0, "unsupported": 0}


def read_nmea(
    path: str | os.PathLike,
    checksum_policy: str = "require",
    xdr_map: dict[str, Any] | None = None,
    time_source: str = "auto",
    nominal_rate_hz: float = 10.0,
    encoding: str = "latin-1",
    pashr_heave_positive: str | None = None,
    tss_roll: Iterable[str] | None = None,
    profile: str | os.PathLike | dict[str, Any] | None = None,
    gga_altitude: str | None = None,
) -> Recording:
    """Read an NMEA 0183 log into a Recording of decoded channels (see :func:`decode`; HRM heel → ``roll``).

    Lines: ``#`` comments, blank lines and non-NMEA text (e.g. gpsd JSON) are skipped; a line may carry a
    timestamp prefix before the ``$``/``!`` (Unix s or ms, ISO 8601, ``stamp;X;`` Signal K style, or an NMEA 4
    ``\\c:...\\`` tag block). TSS1 frames (``:XXAAAA MHHHHQMRRRR MPPPP``, no checksum) are read too. Bad
    lines are counted per sentence type (proprietary ones by message: ``PSXN,23``) and never fatal; a sentence
    imutool does not decode is counted as ``unsupported`` under its name (:func:`sentence_summary`).

    Per-device settings of the motion sentences (:class:`MotionOptions`): ``pashr_heave_positive`` (``up``,
    the default, or ``down``), ``tss_roll`` (sentence types whose roll is a TSS roll, converted to Euler roll;
    default ``("TSS1",)``), ``gga_altitude`` (``msl``, the default, or ``ellipsoid`` for a receiver that writes
    the ellipsoidal height into GGA's altitude field; see :mod:`formats.nmea.gnss`); or a ``profile`` (TOML path
    or dict) whose ``[nmea]`` table holds those keys (the keyword arguments win). The settings and each
    sentence's source convention are in ``meta``.

    Time base (``time_source``; ``auto`` takes the first available): ``stamp`` = the per-line prefixes (s; with
    ``auto``, a sentence with a UTC field sits at that time and the others at their stamp minus the logger
    clock's offset from UTC); ``nmea`` = a sentence with a UTC field (RMC/GGA/GST/GLL/ZDA/PASHR/PSTI,036/GGK/PJK,
    motion sentences with a valid one) at that time, the others placed linearly by their position in the log
    between the fixes around them, extrapolated at the ends with the mean spacing; Unix seconds when a date
    (RMC/ZDA) is known, else seconds of the UTC day; ``index`` = sentence position / ``nominal_rate_hz``. The
    choice is in ``meta['time_source']``, each sentence type's rate, bursts and gaps on its own times in
    ``meta['sentence_timing']``.

    Rows: one per decoded sentence carrying a value (NaN in the channels that sentence does not supply), in
    time order; sentences sharing an identical timestamp are merged into one row (later values win; counted).
    Raises ImutoolError when the file cannot be read or holds no usable sentence.
    """
    if time_source not in TIME_SOURCES:
        raise ImutoolError(f"unknown time source {time_source!r} ({', '.join(TIME_SOURCES)})")
    if checksum_policy not in CHECKSUM_POLICIES:
        raise ImutoolError(f"unknown checksum policy {checksum_policy!r} ({', '.join(CHECKSUM_POLICIES)})")
    if not (nominal_rate_hz > 0 and math.isfinite(nominal_rate_hz)):
        raise ImutoolError(f"nominal rate must be a positive number of Hz, not {nominal_rate_hz!r}")
    spath = os.fspath(path)
    xmap = _normalise_xdr_map(xdr_map)
    prof = profile
    if prof is not None and not isinstance(prof, dict):
        prof = load_profile(os.fspath(prof))
    opts = motion.options_from(prof, pashr_heave_positive, tss_roll, gga_altitude=gga_altitude)
    try:
        with open(spath, encoding=encoding, errors="replace", newline="") as fh:
            text = fh.read()
    except OSError as e:
        raise ImutoolError(f"cannot read: {e.strerror or e}", path=spath) from None
    if "\x00" in text[:4096] and text.count("\x00") > len(text) // 10:
        raise ImutoolError("binary file, not an NMEA text log" + _em3000_hint(text), path=spath)

    counts: dict[str, dict[str, int]] = {}
    bad_lines: list[dict[str, Any]] = []
    n_comment = n_other = n_prefix = 0
    xdr_ids: Counter[str] = Counter()
    rows_vals: list[dict[str, float]] = []
    rows_pos: list[int] = []
    rows_stamp: list[float | None] = []
    rows_key: list[str] = []  # the count key (sentence type) of each row
    anchors: list[tuple[int, float, float | None]] = []  # (position, tod, date epoch)
    anchor_stamp: dict[int, float] = {}  # position → arrival stamp of a sentence with a UTC field
    stamps_seen = 0
    pos = -1

    def bad(lineno: int, stype: str | None, kind: str, msg: str) -> None:
        counts.setdefault(stype or "?", _empty_counts())[kind] += 1
        if len(bad_lines) < _MAX_BAD_LINES:
            bad_lines.append({"line": lineno, "type": stype or "?", "problem": kind, "detail": msg[:120]})

    for lineno, line in enumerate(re.split(r"\r\n|\r|\n", text), start=1):
        st = line.strip()
        if not st:
            continue
        if st.startswith("#"):
            n_comment += 1
            continue
        i_d, i_b = st.find("$"), st.find("!")
        idx = min(i for i in (i_d, i_b) if i >= 0) if (i_d >= 0 or i_b >= 0) else -1
        if idx < 0 and len(st) >= 25 and st[-25] == ":" and (len(st) == 25 or st[-26] in " \t;,"):
            frame, stamp = st[-25:], _parse_stamp(st[:-25]) if len(st) > 25 else None
            pos += 1
            try:
                vals = motion.decode_tss1(frame, opts)
            except NmeaParseError as e:
                bad(lineno, "TSS1", e.kind, str(e))
                continue
            counts.setdefault("TSS1", _empty_counts())["parsed"] += 1
            stamps_seen += stamp is not None
            rows_vals.append(vals)
            rows_key.append("TSS1")
            rows_pos.append(pos)
            rows_stamp.append(stamp)
            continue
        if idx < 0:
            n_other += 1
            continue
        stamp = _parse_stamp(st[:idx]) if idx > 0 else None
        if idx > 0 and stamp is None:
            n_prefix += 1  # text before the sentence that is not a timestamp (spliced line?): sentence still tried
        pos += 1
        try:
            s = parse_sentence(st[idx:], checksum_policy)
        except NmeaParseError as e:
            key = e.sentence_type
            if key and key in motion._SUBTYPED | {"PASHR"}:
                key = motion.count_key_of(key, (st[idx:].split(",", 2) + ["", ""])[1].split("*")[0])
            bad(lineno, key, e.kind, str(e))
            continue
        if stamp is not None:
            stamps_seen += 1
        stype = s.type
        ckey = motion.count_key(s)
        c = counts.setdefault(ckey, _empty_counts())
        tod, de = _nmea_time(s)
        if tod is not None:
            anchors.append((pos, tod, de))
            if stamp is not None:
                anchor_stamp[pos] = stamp
        if stype == "XDR":
            if len(s.fields) % 4:
                xdr_ids["(misaligned sentence)"] += 1
            for k in range(len(s.fields) // 4 if len(s.fields) % 4 == 0 else 0):
                xdr_ids[s.fields[4 * k + 3].strip()] += 1
        try:
            vals, problems = _decode_with(s, xmap, opts)
            if problems and not vals:
                raise NmeaFieldError(problems[0], sentence_type=stype)
        except NmeaUnsupportedError:
            if tod is None:
                c["unsupported"] += 1
            else:
                c["parsed"] += 1  # used for time only
            continue
        except NmeaParseError as e:
            bad(lineno, ckey, e.kind, str(e))
            continue
        except Exception as e:  # a pynmea2 surprise must never abort a whole log
            bad(lineno, ckey, "malformed", f"{type(e).__name__}: {e}")
            continue
        if (
            not vals
            or set(vals) <= {"ths_mode", "peak_reset_time", "peak_reset_day", "peak_reset_month"}
            and "ths_mode" not in vals
        ):
            c["no_data"] += 1
            continue
        c["parsed"] += 1
        if problems:
            c["partial"] += 1
            if len(bad_lines) < _MAX_BAD_LINES:
                bad_lines.append({"line": lineno, "type": ckey, "problem": "partial", "detail": problems[0][:120]})
        rows_vals.append(vals)
        rows_key.append(ckey)
        rows_pos.append(pos)
        rows_stamp.append(stamp)

    n_pos = pos + 1
    if not rows_vals:
        summary = ", ".join(f"{k}: {v}" for k, v in sorted(counts.items()) if any(v.values())) or "none"
        raise ImutoolError(
            f"no usable NMEA sentence with heading/attitude data (sentence counts: {summary})" + _em3000_hint(text),
            path=spath,
        )

    # -- time base: each sentence at its own time — its UTC field where it has one, else its arrival stamp (on
    # the UTC axis, see _stamp_times) or its place between the UTC fixes around it
    src = time_source
    have_stamps = stamps_seen > 0 and all(x is not None for x in rows_stamp)
    if src == "auto":
        src = "stamp" if have_stamps else ("nmea" if anchors else "index")
    t_meta: dict[str, Any] = {}
    pos_arr = np.array(rows_pos, dtype=float)
    if src == "stamp":
        if not have_stamps:
            raise ImutoolError("time source 'stamp' asked for, but not every sentence line has a timestamp", path=spath)
        t = np.array(rows_stamp, dtype=float)
        if anchors and time_source == "auto":
            t, t_meta = _stamp_times(t, pos_arr, anchors, anchor_stamp, nominal_rate_hz)
    elif src == "nmea":
        if not anchors:
            raise ImutoolError(
                "time source 'nmea' asked for, but the log has no RMC/GGA/GLL/ZDA/PASHR time", path=spath
            )
        t, t_meta = _nmea_times(pos_arr, anchors, nominal_rate_hz)
    else:
        t = np.array(rows_pos, dtype=float) / nominal_rate_hz
        t_meta = {"nominal_rate_hz": nominal_rate_hz}

    # -- rows in time order (a sentence at its own UTC may come before one logged ahead of it); identical times
    # merged into one row (a value a later sentence of the same time overwrites is counted per sentence type)
    order = np.argsort(t, kind="stable")
    t = t[order]
    rows_vals = [rows_vals[i] for i in order]
    keys_sorted = [rows_key[i] for i in order]
    order_keys: list[str] = []
    for v in rows_vals:
        for k in v:
            ch = _CHANNELS.get(k)
            if ch and ch[0] not in order_keys:
                order_keys.append(ch[0])
    grp = np.concatenate([[True], np.diff(t) != 0]) if len(t) > 1 else np.array([True])
    row_of = np.cumsum(grp) - 1
    n_rows = int(row_of[-1]) + 1
    data = {name: np.full(n_rows, np.nan) for name in order_keys}
    overwritten: Counter[str] = Counter()
    for r, v, key in zip(row_of, rows_vals, keys_sorted, strict=True):
        for k, x in v.items():
            ch = _CHANNELS.get(k)
            if ch:
                col = data[ch[0]]
                if not math.isnan(col[r]):
                    overwritten[key] += 1
                col[r] = x
    # a sentence without a time field placed between fixes is known in time only to the fix interval
    own_utc = {rows_key[i] for i, p in enumerate(rows_pos) if t_meta.get("_own", {}).get(p) is not None}
    fix_dt = float(t_meta.pop("_fix_interval_s", 0.0) or 0.0) if src == "nmea" else 0.0
    t_meta.pop("_own", None)
    resolution = {k: 0.0 if k in own_utc else 2.0 * fix_dt for k in set(keys_sorted)}
    timing = _sentence_timing(t, keys_sorted, resolution)
    for k, n in overwritten.items():
        timing[k]["values_overwritten_at_same_time"] = int(n)
    units = {name: next(u for kk, (c, u) in _CHANNELS.items() if c == name) for name in order_keys}
    rec = Recording(t[grp], data, units)
    _declare_streams(rec, row_of, rows_vals, keys_sorted, n_rows)
    if rec.streams:  # a stream's times are known to its coarsest sentence's resolution: no gap below it
        rec.meta["stream_time_resolution_s"] = {
            k: max(resolution.get(x, 0.0) for x in k.split("+")) for k in rec.streams
        }
    rec.meta.update(
        {
            "source": spath,
            "format": "nmea0183",
            "time_source": src,
            "time": t_meta,
            "checksum_policy": checksum_policy,
            "sentences": {k: counts[k] for k in sorted(counts)},
            "bad_lines": bad_lines,
            "lines": {"comment": n_comment, "not_nmea": n_other, "sentences": n_pos, "unrecognised_prefix": n_prefix},
            "xdr_map": {k: (("-" if m.sign < 0 else "") + m.quantity) for k, m in xmap.items()},
            "xdr_ids_seen": dict(xdr_ids),
            "signs": "roll + starboard down, pitch + bow up, heave + up (m), heading deg true, rot deg/min",
            "rows": "one per sentence carrying a value, each at its own time; identical timestamps merged",
            "sentence_timing": timing,
        }
    )
    if "ths_mode" in data:
        rec.meta["ths_mode_codes"] = {str(float(ord(c))): c for c in THS_MODES}
    seen = [k for k, v in counts.items() if v["parsed"]]
    conv = {**motion.conventions_for(seen, opts), **gnss.conventions_for(seen, opts)}
    if conv:
        rec.meta["conventions"] = conv
        rec.meta["motion_options"] = opts.as_meta()
    letters = {**motion.LETTER_CODES, **gnss.LETTER_CODES}
    codes = {k: letters[k] for k in data if k in letters}
    if "gnss_height" in data:
        rec.meta["gnss_height"] = gnss.height_meta(
            data.get("gnss_height_datum", []), data.get("gnss_geoid_separation"), opts
        )
    if codes:
        rec.meta["status_codes"] = codes
    return rec


_VARIABLE_CONTENT = {"XDR"}  # sentences whose channels vary from line to line (transducer ids)


def _declare_streams(
    rec: Recording, row_of: np.ndarray, rows_vals: list[dict[str, float]], keys: list[str], n_rows: int
) -> None:
    """Each sentence type is a stream on its own rows (Recording's many clocks): a channel's samples are the rows
    where a sentence that carries it arrived (an empty field there is a missing sample; another sentence's row is
    not). Channels carried by the same sentence types share a stream, named by them (``PSXN23``, ``HDT+THS``); an
    XDR line is keyed by the channels it carries (``XDR:pitch/roll``, or ``XDR:roll`` and ``XDR:pitch`` when a
    device sends each transducer on a line of its own)."""
    key_rows: dict[str, np.ndarray] = {}
    chan_keys: dict[str, set[str]] = {}
    for r, v, key in zip(row_of, rows_vals, keys, strict=True):
        if key in _VARIABLE_CONTENT:  # e.g. XDR ROLL and XDR PITCH on lines of their own: a stream each
            key = f"{key}:" + "/".join(sorted({_CHANNELS[k][0] for k in v if k in _CHANNELS}))
        key_rows.setdefault(key, np.zeros(n_rows, dtype=bool))[r] = True
        for k in v:
            ch = _CHANNELS.get(k)
            if ch:
                chan_keys.setdefault(ch[0], set()).add(key)
    groups: dict[tuple[str, ...], list[str]] = {}
    for name in rec.channels:
        groups.setdefault(tuple(sorted(chan_keys.get(name, ()))), []).append(name)
    masks = {}
    for ks in groups:
        m = np.zeros(n_rows, dtype=bool)
        for k in ks:
            m |= key_rows[k]
        masks[ks] = m
    if all(bool(m.all()) for m in masks.values()):
        return  # one clock: every channel has a sample on every row
    for ks, chans in groups.items():
        rec.set_stream("+".join(ks) or "other", chans, masks[ks])


def _em3000_hint(text: str) -> str:
    """A hint for a file that is Kongsberg EM3000 binary attitude frames rather than an NMEA log."""
    raw = text[:20000].encode("latin-1", "replace")
    frames, skipped = scan_frames(raw)
    if len(frames) >= 3 and len(frames) * 10 >= 0.9 * len(raw):
        return (
            "; it looks like Kongsberg EM3000 binary attitude frames: read it with "
            "formats.nmea.read_em3000(path, rate_hz=...)"
        )
    return ""


def sentence_summary(meta: dict[str, Any]) -> dict[str, dict[str, int]]:
    """What an NMEA log's reader did with its sentences, from ``meta['sentences']``: ``read`` (name → sentences
    decoded), ``not_read`` (name → sentences imutool does not decode, e.g. ``PSXN,26``, ``VDM``), ``no_data``
    (sentences with every field empty), ``bad`` (name → bad checksum + malformed). Empty dicts left out."""
    out: dict[str, dict[str, int]] = {"read": {}, "not_read": {}, "no_data": {}, "bad": {}}
    for k, c in (meta.get("sentences") or {}).items():
        if not isinstance(c, dict):
            continue
        for group, n in (
            ("read", c.get("parsed", 0)),
            ("not_read", c.get("unsupported", 0)),
            ("no_data", c.get("no_data", 0)),
            ("bad", c.get("bad_checksum", 0) + c.get("malformed", 0)),
        ):
            if n:
                out[group][k] = int(n)
    return {g: dict(sorted(v.items(), key=lambda kv: (-kv[1], kv[0]))) for g, v in out.items() if v}


def _anchor_times(
    anchors: list[tuple[int, float, float | None]], default_date: float | None = None
) -> tuple[list[tuple[int, float]], dict[int, float], int, float | None]:
    """The UTC fixes on one time axis: (interpolation anchors [(position, t)] — the first sentence of each new
    time —, every accepted sentence's own time {position: t}, fixes rejected for going backwards, first date).
    Unix seconds where a date is known (RMC/ZDA, else ``default_date``), seconds of the UTC day otherwise; a
    midnight roll-over before the next date is handled."""
    first_date = next((d for _, _, d in anchors if d is not None), default_date)
    interp: list[tuple[int, float]] = []
    own: dict[int, float] = {}
    date = first_date
    prev = -math.inf
    rejected = 0
    for p, tod, d in anchors:
        if d is not None:
            date = d
        base = date if date is not None else 0.0
        tt = base + tod
        if prev - 86400.0 < tt < prev - 43200.0:  # midnight roll-over before a new date arrives
            tt += 86400.0
        if interp and tt == interp[-1][1]:
            own[p] = tt  # several sentences of one epoch carry the same time: the first one anchors it
            continue
        if tt < prev:
            rejected += 1  # a time that goes backwards is not used
            continue
        interp.append((p, tt))
        own[p] = tt
        prev = tt
    return interp, own, rejected, first_date


def _nmea_times(
    pos: np.ndarray, anchors: list[tuple[int, float, float | None]], nominal_rate_hz: float
) -> tuple[np.ndarray, dict[str, Any]]:
    """Place sentences in time from the UTC fixes (see read_nmea): a sentence with a UTC field at that time, the
    others linearly by position between the fixes around them. Returns (times, meta)."""
    interp, own, rejected, first_date = _anchor_times(anchors)
    pa = np.array([p for p, _ in interp], dtype=float)
    ta = np.array([x for _, x in interp])
    if len(pa) >= 2:
        slope = float((ta[-1] - ta[0]) / (pa[-1] - pa[0])) if pa[-1] > pa[0] else 1.0 / nominal_rate_hz
    else:
        slope = 1.0 / nominal_rate_hz
    t = np.interp(pos, pa, ta)
    lo, hi = pos < pa[0], pos > pa[-1]
    t[lo] = ta[0] + (pos[lo] - pa[0]) * slope
    t[hi] = ta[-1] + (pos[hi] - pa[-1]) * slope
    n_own = 0
    for i, p in enumerate(pos):
        x = own.get(int(p))
        if x is not None:
            t[i] = x
            n_own += 1
    meta = {
        "anchors": len(pa),
        "anchors_rejected_going_backwards": rejected,
        "origin": "unix seconds (UTC)" if first_date is not None else "seconds of the UTC day (no date in log)",
        "seconds_per_sentence_between_fixes": slope,
        "rows_at_their_own_utc": n_own,
        "_own": own,  # for the reader (removed there)
        "_fix_interval_s": float(np.median(np.diff(ta))) if len(ta) > 1 else 0.0,
    }
    _start_utc(meta, t, first_date is not None)
    return t, meta


def _start_utc(meta: dict[str, Any], t: np.ndarray, dated: bool) -> None:
    if dated and len(t):
        try:
            meta["start_utc"] = datetime.fromtimestamp(float(np.min(t)), tz=timezone.utc).isoformat()
        except (ValueError, OverflowError, OSError):
            meta["start_utc"] = None  # a date outside what datetime can show (corrupted ZDA/RMC)


_OFFSET_RUN = 15  # UTC fixes in the running median of the logger clock's offset from UTC
_OFFSET_MAX_SPREAD_S = 3600.0  # beyond this the UTC fields are not trusted: arrival stamps only


def _stamp_times(
    stamps: np.ndarray,
    pos: np.ndarray,
    anchors: list[tuple[int, float, float | None]],
    anchor_stamp: dict[int, float],
    nominal_rate_hz: float,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Stamped log with UTC fields, on the logger's clock (the stamps' axis, which other files stamped by the same
    logger share): each sentence with a UTC field at that UTC plus the logger clock's offset from UTC (stamp − UTC
    of the fixes, running median over ``_OFFSET_RUN`` fixes, interpolated along the stamps), so a fix logged late
    sits at its own instant; the others at their arrival stamp. Without a date in the log, the date comes from the
    stamps when they are Unix seconds. Returns (times, meta)."""
    first = next(((p, tod) for p, tod, _ in anchors if p in anchor_stamp), None)
    meta: dict[str, Any] = {"utc_fields": "not used"}
    if first is None:
        return stamps, meta
    default_date = None
    s0 = anchor_stamp[first[0]]
    if s0 > 946_684_800.0:  # Unix seconds after 2000: the day the stamps say, nearest to the fix's time of day
        default_date = math.floor((s0 - first[1]) / 86400.0 + 0.5) * 86400.0
    _, own, rejected, first_date = _anchor_times(anchors, default_date)
    ps = sorted(p for p in own if p in anchor_stamp)
    if not ps:
        return stamps, meta
    st = np.array([anchor_stamp[p] for p in ps])
    off = st - np.array([own[p] for p in ps])
    k = min(_OFFSET_RUN, len(off))
    pad = np.pad(off, (k // 2, k - 1 - k // 2), mode="edge")
    smooth = np.median(np.lib.stride_tricks.sliding_window_view(pad, k), axis=1)
    spread = float(np.percentile(off, 95) - np.percentile(off, 5))
    if not np.isfinite(spread) or np.ptp(smooth) > _OFFSET_MAX_SPREAD_S:
        return stamps, {"utc_fields": f"not used: the logger clock's offset from UTC varies by {np.ptp(smooth):.0f} s"}
    srt = np.argsort(st, kind="stable")
    offset = np.interp(stamps, st[srt], smooth[srt])  # the logger clock's offset from UTC at each line
    t = np.array(stamps, dtype=float)
    n_own = 0
    for i, p in enumerate(pos):
        x = own.get(int(p))
        if x is not None:
            t[i] = x + offset[i]
            n_own += 1
    meta = {
        "utc_fields": "on the logger's clock (the stamps): sentences with a UTC field at that UTC plus the logger "
        "clock's offset from UTC; the others at their arrival stamp",
        "rows_at_their_own_utc": n_own,
        "stamp_offset_s": round(float(np.median(off)), 6),
        "stamp_offset_spread_s": round(spread, 6),
        "anchors_rejected_going_backwards": rejected,
        "origin": "the log's stamps (the logger's clock)",
    }
    _start_utc(meta, t - offset, first_date is not None)
    return t, meta


def _sentence_timing(t: np.ndarray, keys: list[str], min_gap_s: dict[str, float]) -> dict[str, dict[str, Any]]:
    """Rate, bursts and gaps of each sentence type on its own times (:func:`formats.timing.stream_timing`);
    ``min_gap_s`` per type: the resolution of its times (twice the fix interval for a sentence placed between
    fixes, 0 for one at its own UTC or arrival stamp)."""
    karr = np.array(keys, dtype=object)
    return {k: stream_timing(t[karr == k], min_gap_s=min_gap_s.get(k, 0.0)) for k in sorted(set(keys))}


# -- writing logs -------------------------------------------------------------------------------------------------
WRITABLE = ("HDT", "THS", "HDG", "ROT", "XDR", "HRM", "PASHR")


def _channel(rec: Recording, name: str, unit: str) -> np.ndarray | None:
    if name not in rec.channels:
        return None
    a = rec[name]
    if a.ndim != 1:
        return None
    if rec.units.get(name) and rec.units.get(name) != unit:
        return np.asarray(rec.get(name, unit), dtype=float)
    return np.asarray(a, dtype=float)


def _f(a: np.ndarray | None, i: int) -> float | None:
    if a is None:
        return None
    x = float(a[i])
    return x if math.isfinite(x) else None


# the channel whose own samples time each written sentence (first present wins), for a many-clock recording
_WRITE_DRIVERS: dict[str, tuple[str, ...]] = {
    "HDT": ("heading",),
    "THS": ("heading",),
    "HDG": ("heading_sensor", "heading_mag"),
    "ROT": ("rot", "heading"),
    "XDR": ("roll", "pitch"),
    "HRM": ("roll", "roll_period"),
    "PASHR": ("roll", "pitch", "heading", "heave"),
}


def iter_sentences(
    rec: Recording,
    sentences: Iterable[str] = ("HDT",),
    rate_hz: float | None = None,
    talker: str | None = None,
    xdr_map: dict[str, Any] | None = None,
) -> Iterator[tuple[float, str]]:
    """Yield (time s, sentence without CR/LF) from a Recording's channels: heading (true deg), heading_sensor /
    heading_mag / deviation / variation (HDG), rot (deg/min; derived from heading when absent), roll, pitch
    (deg), heave (m), HRM fields (roll, roll_period, amp_port, amp_stbd, peak_port, peak_stbd).

    rate_hz: None writes every row; otherwise, for each point of a uniform grid at that rate, the first row at
    or after it (decimation; no interpolation, so values are the recorded ones). Rows whose needed channel is
    NaN emit nothing for that sentence (THS/ROT/HRM emit an invalid-status sentence instead). Sentence order
    per row follows ``sentences``. XDR ids/signs come from the first roll/pitch entries of ``xdr_map``
    (default ROLL/PTCH, sign +). PASHR's UTC is the recording's real time (:func:`utc_offset_s`), else empty.
    """
    sents = [s.upper() for s in sentences]
    for s in sents:
        if s not in WRITABLE:
            raise ImutoolError(f"cannot write sentence type {s!r} (writable: {', '.join(WRITABLE)})")
    n = len(rec)
    if n == 0:
        return
    if rec.multi_clock:  # each sentence on the clock of the channel it carries (Recording.on_clock)
        groups: dict[str, list[str]] = {}
        for s in sents:
            drv = next((c for c in _WRITE_DRIVERS[s] if c in rec.channels), None)
            groups.setdefault((rec.stream_of(drv) or drv) if drv else "", []).append(s)
        off = utc_offset_s(rec)
        gens = []
        for key, ss in groups.items():
            sub = rec.on_clock(key or next(iter(rec.stream_rows)))
            if off is not None:
                sub.meta["start_utc"] = datetime.fromtimestamp(float(sub.time[0]) + off, timezone.utc).isoformat()
            gens.append(iter_sentences(sub, ss, rate_hz, talker, xdr_map))
        yield from heapq.merge(*gens, key=lambda x: x[0])
        return
    t = rec.time
    if rate_hz is None:
        rows = np.arange(n)
    else:
        if not (rate_hz > 0 and math.isfinite(rate_hz)):
            raise ImutoolError(f"rate must be a positive number of Hz, not {rate_hz!r}")
        grid = t[0] + np.arange(int(np.floor((t[-1] - t[0]) * rate_hz + 1e-9)) + 1) / rate_hz
        rows = np.unique(np.clip(np.searchsorted(t, grid - 1e-9, side="left"), 0, n - 1))
    heading = _channel(rec, "heading", "deg")
    hsensor = _channel(rec, "heading_sensor", "deg")
    hmag = _channel(rec, "heading_mag", "deg")
    dev = _channel(rec, "deviation", "deg")
    var = _channel(rec, "variation", "deg")
    roll = _channel(rec, "roll", "deg")
    pitch = _channel(rec, "pitch", "deg")
    heave = _channel(rec, "heave", "m")
    rot = _channel(rec, "rot", "deg/min")
    period = _channel(rec, "roll_period", "s")
    amp_p, amp_s = _channel(rec, "amp_port", "deg"), _channel(rec, "amp_stbd", "deg")
    peak_p, peak_s = _channel(rec, "peak_port", "deg"), _channel(rec, "peak_stbd", "deg")
    ths_mode = _channel(rec, "ths_mode", "1")
    if rot is None and heading is not None and "ROT" in sents and n >= 2:
        unwrapped = np.degrees(np.unwrap(np.radians(np.nan_to_num(heading, nan=0.0))))
        rot = np.gradient(unwrapped, t) * 60.0
        rot[~np.isfinite(heading)] = np.nan
    xm = _normalise_xdr_map(xdr_map)
    rid = next((k for k, m in xm.items() if m.quantity == "roll"), "ROLL")
    pid = next((k for k, m in xm.items() if m.quantity == "pitch"), "PTCH")
    rsign = int(xm[rid].sign) if rid in xm else 1
    psign = int(xm[pid].sign) if pid in xm else 1
    tk = talker
    utc0 = utc_offset_s(rec) if "PASHR" in sents else None

    for i in rows:
        i = int(i)
        ti = float(t[i])
        for s in sents:
            out: str | None = None
            if s == "HDT":
                h = _f(heading, i)
                out = hdt_sentence(h, talker=tk or "HE") if h is not None else None
            elif s == "THS":
                if heading is not None:
                    mode = "A"
                    if ths_mode is not None and _f(ths_mode, i) is not None:
                        mode = chr(int(ths_mode[i]))
                        mode = mode if mode in THS_MODES else "A"
                    out = ths_sentence(_f(heading, i), mode=mode, talker=tk or "HE")
            elif s == "HDG":
                hs = _f(hsensor, i)
                d, v = _f(dev, i), _f(var, i)
                if hs is None and hmag is not None and _f(hmag, i) is not None:
                    hs = _f(hmag, i) - (d or 0.0)
                    d = 0.0 if d is None else d
                if hs is not None:
                    out = hdg_sentence(hs, d, v, talker=tk or "HC")
            elif s == "ROT":
                if rot is not None:
                    r = _f(rot, i)
                    out = rot_sentence(r, valid=r is not None, talker=tk or "TI")
            elif s == "XDR":
                r, p = _f(roll, i), _f(pitch, i)
                if r is not None or p is not None:
                    out = xdr_roll_pitch(
                        r, p, roll_id=rid, pitch_id=pid, roll_sign=rsign, pitch_sign=psign, talker=tk or "YX"
                    )
            elif s == "HRM":
                r = _f(roll, i)
                if r is not None or period is not None:
                    pr = _f(period, i)
                    out = hrm_sentence(
                        r,
                        pr,
                        _f(amp_p, i),
                        _f(amp_s, i),
                        valid=r is not None,
                        peak_port_deg=_f(peak_p, i),
                        peak_stbd_deg=_f(peak_s, i),
                        talker=tk or "II",
                    )
            elif s == "PASHR":
                h, r, p, hv = _f(heading, i), _f(roll, i), _f(pitch, i), _f(heave, i)
                if any(x is not None for x in (h, r, p, hv)):
                    out = pashr_sentence(None if utc0 is None else ti + utc0, h, r, p, hv)
            if out is not None:
                yield ti, out


def write_nmea(
    rec: Recording,
    path: str | os.PathLike,
    sentences: Sequence[str] = ("HDT", "XDR"),
    rate_hz: float | None = None,
    talker: str | None = None,
    xdr_map: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Write sentences (CRLF line ends, atomic) from a Recording; returns counts per sentence type.
    See :func:`iter_sentences` for channels, decimation and talker defaults."""
    spath = os.fspath(path)
    counts: Counter[str] = Counter()
    with atomic_path(spath) as tmp:
        with open(tmp, "w", encoding="ascii", newline="") as fh:
            for _, s in iter_sentences(rec, sentences, rate_hz, talker=talker, xdr_map=xdr_map):
                fh.write(s + "\r\n")
                addr = s[1:].split(",", 1)[0]
                counts["P" + addr[1:] if addr.startswith("P") else addr[2:]] += 1
        if not counts:  # raised inside the context: no output file is left behind
            have = ", ".join(rec.channels) or "none"
            raise ImutoolError(
                f"no sentence could be written: the recording lacks the channels for "
                f"{', '.join(sentences)} (has: {have})",
                path=spath,
            )
    return {"path": spath, "sentences": dict(counts), "total": int(sum(counts.values()))}
