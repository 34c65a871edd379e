"""GNSS heights: GGA altitude and geoid separation, GST error σ, Trimble ``$PTNL,GGK`` and ``$PTNL,PJK``.

Channels (metres, + up; docs/nmea.md "GNSS heights"):

- ``gnss_height``: the antenna's height. GGA: the ellipsoidal height h = H + N (H the altitude field, above the
  geoid; N the geoid separation, the geoid above the ellipsoid) where N is sent; where N is empty, the altitude
  as sent. ``$PTNL,GGK``: the ellipsoidal height (its ``EHT`` field). ``$PTNL,PJK``: the height as sent, ``EHT``
  (ellipsoidal) or ``GHT`` (orthometric, the receiver's geoid model).
- ``gnss_height_datum``: a letter's code point per row (``chr(int(v))``): ``E`` ellipsoidal, ``A`` the GGA
  altitude as sent (separation empty: orthometric by NMEA's definition, ellipsoidal on receivers without a geoid
  model — which one, the sentence does not say), ``O`` orthometric (PJK ``GHT``).
- ``gnss_geoid_separation`` (GGA N), ``gnss_fix_quality`` (GGA's scale 0..8: 1 GNSS, 2 DGNSS, 4 RTK fixed,
  5 RTK float, 6 dead reckoning, 7 manual, 8 simulator; Trimble's own codes are mapped onto it and kept in
  ``ptnl_quality``), ``gnss_lat_std``, ``gnss_lon_std``, ``gnss_height_std`` (GST, 1 σ).

A receiver that writes the ellipsoidal height into GGA's altitude field (and 0 or nothing as separation) is a
per-device setting, ``gga_altitude = "ellipsoid"`` (:class:`formats.nmea.MotionOptions`): the separation is then
never added. A separation of exactly 0 is taken as that case (H + 0 is the ellipsoidal height either way) and
counted in the metadata. GGA with fix quality 0 (no fix) carries no height: used for its time only.

Layouts: GGA and GST are pynmea2's ``GGA`` and ``GST``; ``$PTNL,GGK`` pynmea2's ``TNLGGK`` (Trimble receiver help:
``EHT`` height, quality 0..13 on Trimble's own scale); ``$PTNL,PJK`` Trimble's receiver help ("Local coordinate
position output": time, date, northing, N, easting, E, quality, satellites, DOP, ``GHT``/``EHT`` height, M).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
from pynmea2.types.proprietary.tnl import TNLGGK
from pynmea2.types.talker import GGA, GST

from .framing import NmeaFieldError, NmeaSentence, NmeaUnsupportedError, _num

GGA_ALTITUDES = ("msl", "ellipsoid")

# letters of the gnss_height_datum channel
DATUM_ELLIPSOID, DATUM_AS_SENT, DATUM_ORTHOMETRIC = "E", "A", "O"

_GGA = {f[1]: i for i, f in enumerate(GGA.fields)}
_GST = {f[1]: i for i, f in enumerate(GST.fields)}
_GGK = {f[1]: i - 1 for i, f in enumerate(TNLGGK.fields)}  # proprietary: index 0 is the message id "GGK"
_PJK = {"timestamp": 1, "datestamp": 2, "quality": 7, "num_sats": 8, "dop": 9, "height": 10, "meters": 11}

# Trimble's GGK/PJK quality → GGA's scale, as Trimble's own GGA sends the same solutions (SPSx51 manual: 2 DGPS and
# OmniSTAR VBS, 4 RTK fixed, 5 RTK float, OmniSTAR XP/HP, Location RTK). 2-D network solutions carry no height of
# their own: 2. RTX (14) and xFill (15) → 5 is an assumption (no public mapping found).
TRIMBLE_TO_GGA = {0: 0, 1: 1, 2: 5, 3: 4, 4: 2, 5: 2, 6: 5, 7: 4, 8: 2, 9: 2, 10: 5, 11: 2, 12: 5, 13: 2, 14: 5, 15: 5}
_HEIGHT_RE = re.compile(r"^(EHT|GHT)?\s*([+-]?\s*\d+(?:\.\d*)?|[+-]?\.\d+)$")


def _f(s: NmeaSentence, i: int) -> str:
    return s.fields[i].strip() if 0 <= i < len(s.fields) else ""


def _quality(s: NmeaSentence, i: int, top: int, key: str) -> int | None:
    v = _num(_f(s, i), "fix quality", s.type)
    if v is None:
        return None
    if v != int(v) or not 0 <= v <= top:
        raise NmeaFieldError(f"{s.type}: fix quality {_f(s, i)[:8]!r} is not 0..{top}", sentence_type=s.type)
    return int(v)


def _metres(s: NmeaSentence, i: int, what: str) -> None:
    u = _f(s, i).upper()
    if u not in ("", "M"):
        raise NmeaFieldError(f"{s.type}: {what} unit {u[:8]!r} is not M (metres)", sentence_type=s.type)


def _dec_gga(s: NmeaSentence, opts: Any, problems: list[str]) -> dict[str, float]:
    """GGA: ``gnss_height`` = altitude + geoid separation (ellipsoidal) where the separation is sent, else the
    altitude as sent (datum ``A``); ``gga_altitude = "ellipsoid"`` takes the altitude as the ellipsoidal height.
    Fix quality 0: no height (the sentence gives its time only)."""
    q = _quality(s, _GGA["gps_qual"], 8, "gnss_fix_quality")
    alt = _num(_f(s, _GGA["altitude"]), "altitude", "GGA")
    sep = _num(_f(s, _GGA["geo_sep"]), "geoid separation", "GGA")
    _metres(s, _GGA["altitude_units"], "altitude")
    _metres(s, _GGA["geo_sep_units"], "geoid separation")
    if q == 0 or q is None:
        return {}
    out: dict[str, float] = {"gnss_fix_quality": float(q)}
    if sep is not None:
        out["gnss_geoid_separation"] = sep
    if alt is None:
        return out
    if getattr(opts, "gga_altitude", "msl") == "ellipsoid":
        out["gnss_height"], datum = alt, DATUM_ELLIPSOID
    elif sep is None:
        out["gnss_height"], datum = alt, DATUM_AS_SENT
    else:
        out["gnss_height"], datum = alt + sep, DATUM_ELLIPSOID
    out["gnss_height_datum"] = float(ord(datum))
    return out


def _dec_gst(s: NmeaSentence, opts: Any, problems: list[str]) -> dict[str, float]:
    """GST: 1-σ errors of latitude, longitude and height (m) of the fix of the same UTC time."""
    out: dict[str, float] = {}
    for name, key in (
        ("std_dev_latitude", "gnss_lat_std"),
        ("std_dev_longitude", "gnss_lon_std"),
        ("std_dev_altitude", "gnss_height_std"),
    ):
        v = _num(_f(s, _GST[name]), name.replace("_", " "), "GST")
        if v is not None:
            out[key] = v
    return out


def _height_field(s: NmeaSentence, i: int, key: str) -> tuple[float | None, str]:
    """A Trimble height field ``EHT150.790`` / ``GHT+25.478`` → (metres, datum letter)."""
    raw = _f(s, i)
    if not raw:
        return None, ""
    m = _HEIGHT_RE.match(raw.upper())
    if not m:
        raise NmeaFieldError(f"{key}: height field {raw[:16]!r} is not EHT/GHT + metres", sentence_type="PTNL")
    datum = DATUM_ORTHOMETRIC if m.group(1) == "GHT" else DATUM_ELLIPSOID
    return float(m.group(2).replace(" ", "")), datum


def _dec_ptnl_height(s: NmeaSentence, layout: dict[str, int], key: str) -> dict[str, float]:
    q = _quality(s, layout["quality"], 99, "ptnl_quality")
    h, datum = _height_field(s, layout["height"], key)
    _metres(s, layout["meters"], "height")
    out: dict[str, float] = {}
    if q is not None:
        out["ptnl_quality"] = float(q)
        out["gnss_fix_quality"] = float(TRIMBLE_TO_GGA.get(q, 0))
    if q == 0 or h is None:
        return out
    out["gnss_height"] = h
    out["gnss_height_datum"] = float(ord(datum))
    return out


def dec_ptnl(s: NmeaSentence, opts: Any, problems: list[str]) -> dict[str, float]:
    """``$PTNL,GGK`` (ellipsoidal height ``EHT``) and ``$PTNL,PJK`` (``GHT`` orthometric or ``EHT``): height,
    Trimble's quality (``ptnl_quality``) and its GGA equivalent (``gnss_fix_quality``). Quality 0: no height."""
    sub = _f(s, 0)
    if sub == "GGK":
        return _dec_ptnl_height(s, _GGK, "PTNL,GGK")
    if sub == "PJK":
        return _dec_ptnl_height(s, _PJK, "PTNL,PJK")
    raise NmeaUnsupportedError(f"PTNL,{sub[:8]}: not decoded", sentence_type=f"PTNL,{sub[:8]}")


