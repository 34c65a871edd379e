"""Which IEC 61162-1 sentences `imutool live` sends, and when: each at its own rate on the input's clock.

Sentences (formatters of :mod:`formats.nmea`; angles in degrees, heel/roll + starboard down, pitch + bow up):

========  =====  ===========================================================================================
HRM       1 Hz   heel, roll period, amplitudes port/starboard, status A/V, peak-hold port/starboard, reset UTC
XDR       10 Hz  pitch and roll (A, deg, PTCH / ROLL; 2 decimals)
PASHR     10 Hz  UTC time, true heading, roll, pitch, heave (+ up), σ; IMU status 1 only while status A
TSS1      10 Hz  heave (cm, + up), status U (unaided, settled: status A with heave) or u, TSS roll, pitch
HDT       1 Hz   true heading (a gyrocompass input); a magnetometer's heading is sent as HDG instead
THS       1 Hz   true heading with mode A (autonomous) or V (not valid); not sent without a true heading
ROT       1 Hz   rate of turn (deg/min, − to port) with A/V
========  =====  ===========================================================================================

Rates are set per sentence (``--rate XDR=20``) on the input's clock; the talker ID (``--talker``, default II)
applies to all but PASHR and TSS1 (proprietary / talker-less).
"""

from __future__ import annotations

import math
from datetime import datetime, timezone
from typing import Any

from formats.errors import ImutoolError
from formats.nmea import (
    hdg_sentence,
    hdt_sentence,
    hrm_sentence,
    pashr_sentence,
    rot_sentence,
    ths_sentence,
    xdr_sentence,
)
from formats.nmea.motion import euler_roll_to_tss, tss1_frame

from .hub import LiveSnapshot

DEFAULT_RATES = {"HRM": 1.0, "XDR": 10.0, "PASHR": 10.0, "TSS1": 10.0, "HDT": 1.0, "THS": 1.0, "ROT": 1.0}
SENTENCES = tuple(DEFAULT_RATES)


def parse_rates(sentences: list[str] | str, rates: dict[str, float] | list[str] | None = None) -> dict[str, float]:
    """{SENTENCE: Hz} from a list (or 'HRM,XDR') and overrides ('XDR=20' strings or a dict)."""
    names = [s.strip().upper() for s in (sentences.split(",") if isinstance(sentences, str) else sentences)]
    names = [n for n in names if n]
    for n in names:
        if n not in DEFAULT_RATES:
            raise ImutoolError(f"sentence {n!r}: expected some of {', '.join(SENTENCES)}")
    out = {n: DEFAULT_RATES[n] for n in names}
    items = rates.items() if isinstance(rates, dict) else [r.split("=", 1) for r in (rates or [])]
    for item in items:
        if len(item) != 2:
            raise ImutoolError(f"--rate {'='.join(item)!r}: expected SENTENCE=HZ (e.g. XDR=20)")
        k, v = item
        k = str(k).strip().upper()
        try:
            hz = float(v)
        except ValueError:
            raise ImutoolError(f"--rate {k}={v!r}: the rate must be a number (Hz)") from None
        if k not in DEFAULT_RATES:
            raise ImutoolError(f"--rate {k}: expected one of {', '.join(SENTENCES)}")
        if not 0 < hz <= 1000:
            raise ImutoolError(f"--rate {k}={v}: expected 0 < Hz <= 1000")
        out.setdefault(k, hz)
        out[k] = hz
    return out


def _r(v: float | None, d: int = 1) -> float | None:
    return None if v is None or not math.isfinite(v) else v


class SentenceScheduler:
    """``due(t)`` → the sentences due at input time ``t`` (s); ``lines(snapshot, names)`` → bytes (CRLF lines)."""

    def __init__(self, rates: dict[str, float], talker: str = "II") -> None:
        if len(talker) != 2 or not talker.isalnum():
            raise ImutoolError(f"talker {talker!r}: expected two letters or digits (e.g. II, HE, YX)")
        self.rates = dict(rates)
        self.talker = talker.upper()
        self._next: dict[str, float] = {}
        self.counts = {k: 0 for k in rates}

    def due(self, t: float) -> list[str]:
        out = []
        for name, hz in self.rates.items():
            nxt = self._next.get(name)
            if nxt is None or t >= nxt - 1e-9:
                period = 1.0 / hz
                # on a grid of the period (no drift); after a gap the grid restarts at t
                self._next[name] = (nxt + period) if nxt is not None and t - nxt < period else t + period
                out.append(name)
        return out

    def lines(self, s: LiveSnapshot, names: list[str], extra: dict[str, Any] | None = None) -> bytes:
        """The named sentences for snapshot ``s``, each ending in CRLF."""
        out = []
        for name in names:
            line = self.sentence(name, s, extra or {})
            if line is not None:
                out.append(line)
                self.counts[name] = self.counts.get(name, 0) + 1
        return ("\r\n".join(out) + "\r\n").encode("ascii") if out else b""

    def sentence(self, name: str, s: LiveSnapshot, extra: dict[str, Any]) -> str | None:
        ok = s.status == "A"
        tk = self.talker
        if name == "HRM":
            reset = None
            if s.peak_reset_utc:
                reset = datetime.strptime(s.peak_reset_utc, "%Y-%m-%dT%H:%M:%SZ").replace(tzinfo=timezone.utc)
            return hrm_sentence(
                _r(s.roll_deg), _r(s.roll_period_s), _r(s.roll_amp_port_deg), _r(s.roll_amp_stbd_deg), ok,
                _r(s.peak_port_deg), _r(s.peak_stbd_deg), reset, talker=tk,
            )  # fmt: skip
        if name == "XDR":
            return xdr_sentence(
                [("A", _r(s.pitch_deg), "D", "PTCH"), ("A", _r(s.roll_deg), "D", "ROLL")], talker=tk, decimals=2
            )
        if name == "PASHR":
            std = extra.get("std_deg") or (None, None, None)
            return pashr_sentence(
                s.utc, s.heading_deg if s.heading_ref == "true" else None, _r(s.roll_deg), _r(s.pitch_deg),
                s.heave_m, std[0], std[1], std[2], 0, 1 if ok else 0,
            )  # fmt: skip
        if name == "TSS1":
            if s.roll_deg is None or not math.isfinite(s.roll_deg) or not math.isfinite(s.pitch_deg):
                return None
            heave = s.heave_m if s.heave_m is not None else 0.0
            roll = max(-99.99, min(99.99, euler_roll_to_tss(s.roll_deg, s.pitch_deg)))
            pitch = max(-99.99, min(99.99, s.pitch_deg))
            return tss1_frame(max(-99.99, min(99.99, heave)), roll, pitch, "U" if ok and s.heave_m is not None else "u")
        if name == "HDT":
            if s.heading_ref != "true":
                return hdg_sentence(s.heading_deg if ok else None, talker=tk)
            return hdt_sentence(s.heading_deg if ok else None, talker=tk)
        if name == "THS":
            if s.heading_ref != "true":
                return None  # THS is a true heading
            return ths_sentence(s.heading_deg, "A" if ok and s.heading_deg is not None else "V", talker=tk)
        if name == "ROT":
            return rot_sentence(s.rot_deg_min, ok, talker=tk)
        return None
