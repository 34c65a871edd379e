"""Status A/V of the live outputs, honest: A only while the estimate can be trusted, V with its cause otherwise.

Causes (each a short phrase; several may hold at once, joined by '; '):

- ``settling (N of S s after start)`` / ``settling (roll/pitch sigma ...)`` — the filter's start-up: ``settle_s``
  must have passed since the first sample (the engine decides an ``auto`` motion model then) and the roll/pitch
  σ must be within ``max_tilt_std_deg`` (1°);
- ``no samples for X s`` — nothing arrived for more than ``stale_s`` (1 s; the sensor unplugged or silent);
- ``input saturated`` — an accelerometer or gyro sample at its range limit in the last ``hold_s``;
- ``self-check inconsistent`` — the filter's own consistency test (windowed NIS, tilt window) failed in the last
  ``hold_s``;
- the windowed self-checks of :mod:`.checks` (gyro scale, stuck input, accelerometer far from g), each with
  its own window and a clearing hysteresis;
- ``filter out of bounds`` — the roll/pitch σ above 1.5 × ``max_tilt_std_deg`` after settling (e.g. after an
  outage);
- ``no heading`` — for the heading sentences only (HDT/THS/ROT carry their own V).

Every change of status is logged with its UTC and the cause (``log``).
"""

from __future__ import annotations

from collections.abc import Callable

STALE_S = 1.0  # s without samples → V
HOLD_S = 2.0  # s a saturation or inconsistency keeps the status V after its last sample
MAX_TILT_STD_DEG = 1.0  # deg: roll/pitch σ to reach before A (MSC.363(92) asks ±1° of the heel)
OUT_OF_BOUNDS = 1.5  # × MAX_TILT_STD_DEG: once settled, V again above this (a margin: no A/V flicker at the edge)


class LiveStatus:
    """Tracks the causes and gives ``status`` ('A'/'V') and ``cause`` (words, '' when A)."""

    def __init__(
        self,
        settle_s: float,
        log: Callable[[str], None],
        stale_s: float = STALE_S,
        hold_s: float = HOLD_S,
        max_tilt_std_deg: float = MAX_TILT_STD_DEG,
    ) -> None:
        self.settle_s, self.stale_s, self.hold_s = settle_s, stale_s, hold_s
        self.max_tilt_std_deg = max_tilt_std_deg
        self.log = log
        self.t0: float | None = None
        self.settled = False
        self.stale_for = 0.0
        self._saturated_until = -float("inf")
        self._inconsistent_until = -float("inf")
        self._std_ok = False
        self._t = -float("inf")
        self.tilt_std_deg = float("inf")
        self.status = "V"
        self.cause = "starting"
        self.changes = 0
        self.v_seconds: dict[str, float] = {}
        self.check_causes: list[str] = []  # the windowed self-checks' (imutool.live.checks), set by the engine

    def samples(self, t_last: float, saturated: bool, inconsistent: bool, tilt_std_deg: float) -> None:
        """A block arrived: its last time (s), whether any row was saturated or flagged inconsistent, the σ."""
        if self.t0 is None:
            self.t0 = t_last
        self._t = t_last
        self.stale_for = 0.0
        if saturated:
            self._saturated_until = t_last + self.hold_s
        if inconsistent:
            self._inconsistent_until = t_last + self.hold_s
        limit = self.max_tilt_std_deg * (OUT_OF_BOUNDS if self.settled else 1.0)
        self._std_ok = tilt_std_deg <= limit
        self.tilt_std_deg = tilt_std_deg
        if not self.settled and t_last - self.t0 >= self.settle_s and self._std_ok:
            self.settled = True
            self.log(f"filter settled after {t_last - self.t0:.1f} s")

    def silence(self, seconds: float) -> None:
        """No sample for ``seconds`` (host monotonic)."""
        self.stale_for = seconds

    def causes(self) -> list[str]:
        out = []
        if not self.settled:
            since = 0.0 if self.t0 is None else self._t - self.t0
            if since < self.settle_s:
                out.append(f"settling ({since:.0f} of {self.settle_s:.0f} s after start)")
            else:
                out.append(f"settling (roll/pitch sigma {self.tilt_std_deg:.2f} > {self.max_tilt_std_deg} deg)")
        if self.stale_for > self.stale_s:
            out.append(f"no samples for {self.stale_for:.1f} s")
        if self._t <= self._saturated_until:
            out.append("input saturated")
        if self._t <= self._inconsistent_until:
            out.append("self-check inconsistent")
        if self.settled and not self._std_ok:
            out.append("filter out of bounds")
        out += self.check_causes
        return out

    def update(self) -> str:
        """Re-evaluate; log a change (with its cause); return 'A' or 'V'."""
        causes = self.causes()
        status = "V" if causes else "A"
        # the settling count changes every second: a change of status is a change of the kinds of cause
        kinds = [c.split(" (")[0].split(" for ")[0] for c in causes]
        old_kinds = [c.split(" (")[0].split(" for ")[0] for c in self.cause.split("; ")] if self.cause else []
        if status != self.status or kinds != old_kinds:
            self.changes += 1
            self.log(f"status {status}" + (f": {'; '.join(causes)}" if causes else " (estimate trustworthy)"))
        self.status, self.cause = status, "; ".join(causes)
        return status