PTNL_MESSAGES = ("GGK", "PJK")

DECODERS: dict[str, Callable[[NmeaSentence, Any, list[str]], dict[str, float]]] = {"GGA": _dec_gga, "GST": _dec_gst}


def utc_field(s: NmeaSentence) -> str | None:
    """The ``hhmmss.ss`` UTC field of GST, ``$PTNL,GGK`` and ``$PTNL,PJK`` (GGA's is read with RMC's)."""
    if s.type == "GST":
        return _f(s, 0)
    if s.type == "PTNL" and _f(s, 0) in PTNL_MESSAGES:
        return _f(s, 1)
    return None


CHANNELS: dict[str, tuple[str, str]] = {
    "gnss_height": ("gnss_height", "m"),
    "gnss_height_datum": ("gnss_height_datum", "1"),
    "gnss_geoid_separation": ("gnss_geoid_separation", "m"),
    "gnss_fix_quality": ("gnss_fix_quality", "1"),
    "ptnl_quality": ("ptnl_quality", "1"),
    "gnss_lat_std": ("gnss_lat_std", "m"),
    "gnss_lon_std": ("gnss_lon_std", "m"),
    "gnss_height_std": ("gnss_height_std", "m"),
}

LETTER_CODES = {
    "gnss_height_datum": "E ellipsoidal height, A GGA altitude as sent (separation empty: orthometric or "
    "ellipsoidal, the sentence does not say), O orthometric (PJK GHT)",
}

