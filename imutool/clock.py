"""How a recording's times are shown to a user: UTC clock time where the recording has a date, seconds from its
start otherwise — in reports (PDF and JSON), ``evaluate`` and its plots.

A recording has a date when its times are Unix seconds (what the NMEA reader gives a log with ZDA/RMC dates, a
ROS bag's stamps, an absolute epoch column) or its metadata gives the UTC of time 0 (``utc_start`` or
``start_utc``, ISO 8601). A time is then printed as ``12:34:56.4`` (the date stated once, in the axis label or
the JSON's ISO field), never as ``1406851247.4``; a plot's time axis carries clock ticks, not a ``+1.4068e9``
offset.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from typing import Any

import numpy as np

EPOCH_MIN_S = 1e8  # 1973-03-03: a first time below this is seconds from some start, not Unix time
EPOCH_MAX_S = 4.1e9  # 2099-12-04
CLOCK_STEPS_S = (1, 2, 5, 10, 15, 30, 60, 120, 300, 600, 900, 1800, 3600, 7200, 10800, 21600, 43200, 86400)
"""Tick steps of a UTC time axis (s)."""


@dataclass(frozen=True)
class Clock:
    """origin_unix: Unix time (s) of recording time 0, None without a date; start_s: recording time (s) of the
    first sample (where "seconds from the start" count from)."""

    origin_unix: float | None
    start_s: float = 0.0

    @classmethod
    def of(cls, rec: Any) -> Clock:
        """The clock of a :class:`formats.Recording` (its times and metadata)."""
        t = np.asarray(rec.time, dtype=float)
        fin = t[np.isfinite(t)]
        start = float(fin[0]) if fin.size else 0.0
        return cls(utc_origin(start, getattr(rec, "meta", {}) or {}), start)

    @classmethod
    def from_json(cls, d: dict[str, Any] | None, start_s: float = 0.0) -> Clock:
        """The clock described by :meth:`as_json` (None: undated, from ``start_s``)."""
        if not d:
            return cls(None, start_s)
        return cls(d.get("utc_of_time_0_unix"), float(d.get("start_s", start_s)))

    @property
    def dated(self) -> bool:
        return self.origin_unix is not None

    def unix(self, t: float) -> float | None:
        """Unix time (s) of recording time ``t`` (None without a date)."""
        return None if self.origin_unix is None else self.origin_unix + float(t)

    def iso(self, t: float | None) -> str | None:
        """ISO 8601 UTC of recording time ``t`` to the millisecond (``2014-08-01T00:20:47.400Z``); None
        without a date or a finite time."""
        if t is None or not self.dated or not math.isfinite(float(t)) or self.unix(t) < EPOCH_MIN_S:  # type: ignore[operator]
            return None  # not a time of this clock (e.g. a steps file's times from 0 against Unix times)
        d = _utc(self.unix(t))  # type: ignore[arg-type]
        return None if d is None else d.strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"

    def text(self, t: float | None, decimals: int = 1) -> str:
        """Recording time ``t`` as a user reads it: ``00:20:47.4`` (UTC) or seconds from the start (``12.3``)."""
        if t is None or not math.isfinite(float(t)):
            return "-"
        if self.dated and self.unix(t) >= EPOCH_MIN_S:  # type: ignore[operator]
            d = _utc(self.unix(t))  # type: ignore[arg-type]
            if d is not None:
                d = d + timedelta(seconds=0.5 * 10.0**-decimals)  # rounded, not cut
                s = d.strftime("%H:%M:%S")
                return s + (d.strftime(".%f")[: decimals + 1] if decimals > 0 else "")
        return f"{float(t) - self.start_s:.{decimals}f}"

    def time_of(self, unix: float) -> float:
        """Recording time (s) of the Unix time ``unix`` (a dated clock only: ValueError otherwise)."""
        if self.origin_unix is None:
            raise ValueError("a clock without a date has no recording time for a UTC time")
        return float(unix) - self.origin_unix

    @property
    def unit(self) -> str:
        """The unit of :meth:`text`: ``UTC`` or ``s from start``."""
        return "UTC" if self.dated else "s from start"

    def date(self) -> str | None:
        """The UTC date (YYYY-MM-DD) of the first sample, None without a date."""
        d = _utc(self.unix(self.start_s)) if self.dated else None  # type: ignore[arg-type]
        return None if d is None else d.strftime("%Y-%m-%d")

    def axis_label(self, what: str = "time") -> str:
        """A time axis's label: ``time (UTC, 2014-08-01)`` or ``time (s from the start)``."""
        return f"{what} (UTC, {self.date()})" if self.dated else f"{what} (s from the start)"

    def x(self, t: Any) -> np.ndarray:
        """Plot x values of recording times: seconds from the start (small numbers: no axis offset)."""
        return np.asarray(t, dtype=float) - self.start_s

    def axis(self, ax: Any, what: str = "time") -> None:
        """Label a matplotlib axis plotted in :meth:`x` values; dated: its ticks read as UTC clock time."""
        ax.set_xlabel(self.axis_label(what))
        if self.dated:
            from matplotlib.ticker import FuncFormatter, Locator

            zero = float(self.origin_unix) + self.start_s  # type: ignore[arg-type]  # Unix time of x = 0

            class _ClockTicks(Locator):  # ticks on whole clock steps (…, 5 min, 10 min, 15 min, 30 min, 1 h, …)
                def __call__(self) -> Any:
                    return self.tick_values(*self.axis.get_view_interval())

                def tick_values(self, vmin: float, vmax: float) -> Any:
                    lo, hi = min(vmin, vmax), max(vmin, vmax)
                    step = next((s for s in CLOCK_STEPS_S if s >= (hi - lo) / 7), CLOCK_STEPS_S[-1])
                    first = math.ceil((lo + zero) / step) * step - zero
                    return np.arange(first, hi + 1e-9 * step, step)

            ax.xaxis.set_major_locator(_ClockTicks())
            ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _pos: self.text(v + self.start_s, 0)))
        else:
            ax.ticklabel_format(axis="x", style="plain", useOffset=False)

    def as_json(self) -> dict[str, Any]:
        """What the JSON states: how its times are shown, the UTC of time 0 and of the first sample."""
        if not self.dated:
            return {
                "shown_as": "seconds from the start (the recording has no date)",
                "start_s": self.start_s,
                "utc_of_time_0": None,
            }
        return {
            "shown_as": "UTC clock time (each time in s has an ISO 8601 *_utc field beside it)",
            "start_s": self.start_s,
            "start_utc": self.iso(self.start_s),
            "utc_of_time_0": "the Unix epoch (the times are Unix seconds)"
            if self.origin_unix == 0.0
            else self.iso(0.0),
            "utc_of_time_0_unix": self.origin_unix,
        }


