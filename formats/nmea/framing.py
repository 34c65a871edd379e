"""NMEA 0183 framing: the checksum (its one home in imutool), ``$``/``!`` + address + fields + ``*hh``, the
errors every decoder raises, and the number-field helper. Units and signs: see :mod:`formats.nmea`."""

from __future__ import annotations

import dataclasses
import math
import operator
import re
from functools import reduce

from ..errors import ImutoolError

MAX_SENTENCE_LENGTH = 82  # characters including '$' and <CR><LF> (IEC 61162-1)
CHECKSUM_POLICIES = ("require", "ignore", "accept-missing")
_HHMMSS_RE = re.compile(r"\d{6}(\.\d*)?")


# -- errors ---------------------------------------------------------------------------------------------------
class NmeaParseError(ImutoolError):
    """A line that is not a well-formed sentence (``kind`` = 'malformed')."""

    kind = "malformed"

    def __init__(
        self, message: str, *, sentence_type: str | None = None, path: str | None = None, line: int | None = None
    ):
        super().__init__(message, path=path, line=line)
        self.sentence_type = sentence_type


class NmeaChecksumError(NmeaParseError):
    """Checksum wrong, or missing under ``checksum_policy='require'`` (``kind`` = 'bad_checksum')."""

    kind = "bad_checksum"


class NmeaUnsupportedError(NmeaParseError):
    """Well-formed sentence of a type imutool does not decode (``kind`` = 'unsupported')."""

    kind = "unsupported"


class NmeaFieldError(NmeaParseError):
    """A field that should hold a number holds something else (``kind`` = 'malformed')."""


# -- framing ------------------------------------------------------------------------------------------------------
@dataclasses.dataclass
class NmeaSentence:
    """One framed sentence. ``talker`` is 2 characters ('P' for proprietary); ``formatter`` the rest of the
    address ('HDT'; 'ASHR' for $PASHR); ``fields`` the comma-separated data fields; ``checksum_ok`` True/False,
    or None when the sentence carried no checksum."""

    talker: str
    formatter: str
    fields: list[str]
    checksum_ok: bool | None
    raw: str

    @property
    def type(self) -> str:
        """Type key used for counting and decoding: 'HDT', 'XDR', 'PASHR', 'VDM'..."""
        return "P" + self.formatter if self.talker == "P" else self.formatter

    @property
    def address(self) -> str:
        return self.talker + self.formatter


def checksum_value(body: str | bytes) -> int:
    """The NMEA 0183 checksum as a number 0–255: XOR of every byte between '$'/'!' and '*' (both excluded).
    Text is taken as Latin-1 (a character outside it counts as '?', so it never matches by accident)."""
    data = body if isinstance(body, (bytes, bytearray)) else body.encode("latin-1", "replace")
    return reduce(operator.xor, data, 0) & 0xFF


def checksum(body: str | bytes) -> str:
    """NMEA checksum: XOR of every character between '$'/'!' and '*' (both excluded), as 2 upper-case hex.
    The one implementation in imutool: writers, readers, the reports' capture checks and the bridge protocol
    call this (or :func:`checksum_value`)."""
    return f"{checksum_value(body):02X}"


_BAD_CHAR_RE = re.compile(r"[^\x20-\x7e]|[$!*]")
_ADDR_RE = re.compile(r"^(?:P[A-Z0-9]{1,9}|[A-Z0-9]{2}[A-Z0-9]{3})$")
_HEX2_RE = re.compile(r"[0-9A-Fa-f]{2}")


def parse_sentence(line: str, checksum_policy: str = "require") -> NmeaSentence:
    """Frame and checksum-check one sentence (leading/trailing whitespace and CR/LF are ignored).

    checksum_policy: ``require`` (a missing or wrong checksum raises :class:`NmeaChecksumError`),
    ``accept-missing`` (a missing checksum is accepted, a wrong one raises), ``ignore`` (never raises for the
    checksum; ``checksum_ok`` says what was found). Anything that is not ``$``/``!`` + address + fields raises
    :class:`NmeaParseError` (a subclass of ImutoolError).
    """
    if checksum_policy not in CHECKSUM_POLICIES:
        raise ImutoolError(f"unknown checksum policy {checksum_policy!r} ({', '.join(CHECKSUM_POLICIES)})")
    if not isinstance(line, str):
        raise NmeaParseError("not a text line")
    s = line.strip()
    if len(s) < 7 or s[0] not in "$!":
        raise NmeaParseError("does not start with '$' or '!' followed by an address")
    star = s.rfind("*")
    cs_ok: bool | None
    if star >= 0 and len(s) - star == 3 and _HEX2_RE.fullmatch(s, star + 1):
        body = s[1:star]
        cs_ok = checksum(body) == s[star + 1 :].upper()
    else:
        body = s[1:]
        cs_ok = None
    addr = body.split(",", 1)[0]
    stype = ("P" + addr[1:] if addr[:1] == "P" else addr[2:]) if _ADDR_RE.match(addr) else None
    if cs_ok is False and checksum_policy != "ignore":
        raise NmeaChecksumError(
            f"checksum mismatch (got {s[star + 1 :]}, computed {checksum(body)})", sentence_type=stype
        )
    if cs_ok is None:
        if "*" in body:
            raise NmeaParseError("malformed checksum field", sentence_type=stype)
        if checksum_policy == "require":
            raise NmeaChecksumError("no checksum (checksum policy 'require')", sentence_type=stype)
    if stype is None:
        raise NmeaParseError(f"bad address field {addr[:12]!r}")
    if "," not in body:
        raise NmeaParseError("no data fields", sentence_type=stype)
    bad = _BAD_CHAR_RE.search(body)
    if bad:
        raise NmeaParseError(
            f"illegal character {bad.group()!r} inside the sentence (spliced line?)", sentence_type=stype
        )
    fields = body.split(",")[1:]
    if addr[0] == "P":
        return NmeaSentence("P", addr[1:], fields, cs_ok, s)
    return NmeaSentence(addr[:2], addr[2:], fields, cs_ok, s)


def _num(s: str | None, what: str, stype: str) -> float | None:
    """Float of a field; None for an empty field; NmeaFieldError for garbage."""
    if s is None:
        return None
    s = s.strip()
    if s == "":
        return None
    try:
        v = float(s)
    except ValueError:
        raise NmeaFieldError(f"{stype}: {what} field {s[:16]!r} is not a number", sentence_type=stype) from None
    if not math.isfinite(v):
        raise NmeaFieldError(f"{stype}: {what} field {s[:16]!r} is not finite", sentence_type=stype)
    return v