CONVENTIONS = {
    "GGA": "gnss_height = altitude + geoid separation (ellipsoidal, m + up); separation empty → the altitude as "
    "sent (datum A); fix quality 0 → no height",
    "GST": "σ of latitude, longitude and height error, m (1 σ)",
    "PTNL,GGK": "EHT = ellipsoidal height, m + up; Trimble quality → GGA scale (2 RTK float → 5, 3 RTK fixed → 4)",
    "PTNL,PJK": "height as sent: GHT orthometric (the receiver's geoid), EHT ellipsoidal; quality as GGK",
}


def conventions_for(keys: Iterable[str], opts: Any) -> dict[str, str]:
    """The CONVENTIONS entries of the sentence names seen, with the ``gga_altitude`` setting that applied."""
    out: dict[str, str] = {}
    for k in keys:
        c = CONVENTIONS.get(k)
        if c is None:
            continue
        if k == "GGA" and getattr(opts, "gga_altitude", "msl") == "ellipsoid":
            c = "gga_altitude = ellipsoid: the altitude field is taken as the ellipsoidal height (separation not added)"
        out[k] = c
    return out


def height_meta(datum_codes: Any, separations: Any, opts: Any) -> dict[str, Any]:
    """``meta['gnss_height']``: which height datum the ``gnss_height`` rows are in (counts per datum letter), the
    ``gga_altitude`` setting, and a note when the datum is unknown (separation empty), mixed, or the separation
    is 0 (a receiver that writes the ellipsoidal height into the altitude field)."""
    codes = np.asarray(datum_codes, dtype=float)
    codes = codes[np.isfinite(codes)]
    counts = {chr(int(c)): int(n) for c, n in zip(*np.unique(codes, return_counts=True), strict=True)}
    names = {
        DATUM_ELLIPSOID: "ellipsoidal",
        DATUM_AS_SENT: "GGA altitude as sent (separation empty)",
        DATUM_ORTHOMETRIC: "orthometric",
    }
    out: dict[str, Any] = {
        "datum": " + ".join(names[k] for k in counts) if counts else "none",
        "rows_by_datum": counts,
        "gga_altitude": getattr(opts, "gga_altitude", "msl"),
        "unit": "m, + up",
    }
    notes = []
    if DATUM_AS_SENT in counts:
        notes.append(
            "GGA geoid separation empty: gnss_height is the altitude as sent — orthometric by NMEA's definition, "
            "but ellipsoidal on a receiver that has no geoid model; say which with gga_altitude (profile [nmea])"
        )
    n_zero = int(np.count_nonzero(np.asarray(separations, dtype=float) == 0.0)) if separations is not None else 0
    if n_zero:
        out["geoid_separation_zero_rows"] = n_zero
        notes.append(
            f"GGA geoid separation 0 on {n_zero} rows: the receiver writes the ellipsoidal height into the altitude "
            "field (no geoid model); gnss_height is the ellipsoidal height either way"
        )
    if len(counts) > 1:
        notes.append("gnss_height rows in more than one datum: they differ by the geoid separation")
    if notes:
        out["note"] = "; ".join(notes)
    return out