def utc_origin(first_time_s: float, meta: dict[str, Any]) -> float | None:
    """Unix time (s) of recording time 0: 0 when the times are Unix seconds, the metadata's ``utc_start`` or
    ``start_utc`` (ISO 8601, the UTC of time 0) when they count from a start, else None (no date)."""
    if EPOCH_MIN_S <= first_time_s <= EPOCH_MAX_S:
        return 0.0
    text = meta.get("utc_start") or meta.get("start_utc")
    if not text:
        return None
    try:
        d = datetime.fromisoformat(str(text).strip().replace("Z", "+00:00"))
    except ValueError:
        return None
    return (d if d.tzinfo else d.replace(tzinfo=timezone.utc)).timestamp()


def parse_utc(text: str) -> float | None:
    """Unix time (s) of an ISO 8601 date and time (``2014-08-01T12:00:00Z``, ``2014-08-01 12:00:00.5``,
    ``2014-08-01T14:00+02:00``; no zone: UTC); None for text that is not one (a number of seconds, a time without
    a date)."""
    t = str(text).strip()
    if not re.fullmatch(r"\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}(:\d{2}(\.\d+)?)?(Z|[+-]\d{2}:?\d{2})?", t, flags=re.I):
        return None
    try:
        d = datetime.fromisoformat(re.sub(r"[zZ]$", "+00:00", t))
    except ValueError:
        return None
    return (d if d.tzinfo else d.replace(tzinfo=timezone.utc)).timestamp()


def _utc(unix: float) -> datetime | None:
    try:
        return datetime.fromtimestamp(float(unix), tz=timezone.utc)
    except (ValueError, OverflowError, OSError):
        return None


TIME_KEYS = ("start_s", "end_s", "t_peak_s", "t_s", "time_s")
"""Keys of the times (recording seconds) in a report's rows; each gets an ISO ``*_utc`` beside it when dated."""


def stamp_times(obj: Any, clock: Clock) -> None:
    """Add ``<name>_utc`` (ISO 8601) beside every :data:`TIME_KEYS` value in the dicts of ``obj`` (in place;
    nothing without a date)."""
    if not clock.dated:
        return
    if isinstance(obj, dict):
        for k in [k for k in obj if k in TIME_KEYS]:
            v = obj[k]
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                obj[k[:-2] + "_utc"] = clock.iso(v)
        for v in list(obj.values()):
            stamp_times(v, clock)
    elif isinstance(obj, (list, tuple)):
        for v in obj:
            stamp_times(v, clock)
