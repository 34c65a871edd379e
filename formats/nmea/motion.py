"""The motion sensors' own sentences: Kongsberg Seapath/MRU, iXblue/Exail, Hemisphere, Teledyne RDI, Trimble,
Applanix/OxTS/NovAtel/SBG ``$PASHR``, SBG, Furuno, and the TSS1 frame — decoded into imutool's signs.

Every decoder converts to imutool's conventions (``formats.nmea``): roll + starboard down, pitch + bow up,
heave m + up, heading deg clockwise from true north in [0, 360), rates deg/s (roll/pitch/yaw) and m/s (heave
rate + up), surge m + forward, sway m + starboard. Status and quality fields are kept as channels (numbers as
sent; a status letter as its code point, ``chr(int(v))`` gives it back, described in :data:`LETTER_CODES`).
A value the device itself flags invalid in the same sentence is dropped (its status channel is kept).
:data:`CONVENTIONS` states, per sentence, what the sender's convention is and what was done to it; the log
reader writes it into the recording's metadata.

Layouts, and where they come from (where no public source confirms a sign, the code says so and the value is
decoded as sent):

- ``$PSXN,20/22/23/24`` (Kongsberg Seapath, MRU): field layout of pynmea2's ``SXN20`` … ``SXN24`` (whose doc
  text gives the signs: roll + port side up, pitch + bow up, heave + down, yaw rate + bow to starboard,
  vertical velocity + down); a Seapath 320+ capture in NOAA's NCEI archive gives the real lines.
- ``$PHTRO``, ``$PHLIN``, ``$PHINF``, ``$PHOCT`` (iXblue/Exail): SBG Systems' sbgECom NMEA documentation
  (``doc/nmeaMessages.md``), which emits these iXblue sentences and states their fields and signs (PHTRO
  letters M/P pitch bow up/down, B/T port down/up; PHLIN/PHOCT sway + port, heave + up; PHOCT pitch + bow
  down). iXblue's own interface library was not reachable here.
- ``$PSAT,HPR`` (Hemisphere/CSI): CSI Wireless programming manual §2.14 and a NOAA ship log. The tilt is the
  elevation of the secondary antenna seen from the primary (negative when the secondary is below; the
  ``$JATT,NEGTILT`` setting flips it, ``$JATT,ROLL`` makes it a roll): bow up / starboard down only when the
  secondary antenna is forward / to starboard and NEGTILT is off. Decoded as sent.
- ``$PRDID`` (Teledyne RDI; also Applanix POS MV and SBG): pynmea2's ``RDID`` layout (pitch first); signs
  from SBG's documentation (pitch + bow up, roll + port up). POS MV can send TSS or Tait-Bryan roll here
  (a setting): list ``PRDID`` in ``tss_roll`` for the former.
- ``$PTNL,AVR`` (Trimble moving baseline): pynmea2's ``TNLAVR`` layout and Trimble's receiver help. Yaw is the
  azimuth of the antenna baseline (the heading when antenna 2 is ahead of antenna 1 on the keel line); tilt is
  the baseline's elevation (bow up when antenna 2 is forward), roll likewise across. Trimble does not state
  the signs: decoded as sent.
- ``$PASHR`` (Applanix, OxTS, NovAtel, Trimble RT300, SBG): pynmea2's ``ASHRATT`` layout; 11 fields, or 10
  (NovAtel firmware before 7.03 has no INS-status field). The heave sign differs between vendors (SBG:
  + down, its WASSP variant and Applanix: + up; NovAtel and Trimble do not say): a per-device setting,
  ``pashr_heave_positive`` (default ``up``). The two status fields mean different things per vendor; kept
  as numbers (``pashr_aiding``, ``pashr_imu_status``).
- ``$PSBGA``, ``$PSBGB`` (SBG Systems): sbgECom ``doc/nmeaMessages.md`` (roll + port up, pitch + bow up, PSBGB
  heave + down, body rates x + port up / y + bow up / z clockwise, body velocities FRD).
- ``$PFEC,GPatt`` / ``$PFEC,GPhve`` (Furuno): Furuno SC-120 manual and Kongsberg/Simrad third-party datagram
  pages (yaw = true heading, pitch, roll; heave m + status A). No public source found states the signs:
  decoded as sent.
- TSS1 (``:XXAAAA MHHHHQMRRRR MPPPP``): NovAtel OEM7 TSS1 log. Its roll is the TSS (horizontal-plane) roll,
  asin(sin φ·cos θ), not the Euler roll φ: converted to Euler roll (``tss_roll`` lists the sentence types
  treated so; TSS1 by default).
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Iterable
from typing import Any

from pynmea2.types.proprietary.ash import ASHRATT
from pynmea2.types.proprietary.rdi import RDID
from pynmea2.types.proprietary.sxn import SXN20, SXN22, SXN23, SXN24
from pynmea2.types.proprietary.tnl import TNLAVR

from ..errors import ImutoolError
from . import gnss
from .framing import _HHMMSS_RE, NmeaFieldError, NmeaParseError, NmeaSentence, NmeaUnsupportedError, _num
from .gnss import GGA_ALTITUDES

HEAVE_SIGNS = ("up", "down")


@dataclasses.dataclass(frozen=True)
class MotionOptions:
    """Per-device settings the sentences themselves do not carry.

    pashr_heave_positive: ``up`` (default: Applanix, SBG's WASSP variant, imutool's own writer) or ``down``
    (SBG's PASHR); tss_roll: sentence types whose roll is a TSS (horizontal-plane) roll, converted to Euler
    roll (``TSS1`` by default; add ``PRDID`` or ``EM3000`` where the sender is set to TSS angles); gga_altitude:
    ``msl`` (default, NMEA's definition: GGA's altitude is above the geoid, the ellipsoidal height is altitude +
    separation) or ``ellipsoid`` (a receiver that writes the ellipsoidal height into the altitude field).
    """

    pashr_heave_positive: str = "up"
    tss_roll: frozenset[str] = frozenset({"TSS1"})
    gga_altitude: str = "msl"

    def __post_init__(self) -> None:
        if self.pashr_heave_positive not in HEAVE_SIGNS:
            raise ImutoolError(f"pashr_heave_positive must be 'up' or 'down', not {self.pashr_heave_positive!r}")
        if self.gga_altitude not in GGA_ALTITUDES:
            raise ImutoolError(f"gga_altitude must be 'msl' or 'ellipsoid', not {self.gga_altitude!r}")
        object.__setattr__(self, "tss_roll", frozenset(str(t).strip().upper() for t in self.tss_roll))

    def as_meta(self) -> dict[str, Any]:
        return {
            "pashr_heave_positive": self.pashr_heave_positive,
            "tss_roll": sorted(self.tss_roll),
            "gga_altitude": self.gga_altitude,
        }


DEFAULT_OPTIONS = MotionOptions()


def options_from(
    profile: dict[str, Any] | None = None,
    pashr_heave_positive: str | None = None,
    tss_roll: Iterable[str] | None = None,
    source: str = "profile",
    gga_altitude: str | None = None,
) -> MotionOptions:
    """MotionOptions from a profile's ``[nmea]`` table (keys ``pashr_heave_positive``, ``tss_roll``), then the
    keyword arguments (which win). Unknown keys in ``[nmea]`` are refused (a typo must not pass silently)."""
    table = (profile or {}).get("nmea", {})
    if not isinstance(table, dict):
        raise ImutoolError(f"{source}: [nmea] must be a table")
    unknown = set(table) - {"pashr_heave_positive", "tss_roll", "gga_altitude"}
    if unknown:
        raise ImutoolError(f"{source}: unknown [nmea] key(s) {', '.join(sorted(unknown))}")
    heave = pashr_heave_positive or table.get("pashr_heave_positive", DEFAULT_OPTIONS.pashr_heave_positive)
    tss = tss_roll if tss_roll is not None else table.get("tss_roll", DEFAULT_OPTIONS.tss_roll)
    if isinstance(tss, str):
        tss = [t for t in tss.split(",") if t.strip()]
    alt = gga_altitude or table.get("gga_altitude", DEFAULT_OPTIONS.gga_altitude)
    return MotionOptions(str(heave), frozenset(tss), str(alt))


# -- conversions ---------------------------------------------------------------------------------------------------
def tss_roll_to_euler(roll_tss_deg: float, pitch_deg: float) -> float:
    """Euler (Tait-Bryan) roll φ (deg) from a TSS roll r = asin(sin φ·cos θ) and the pitch θ (deg): the angle of
    the body y axis below the horizontal plane. |sin r| > cos θ (impossible geometry) is clipped to ±90°."""
    c = math.cos(math.radians(pitch_deg))
    x = math.sin(math.radians(roll_tss_deg)) / c if c > 0 else math.copysign(1.0, roll_tss_deg)
    return math.degrees(math.asin(max(-1.0, min(1.0, x))))


def euler_roll_to_tss(roll_deg: float, pitch_deg: float) -> float:
    """TSS (horizontal-plane) roll asin(sin φ·cos θ) in deg from Euler roll φ and pitch θ (deg)."""
    return math.degrees(math.asin(math.sin(math.radians(roll_deg)) * math.cos(math.radians(pitch_deg))))


# -- helpers -------------------------------------------------------------------------------------------------------
def _layout(cls: type) -> dict[str, int]:
    """Field name → index in NmeaSentence.fields, from a pynmea2 proprietary class (whose data list starts with
    the rest of the address, so its index is ours + 1)."""
    return {f[1]: i - 1 for i, f in enumerate(cls.fields)}


_SXN20, _SXN22, _SXN23, _SXN24 = _layout(SXN20), _layout(SXN22), _layout(SXN23), _layout(SXN24)
_RDID, _AVR, _ASHR = _layout(RDID), _layout(TNLAVR), _layout(ASHRATT)


def _field(s: NmeaSentence, i: int) -> str:
    return s.fields[i].strip() if 0 <= i < len(s.fields) else ""


def _val(s: NmeaSentence, i: int, what: str) -> float | None:
    return _num(_field(s, i), what, s.type)


def _put(out: dict[str, float], key: str, v: float | None, sign: float = 1.0) -> None:
    if v is not None:
        out[key] = sign * v + 0.0  # + 0.0: a negated zero is written as 0.0


def _heading(out: dict[str, float], v: float | None) -> None:
    if v is not None:
        out["heading_true"] = v % 360.0


def _code(out: dict[str, float], key: str, letter: str, allowed: str, stype: str) -> None:
    """A one-letter status as its code point; an unknown letter is a field error."""
    if not letter:
        return
    if len(letter) != 1 or letter not in allowed:
        raise NmeaFieldError(f"{stype}: status {letter[:8]!r} is not one of {allowed}", sentence_type=stype)
    out[key] = float(ord(letter))


def _int_status(out: dict[str, float], key: str, s: NmeaSentence, i: int, allowed: Iterable[int]) -> int | None:
    v = _val(s, i, key)
    if v is None:
        return None
    if v != int(v) or int(v) not in allowed:
        raise NmeaFieldError(
            f"{s.type}: {key} {_field(s, i)[:8]!r} is not one of {sorted(allowed)}", sentence_type=s.type
        )
    out[key] = float(int(v))
    return int(v)


def _unsupported(s: NmeaSentence, what: str) -> NmeaUnsupportedError:
    return NmeaUnsupportedError(f"{count_key(s)}: {what}", sentence_type=count_key(s))


# -- Kongsberg Seapath / MRU ---------------------------------------------------------------------------------------
def _dec_psxn(s: NmeaSentence, opts: MotionOptions, problems: list[str]) -> dict[str, float]:
    """$PSXN,20 quality (0 normal, 1 reduced performance, 2 invalid), 22 gyro calibration/offset (deg),
    23 roll/pitch/heading/heave (heave + down in the sentence → + up; may be empty), 24 rates (deg/s) and
    vertical velocity (+ down → ``heave_rate`` + up)."""
    sub = _field(s, 0)
    out: dict[str, float] = {}
    if sub == "20":
        for attr, key in (
            ("horiz_qual", "psxn_quality_horizontal"),
            ("hgt_qual", "psxn_quality_height"),
            ("head_qual", "psxn_quality_heading"),
            ("rp_qual", "psxn_quality_roll_pitch"),
        ):
            _int_status(out, key, s, _SXN20[attr], (0, 1, 2))
    elif sub == "22":
        _put(out, "psxn_gyro_calibration", _val(s, _SXN22["gyro_calib"], "gyro calibration"))
        _put(out, "psxn_gyro_offset", _val(s, _SXN22["gyro_ffs"], "gyro offset"))
    elif sub == "23":
        _put(out, "roll", _val(s, _SXN23["roll"], "roll"))  # + port side up = + starboard down
        _put(out, "pitch", _val(s, _SXN23["pitch"], "pitch"))
        _heading(out, _val(s, _SXN23["head"], "heading"))
        _put(out, "heave", _val(s, _SXN23["heave"], "heave"), -1.0)  # + down → + up
    elif sub == "24":
        _put(out, "roll_rate", _val(s, _SXN24["roll_rate"], "roll rate"))
        _put(out, "pitch_rate", _val(s, _SXN24["pitch_rate"], "pitch rate"))
        _put(out, "yaw_rate", _val(s, _SXN24["yaw_rate"], "yaw rate"))
        _put(out, "heave_rate", _val(s, _SXN24["vertical_vel"], "vertical velocity"), -1.0)  # + down → + up
    else:
        raise _unsupported(s, "only PSXN,20/22/23/24 are decoded")
    return out


# -- iXblue / Exail ------------------------------------------------------------------------------------------------
def _signed_by_letter(s: NmeaSentence, i: int, what: str, plus: str, minus: str) -> float | None:
    """A magnitude followed by a direction letter (PHTRO)."""
    v = _val(s, i, what)
    letter = _field(s, i + 1).upper()
    if v is None:
        return None
    if letter not in (plus, minus):
        raise NmeaFieldError(f"PHTRO: {what} letter {letter[:4]!r} is not {plus} or {minus}", sentence_type="PHTRO")
    if v < 0:
        raise NmeaFieldError(f"PHTRO: {what} {v:g} is signed; the letter gives the sign", sentence_type="PHTRO")
    return v if letter == plus else -v


def _dec_phtro(s: NmeaSentence, opts: MotionOptions, problems: list[str]) -> dict[str, float]:
    """$PHTRO,pitch,M|P,roll,B|T: pitch M = bow up (+), P = bow down; roll T = port up (+ starboard down),
    B = port down."""
    out: dict[str, float] = {}
    _put(out, "pitch", _signed_by_letter(s, 0, "pitch", "M", "P"))
    _put(out, "roll", _signed_by_letter(s, 2, "roll", "T", "B"))
    return out


def _dec_phlin(s: NmeaSentence, opts: MotionOptions, problems: list[str]) -> dict[str, float]:
    """$PHLIN,surge,sway,heave (m): surge + forward, sway + port (→ + starboard), heave + up."""
    out: dict[str, float] = {}
    _put(out, "surge", _val(s, 0, "surge"))
    _put(out, "sway", _val(s, 1, "sway"), -1.0)
    _put(out, "heave", _val(s, 2, "heave"))
    return out


_HEX8_RE = re.compile(r"[0-9A-Fa-f]{1,8}")


def _dec_phinf(s: NmeaSentence, opts: MotionOptions, problems: list[str]) -> dict[str, float]:
    """$PHINF,hhhhhhhh: the 32-bit status word (bit 0 heading, 1 roll, 2 pitch invalid or converging, 3 heave
    initialising, 5 alignment, 27 a heading/roll/pitch component invalid) as ``phinf_status``."""
    h = _field(s, 0)
    if not h:
        return {}
    if not _HEX8_RE.fullmatch(h):
        raise NmeaFieldError(f"PHINF: status {h[:12]!r} is not 8 hex digits", sentence_type="PHINF")
    return {"phinf_status": float(int(h, 16))}


_PHOCT_STATUS = "TEI"  # valid, invalid, initialising


def _dec_phoct(s: NmeaSentence, opts: MotionOptions, problems: list[str]) -> dict[str, float]:
    """$PHOCT,01,time,utc status,latency,heading,status,roll,status,pitch,status,primary heave,heave status,
    heave,surge,sway,heave speed,surge speed,sway speed,heading rate. Roll + port up, pitch + bow DOWN (→
    negated), heave + up, sway + port (→ negated), heading rate deg/min + clockwise (→ ``rot``). Status E
    (invalid) drops the values it covers; I (initialising) keeps them."""
    if _field(s, 0) != "01":
        raise _unsupported(s, f"PHOCT protocol version {_field(s, 0)[:4]!r} (only 01 is decoded)")
    out: dict[str, float] = {}
    st = {}
    for i, name in ((5, "heading"), (7, "roll"), (9, "pitch"), (11, "heave")):
        letter = _field(s, i).upper()
        _code(out, f"phoct_{name}_status", letter, _PHOCT_STATUS, "PHOCT")
        st[name] = letter
    if st["heading"] != "E":
        _heading(out, _val(s, 4, "heading"))
        _put(out, "rot", _val(s, 18, "heading rate"))
    if st["roll"] != "E":
        _put(out, "roll", _val(s, 6, "roll"))
    if st["pitch"] != "E":
        _put(out, "pitch", _val(s, 8, "pitch"), -1.0)
    if st["heave"] != "E":
        _put(out, "heave_primary", _val(s, 10, "primary heave"))
        _put(out, "heave", _val(s, 12, "heave"))
        _put(out, "surge", _val(s, 13, "surge"))
        _put(out, "sway", _val(s, 14, "sway"), -1.0)
        _put(out, "heave_rate", _val(s, 15, "heave speed"))
        _put(out, "surge_rate", _val(s, 16, "surge speed"))
        _put(out, "sway_rate", _val(s, 17, "sway speed"), -1.0)
    return out


# -- Hemisphere, Teledyne RDI, Trimble -----------------------------------------------------------------------------
def _dec_psat(s: NmeaSentence, opts: MotionOptions, problems: list[str]) -> dict[str, float]:
    """$PSAT,HPR,time,heading,pitch,roll,N|G (heading source GNSS / gyro). Pitch or roll may be empty (two
    antennas measure one of them). Signs as sent: the secondary antenna's elevation seen from the primary,
    flipped by the receiver's NEGTILT setting (see the module docstring)."""
    if _field(s, 0) != "HPR":
        raise _unsupported(s, "only PSAT,HPR is decoded")
    out: dict[str, float] = {}
    _heading(out, _val(s, 2, "heading"))
    _put(out, "pitch", _val(s, 3, "pitch"))
    _put(out, "roll", _val(s, 4, "roll"))
    _code(out, "psat_heading_source", _field(s, 5).upper(), "NG", "PSAT")
    return out


def _dec_prdid(s: NmeaSentence, opts: MotionOptions, problems: list[str]) -> dict[str, float]:
    """$PRDID,pitch,roll,heading (pitch FIRST): pitch + bow up, roll + port up (= + starboard down)."""
    out: dict[str, float] = {}
    _put(out, "pitch", _val(s, _RDID["pitch"], "pitch"))
    _put(out, "roll", _val(s, _RDID["roll"], "roll"))
    _heading(out, _val(s, _RDID["heading"], "heading"))
    if "PRDID" in opts.tss_roll and "roll" in out and "pitch" in out:
        out["roll"] = tss_roll_to_euler(out["roll"], out["pitch"])
    return out


def _dec_ptnl(s: NmeaSentence, opts: MotionOptions, problems: list[str]) -> dict[str, float]:
    """$PTNL,AVR,time,yaw,Yaw,tilt,Tilt,roll,Roll,range,quality,PDOP,satellites: the moving-baseline vector.
    Quality 0 (no fix) drops the angles; the label after a value says what it is (some senders put a roll in
    the tilt slot, labelled ``Roll``)."""
    if _field(s, 0) in gnss.PTNL_MESSAGES:
        return gnss.dec_ptnl(s, opts, problems)
    if _field(s, 0) != "AVR":
        raise _unsupported(s, "only PTNL,AVR, PTNL,GGK and PTNL,PJK are decoded")
    out: dict[str, float] = {}
    q = _int_status(out, "avr_quality", s, _AVR["gps_quality"], range(10))
    _put(out, "avr_baseline", _val(s, _AVR["baseline"], "range"))
    if q == 0:
        return out
    _heading(out, _val(s, _AVR["yaw_angle"], "yaw"))
    for vi, li in ((_AVR["tilt_angle"], _AVR["tilt"]), (_AVR["roll_angle"], _AVR["roll"])):
        label = _field(s, li).upper()
        v = _val(s, vi, label.lower() or "tilt/roll")
        if v is None:
            continue
        if label == "TILT":
            out["pitch"] = v
        elif label == "ROLL":
            out["roll"] = v
        else:
            raise NmeaFieldError(
                f"PTNL,AVR: value {v:g} labelled {label[:8]!r}, not Tilt or Roll", sentence_type="PTNL"
            )
    return out


# -- $PASHR --------------------------------------------------------------------------------------------------------
def _dec_pashr(s: NmeaSentence, opts: MotionOptions, problems: list[str]) -> dict[str, float]:
    """$PASHR attitude: time, heading, 'T', roll, pitch, heave, roll/pitch/heading σ (deg), aiding/quality flag,
    [IMU/INS status]. Roll + starboard down, pitch + bow up (OxTS, Applanix); heave sign per device
    (``pashr_heave_positive``). Ashtech replies ($PASHR,ACK / POS / ATT ...) are unsupported."""
    f0 = _field(s, 0)
    if (f0 and not _HHMMSS_RE.fullmatch(f0)) or len(s.fields) < 6:
        raise _unsupported(s, "not an attitude sentence (Ashtech reply)")
    out: dict[str, float] = {}
    h = _val(s, _ASHR["true_heading"], "heading")
    if h is not None and _field(s, _ASHR["is_true_heading"]).upper() == "T":
        _heading(out, h)
    _put(out, "roll", _val(s, _ASHR["roll"], "roll"))
    _put(out, "pitch", _val(s, _ASHR["pitch"], "pitch"))
    _put(out, "heave", _val(s, _ASHR["heave"], "heave"), 1.0 if opts.pashr_heave_positive == "up" else -1.0)
    _put(out, "roll_std", _val(s, _ASHR["roll_accuracy"], "roll accuracy"))
    _put(out, "pitch_std", _val(s, _ASHR["pitch_accuracy"], "pitch accuracy"))
    _put(out, "heading_std", _val(s, _ASHR["heading_accuracy"], "heading accuracy"))
    _put(out, "pashr_aiding", _val(s, _ASHR["aiding_status"], "aiding status"))
    _put(out, "pashr_imu_status", _val(s, _ASHR["imu_status"], "IMU status"))
    return out


# -- SBG Systems ---------------------------------------------------------------------------------------------------
_SBG_SOLUTION = "abcdefghijklmnopqrstuvABCDEFGHIJKLMNOPQRSTUV"


def _dec_psbga(s: NmeaSentence, opts: MotionOptions, problems: list[str]) -> dict[str, float]:
    """$PSBGA,time,utc status,roll,pitch,heading,roll σ,pitch σ,heading σ,solution,rp status,heading status:
    roll + port up, pitch + bow up; status i (invalid) drops roll/pitch or heading, v = valid."""
    out: dict[str, float] = {}
    _code(out, "psbga_solution", _field(s, 8), _SBG_SOLUTION, "PSBGA")
    rp, hd = _field(s, 9), _field(s, 10)
    _code(out, "psbga_roll_pitch_status", rp, "iv", "PSBGA")
    _code(out, "psbga_heading_status", hd, "iv", "PSBGA")
    if rp != "i":
        _put(out, "roll", _val(s, 2, "roll"))
        _put(out, "pitch", _val(s, 3, "pitch"))
    if hd != "i":
        _heading(out, _val(s, 4, "heading"))
    _put(out, "roll_std", _val(s, 5, "roll std"))
    _put(out, "pitch_std", _val(s, 6, "pitch std"))
    _put(out, "heading_std", _val(s, 7, "heading std"))
    return out


def _dec_psbgb(s: NmeaSentence, opts: MotionOptions, problems: list[str]) -> dict[str, float]:
    """$PSBGB,1,time,utc status,roll,pitch,heading,σ×3,rp status,heading status,heave,heave σ,heave status,
    rate x,y,z,velocity x,y,z,velocity σ,velocity status: roll + port up, pitch + bow up, heave + down (→ + up),
    body rates deg/s (x + port up, y + bow up, z clockwise: FRD), body velocity m/s FRD. Status 0 (invalid)
    drops what it covers; 1 optimal, 2 degraded (heave: 1 velocity aided, 2 standalone)."""
    if _field(s, 0) != "1":
        raise _unsupported(s, f"PSBGB version {_field(s, 0)[:4]!r} (only 1 is decoded)")
    out: dict[str, float] = {}
    rp = _int_status(out, "psbgb_roll_pitch_status", s, 9, (0, 1, 2))
    hd = _int_status(out, "psbgb_heading_status", s, 10, (0, 1, 2))
    hv = _int_status(out, "psbgb_heave_status", s, 13, (0, 1, 2))
    vs = _int_status(out, "psbgb_velocity_status", s, 21, (0, 1, 2))
    if rp != 0:
        _put(out, "roll", _val(s, 3, "roll"))
        _put(out, "pitch", _val(s, 4, "pitch"))
    if hd != 0:
        _heading(out, _val(s, 5, "heading"))
    _put(out, "roll_std", _val(s, 6, "roll std"))
    _put(out, "pitch_std", _val(s, 7, "pitch std"))
    _put(out, "heading_std", _val(s, 8, "heading std"))
    if hv != 0:
        _put(out, "heave", _val(s, 11, "heave"), -1.0)
    _put(out, "heave_std", _val(s, 12, "heave std"))
    _put(out, "roll_rate", _val(s, 14, "rate x"))
    _put(out, "pitch_rate", _val(s, 15, "rate y"))
    _put(out, "yaw_rate", _val(s, 16, "rate z"))
    if vs != 0:
        for i, key in ((17, "body_vel_x"), (18, "body_vel_y"), (19, "body_vel_z")):
            _put(out, key, _val(s, i, key))
    return out


# -- Furuno --------------------------------------------------------------------------------------------------------
def _dec_pfec(s: NmeaSentence, opts: MotionOptions, problems: list[str]) -> dict[str, float]:
    """$PFEC,GPatt,yaw,pitch,roll (deg; yaw = true heading) and $PFEC,GPhve,heave,status (m; V drops it).
    Furuno's public pages do not state the signs: values as sent."""
    sub = _field(s, 0)
    out: dict[str, float] = {}
    if sub == "GPatt":
        _heading(out, _val(s, 1, "yaw"))
        _put(out, "pitch", _val(s, 2, "pitch"))
        _put(out, "roll", _val(s, 3, "roll"))
    elif sub == "GPhve":
        status = _field(s, 2).upper()
        _code(out, "pfec_heave_status", status, "AV", "PFEC")
        if status != "V":
            _put(out, "heave", _val(s, 1, "heave"))
    else:
        raise _unsupported(s, "only PFEC,GPatt and PFEC,GPhve are decoded")
    return out


# -- TSS1 (not NMEA: fixed-length ASCII heave/roll/pitch frame) ----------------------------------------------------
TSS1_LENGTH = 27  # characters including CR/LF
TSS1_STATUS = "UuGgHhFf"  # Unaided, GNSS(speed) aided, Heading aided, Full aided; lower case = settling
_TSS1_RE = re.compile(r"^:([0-9A-F]{2})([0-9A-F]{4}) ([ -])(\d{4})([A-Za-z])([ -])(\d{4}) ([ -])(\d{4})$")


def _tss1_signed(v: float, scale: float, what: str) -> str:
    n = int(round(v * scale))
    if abs(n) > 9999:
        raise ImutoolError(f"TSS1: {what} {v:g} is outside the frame's range (±{9999 / scale:g})")
    return ("-" if n < 0 else " ") + f"{abs(n):04d}"


def tss1_frame(
    heave_m: float,
    roll_deg: float,
    pitch_deg: float,
    status: str = "U",
    horizontal_accel_m_s2: float = 0.0,
    vertical_accel_m_s2: float = 0.0,
) -> str:
    """TSS1 frame ``:XXAAAA MHHHHQMRRRR MPPPP`` (no CR/LF; 25 characters, 27 with CR/LF).

    Layout (NovAtel OEM7 "TSS1" log; Norwegian Subsea and Kongsberg EK80 TSS1 pages): XX horizontal acceleration,
    unsigned hex, 3.83 cm/s² per bit (0–9.81 m/s²); AAAA vertical acceleration, 16-bit two's-complement hex,
    0.0625 cm/s² per bit (±20.48 m/s²); space; heave sign (space or '-') and 4 digits in cm; status Q
    (:data:`TSS1_STATUS`); roll sign and 4 digits in 0.01° (+ = port up, i.e. starboard down); space; pitch sign
    and 4 digits in 0.01° (+ bow up). The caller chooses the heave sign (TSS1 itself defines + = up) and the roll
    (TSS1 defines the TSS roll; :func:`euler_roll_to_tss` converts an Euler roll)."""
    if status not in TSS1_STATUS or len(status) != 1:
        raise ImutoolError(f"TSS1 status {status!r} must be one of {TSS1_STATUS}")
    for v, what in ((heave_m, "heave"), (roll_deg, "roll"), (pitch_deg, "pitch")):
        if v is None or not math.isfinite(v):
            raise ImutoolError(f"TSS1: {what} is missing (the frame has no empty field)")
    xx = min(255, max(0, int(round(abs(horizontal_accel_m_s2 or 0.0) / 0.0383))))
    va = int(round((vertical_accel_m_s2 or 0.0) / 0.000625))
    va = min(32767, max(-32768, va)) & 0xFFFF
    return (
        f":{xx:02X}{va:04X} "
        + _tss1_signed(heave_m, 100.0, "heave")
        + status
        + _tss1_signed(roll_deg, 100.0, "roll")
        + " "
        + _tss1_signed(pitch_deg, 100.0, "pitch")
    )


def parse_tss1(line: str) -> dict[str, float | str]:
    """Decode one TSS1 frame (CR/LF optional) as sent: horizontal_accel, vertical_accel (m/s²), heave (m),
    status (letter), settled (1.0/0.0 from the letter's case), roll (the TSS roll), pitch (deg).
    Raises NmeaParseError. :func:`decode_tss1` gives imutool's channels (Euler roll)."""
    s = line.rstrip("\r\n")
    m = _TSS1_RE.match(s)
    if not m:
        raise NmeaParseError(f"not a TSS1 frame: {s[:30]!r}", sentence_type="TSS1")
    xx, aaaa, hs, hv, q, rs, rv, ps, pv = m.groups()
    if q not in TSS1_STATUS:
        raise NmeaFieldError(f"TSS1: status {q!r} is not one of {TSS1_STATUS}", sentence_type="TSS1")
    va = int(aaaa, 16)
    va = va - 0x10000 if va >= 0x8000 else va

    def sg(sign: str, digits: str, scale: float) -> float:
        return (-1.0 if sign == "-" else 1.0) * int(digits) / scale

    return {
        "horizontal_accel": int(xx, 16) * 0.0383,
        "vertical_accel": va * 0.000625,
        "heave": sg(hs, hv, 100.0),
        "status": q,
        "settled": 1.0 if q.isupper() else 0.0,
        "roll": sg(rs, rv, 100.0),
        "pitch": sg(ps, pv, 100.0),
    }


def decode_tss1(line: str, opts: MotionOptions = DEFAULT_OPTIONS) -> dict[str, float]:
    """A TSS1 frame as imutool channels: heave (m + up), roll (Euler, converted from the TSS roll unless
    ``TSS1`` is left out of ``opts.tss_roll``), pitch, settled, tss1_status (code point), tss1_accel_horizontal,
    tss1_accel_vertical (m/s²)."""
    d = parse_tss1(line)
    roll = float(d["roll"])
    if "TSS1" in opts.tss_roll:
        roll = tss_roll_to_euler(roll, float(d["pitch"]))
    return {
        "heave": float(d["heave"]),
        "roll": roll,
        "pitch": float(d["pitch"]),
        "settled": float(d["settled"]),
        "tss1_status": float(ord(str(d["status"]))),
        "tss1_accel_horizontal": float(d["horizontal_accel"]),
        "tss1_accel_vertical": float(d["vertical_accel"]),
    }


def is_tss1(text: str) -> bool:
    """Whether a stripped line is shaped like a TSS1 frame (starts with ':' and is 25 characters long)."""
    return len(text) == 25 and text[0] == ":"


# -- registry ------------------------------------------------------------------------------------------------------
DECODERS: dict[str, Callable[[NmeaSentence, MotionOptions, list[str]], dict[str, float]]] = {
    "PSXN": _dec_psxn,
    "PHTRO": _dec_phtro,
    "PHLIN": _dec_phlin,
    "PHINF": _dec_phinf,
    "PHOCT": _dec_phoct,
    "PSAT": _dec_psat,
    "PRDID": _dec_prdid,
    "PTNL": _dec_ptnl,
    "PASHR": _dec_pashr,
    "PSBGA": _dec_psbga,
    "PSBGB": _dec_psbgb,
    "PFEC": _dec_pfec,
}

# proprietary sentences whose first field names the message: counted (and named) as "PSXN,23", "PFEC,GPatt"...
_SUBTYPED = {"PSXN", "PTNL", "PSAT", "PFEC", "PSTI"}
_SUBTYPE_RE = re.compile(r"[A-Za-z0-9]{1,8}")


def count_key(s: NmeaSentence) -> str:
    """The name a sentence is counted under: its type, with the message id for multi-message proprietary
    addresses (``PSXN,23``, ``PTNL,AVR``, ``PFEC,GPatt``; an Ashtech reply ``PASHR,ACK``)."""
    return count_key_of(s.type, s.fields[0] if s.fields else "")


def count_key_of(stype: str, first_field: str) -> str:
    """:func:`count_key` from the sentence type and its first data field (also for a line that failed its
    checksum, so that its count lands under the same name)."""
    first = first_field.strip()
    if stype in _SUBTYPED and _SUBTYPE_RE.fullmatch(first):
        return f"{stype},{first}"
    if stype == "PASHR" and first.isalpha() and _SUBTYPE_RE.fullmatch(first):
        return f"{stype},{first}"
    return stype


def utc_field(s: NmeaSentence) -> str | None:
    """The ``hhmmss.ss`` UTC field of a motion sentence that carries a valid one (PSBGA, PSBGB, PHOCT with its
    UTC status valid; PTNL,AVR), else None. PSAT,HPR is left out: CSI's manual calls its time GPS time."""
    t = s.type
    if t == "PSBGA" and _field(s, 1).lower() in ("v", "d"):
        return _field(s, 0)
    if t == "PSBGB" and _field(s, 2) in ("1", "2", "3", "4"):
        return _field(s, 1)
    if t == "PHOCT" and _field(s, 2).upper() == "T":
        return _field(s, 1)
    if t == "PTNL" and _field(s, 0) == "AVR":
        return _field(s, 1)
    return gnss.utc_field(s)


# Recording channels of the motion sentences: decode key → (channel, unit)
CHANNELS: dict[str, tuple[str, str]] = {
    "roll_rate": ("roll_rate", "deg/s"),
    "pitch_rate": ("pitch_rate", "deg/s"),
    "yaw_rate": ("yaw_rate", "deg/s"),
    "heave_rate": ("heave_rate", "m/s"),
    "heave_primary": ("heave_primary", "m"),
    "surge": ("surge", "m"),
    "sway": ("sway", "m"),
    "surge_rate": ("surge_rate", "m/s"),
    "sway_rate": ("sway_rate", "m/s"),
    "roll_std": ("roll_std", "deg"),
    "pitch_std": ("pitch_std", "deg"),
    "heading_std": ("heading_std", "deg"),
    "heave_std": ("heave_std", "m"),
    "body_vel_x": ("body_vel_x", "m/s"),
    "body_vel_y": ("body_vel_y", "m/s"),
    "body_vel_z": ("body_vel_z", "m/s"),
    "settled": ("settled", "1"),
    "psxn_quality_horizontal": ("psxn_quality_horizontal", "1"),
    "psxn_quality_height": ("psxn_quality_height", "1"),
    "psxn_quality_heading": ("psxn_quality_heading", "1"),
    "psxn_quality_roll_pitch": ("psxn_quality_roll_pitch", "1"),
    "psxn_gyro_calibration": ("psxn_gyro_calibration", "deg"),
    "psxn_gyro_offset": ("psxn_gyro_offset", "deg"),
    "phinf_status": ("phinf_status", "1"),
    "phoct_heading_status": ("phoct_heading_status", "1"),
    "phoct_roll_status": ("phoct_roll_status", "1"),
    "phoct_pitch_status": ("phoct_pitch_status", "1"),
    "phoct_heave_status": ("phoct_heave_status", "1"),
    "psat_heading_source": ("psat_heading_source", "1"),
    "avr_quality": ("avr_quality", "1"),
    "avr_baseline": ("avr_baseline", "m"),
    "pashr_aiding": ("pashr_aiding", "1"),
    "pashr_imu_status": ("pashr_imu_status", "1"),
    "psbga_solution": ("psbga_solution", "1"),
    "psbga_roll_pitch_status": ("psbga_roll_pitch_status", "1"),
    "psbga_heading_status": ("psbga_heading_status", "1"),
    "psbgb_roll_pitch_status": ("psbgb_roll_pitch_status", "1"),
    "psbgb_heading_status": ("psbgb_heading_status", "1"),
    "psbgb_heave_status": ("psbgb_heave_status", "1"),
    "psbgb_velocity_status": ("psbgb_velocity_status", "1"),
    "pfec_heave_status": ("pfec_heave_status", "1"),
    "tss1_status": ("tss1_status", "1"),
    "tss1_accel_horizontal": ("tss1_accel_horizontal", "m/s^2"),
    "tss1_accel_vertical": ("tss1_accel_vertical", "m/s^2"),
}

# channels holding a status letter's code point: what the letters mean
LETTER_CODES: dict[str, str] = {
    "phoct_heading_status": "T valid, E invalid (value dropped), I initialising",
    "phoct_roll_status": "T valid, E invalid (value dropped), I initialising",
    "phoct_pitch_status": "T valid, E invalid (value dropped), I initialising",
    "phoct_heave_status": "T valid, E invalid (heave, surge, sway and speeds dropped), I initialising",
    "psat_heading_source": "N GNSS, G gyro",
    "psbga_solution": "SBG smart solution type a..v (lower case: INS not yet aligned)",
    "psbga_roll_pitch_status": "v valid, i invalid (value dropped)",
    "psbga_heading_status": "v valid, i invalid (value dropped)",
    "pfec_heave_status": "A valid, V invalid (value dropped)",
    "tss1_status": "U unaided, G GNSS aided, H heading aided, F fully aided; lower case while settling",
}

# What each sender's convention is and what the reader did (keyed by count_key; written into the metadata)
CONVENTIONS: dict[str, str] = {
    "PSXN,20": "Seapath quality 0 normal, 1 reduced performance, 2 invalid (kept as channels)",
    "PSXN,22": "Seapath gyro calibration and short-term offset, deg",
    "PSXN,23": "roll + port up (= imutool), pitch + bow up, heading true; heave + DOWN in the sentence → negated",
    "PSXN,24": "rates deg/s (roll + port up, pitch + bow up, yaw + to starboard); vertical velocity + down → "
    "heave_rate + up",
    "PHTRO": "pitch letter M bow up / P bow down, roll letter T port up / B port down → signed",
    "PHLIN": "surge + forward, sway + PORT → negated, heave + up",
    "PHINF": "iXblue status word (bit 0 heading, 1 roll, 2 pitch invalid; 3 heave initialising) as phinf_status",
    "PHOCT": "roll + port up, pitch + bow DOWN → negated, heave + up, sway + PORT → negated, heading rate "
    "deg/min + clockwise → rot; status E drops the values",
    "PSAT,HPR": "Hemisphere heading true; pitch/roll as sent: + when the secondary antenna is above the primary "
    "(the receiver's NEGTILT setting flips it)",
    "PRDID": "pitch FIRST; pitch + bow up, roll + port up (= imutool), heading",
    "PTNL,AVR": "baseline yaw → heading, tilt → pitch, roll → roll as sent (Trimble states no sign)",
    "PASHR": "roll + starboard down, pitch + bow up, heading true; heave sign per device (setting "
    "pashr_heave_positive)",
    "PSBGA": "roll + port up (= imutool), pitch + bow up, heading true; status i drops the values",
    "PSBGB": "roll + port up, pitch + bow up, heave + DOWN → negated; body rates and velocities FRD",
    "PFEC,GPatt": "Furuno yaw (heading true), pitch, roll as sent (sign convention not documented publicly)",
    "PFEC,GPhve": "Furuno heave as sent (sign convention not documented publicly); status V drops it",
    "TSS1": "heave + up, pitch + bow up; roll is the TSS roll asin(sin φ·cos θ) → Euler roll φ (unless tss_roll "
    "leaves TSS1 out)",
    "EM3000": "roll + port up, pitch + bow up, heave + up, heading 0..359.99, 0.01° / 1 cm; status byte kept",
}


def conventions_for(keys: Iterable[str], opts: MotionOptions) -> dict[str, str]:
    """The CONVENTIONS entries of the sentence names seen, with the per-device settings that applied."""
    out: dict[str, str] = {}
    for k in keys:
        c = CONVENTIONS.get(k)
        if c is None:
            continue
        if k == "PASHR":
            c += f": heave + {opts.pashr_heave_positive} assumed"
            c += "" if opts.pashr_heave_positive == "up" else " → negated"
        if k == "PRDID" and "PRDID" in opts.tss_roll:
            c += "; roll taken as TSS roll → Euler roll"
        if k == "TSS1" and "TSS1" not in opts.tss_roll:
            c = "heave + up, pitch + bow up; roll kept as the TSS roll asin(sin φ·cos θ) (tss_roll leaves TSS1 out)"
        out[k] = c
    return out
