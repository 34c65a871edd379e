"""One time per captured frame: the MCU clock of bridge frames mapped to UTC, NMEA lines spread by the baud rate.

A serial read returns a batch of frames with one arrival time, so arrival stamps repeat (a 200 Hz stream read
every ~15 ms gives ~3 frames per stamp) and every later command's validation would drop the repeats. The
bridge frames carry the MCU's microsecond clock ``t_us`` (mod 2³²) and a sequence number; :class:`FrameClock`
turns them into UTC epoch seconds, one per frame:

* ``t_us`` is unwrapped (a step back by more than half the range is a wrap, +2³² µs); a step back that is
  not a wrap (the MCU restarted) starts a new clock segment. When ``t_us`` does not advance at all (a bridge
  without a clock) the sequence number (unwrapped mod 2¹⁶) times the period fitted to the arrival times
  stands in for it.
* UTC = m + offset + drift·(m − m₀), m the MCU time in s. Arrival = send + latency with latency ≥ 0, so the
  mapping is fitted to the *lower envelope* of arrival − m: the smallest value per ``window_s`` window of MCU
  time (the frame that waited least), a least-squares line through those minima (drift, bounded to
  ±``max_drift``), then shifted down so that no frame is stamped after it arrived. The last frame of each
  batch is the one used (it waited least).
* Stamps are strictly increasing: a refit never moves a frame before the one written before it.

NMEA lines have no clock of their own: :func:`spread_by_baud` keeps each line's arrival stamp but moves the
lines of one batch back by the bytes that followed them on the wire (10 bits per byte, 8N1).
"""

from __future__ import annotations

import numpy as np

WRAP_US = 1 << 32
SEQ_WRAP = 1 << 16
_EPS = 1e-6  # s: the smallest step between two stamps


class FrameClock:
    """Maps MCU time (``t_us``) or sequence numbers of frames to UTC epoch seconds, one per frame."""

    def __init__(self, window_s: float = 5.0, max_drift: float = 500e-6):
        self.window_s = window_s
        self.max_drift = max_drift
        self._last_raw: int | None = None
        self._wraps = 0
        self._last_seq: int | None = None
        self._seq_wraps = 0
        self._minima: dict[int, tuple[float, float]] = {}  # window → (m, arrival − m), smallest per window
        self._m0: float | None = None
        self._offset = 0.0
        self._drift = 0.0
        self._last_out = -np.inf
        self.segments = 0  # clock segments started (MCU restarts + 1)
        self.source = "t_mcu"  # or "seq" when t_us does not advance
        self._period: float | None = None
        self._seq_first: tuple[int, float] | None = None

    # -- MCU time in seconds ------------------------------------------------------------------------------------
    def _unwrap_us(self, t_us: np.ndarray) -> tuple[np.ndarray, int]:
        """Unwrapped µs; also the index of the first frame of a new segment after a restart (or -1)."""
        raw = np.asarray(t_us, dtype=np.int64)
        prev = np.empty_like(raw)
        prev[1:] = raw[:-1]
        prev[0] = raw[0] if self._last_raw is None else self._last_raw
        d = raw - prev
        wrap = d < -(WRAP_US // 2)
        restart = (d < 0) & ~wrap
        cut = int(np.flatnonzero(restart)[0]) if restart.any() else -1
        if cut >= 0:  # handle the part before the restart; the caller feeds the rest again
            raw, wrap = raw[:cut], wrap[:cut]
        w = self._wraps + np.cumsum(wrap)
        if len(raw):
            self._wraps = int(w[-1])
            self._last_raw = int(raw[-1])
        return raw + w * WRAP_US, cut

    def _unwrap_seq(self, seq: np.ndarray) -> np.ndarray:
        s = np.asarray(seq, dtype=np.int64) & (SEQ_WRAP - 1)
        prev = np.empty_like(s)
        prev[1:] = s[:-1]
        prev[0] = s[0] if self._last_seq is None else self._last_seq
        w = self._seq_wraps + np.cumsum(s < prev)
        self._seq_wraps = int(w[-1])
        self._last_seq = int(s[-1])
        return s + w * SEQ_WRAP

    # -- fit ------------------------------------------------------------------------------------------------------
    def _restart(self) -> None:
        self._minima.clear()
        self._m0 = None
        self._wraps = 0
        self._last_raw = None
        self.segments += 1

    def _add_point(self, m: float, arrival: float) -> None:
        if self._m0 is None:
            self._m0 = m
        k = int(np.floor((m - self._m0) / self.window_s))
        d = arrival - m
        old = self._minima.get(k)
        if old is None or d < old[1]:
            self._minima[k] = (m, d)
        pts = np.array(list(self._minima.values()))
        x = pts[:, 0] - self._m0
        if len(pts) >= 3 and np.ptp(x) > 0:
            slope = float(np.polyfit(x, pts[:, 1], 1)[0])
            self._drift = float(np.clip(slope, -self.max_drift, self.max_drift))
        else:
            self._drift = 0.0
        self._offset = float(np.min(pts[:, 1] - self._drift * x))

    def map(self, t_us: np.ndarray, seq: np.ndarray, arrival: float) -> np.ndarray:
        """UTC epoch seconds for a batch of frames that arrived (all of them) by ``arrival`` (UTC s)."""
        t_us = np.asarray(t_us, dtype=np.int64)
        n = len(t_us)
        if n == 0:
            return np.empty(0)
        if self._m0 is None and self.segments == 0:
            self.segments = 1
        if (
            self.source == "t_mcu"
            and n > 1
            and np.all(t_us == t_us[0])
            and (self._last_raw is None or self._last_raw == t_us[0])
        ):
            self.source = "seq"  # no MCU clock: count frames instead
        if self.source == "seq":
            m = self._seq_seconds(self._unwrap_seq(seq), arrival)
            return self._stamp(m, arrival)
        us, cut = self._unwrap_us(t_us)
        if cut < 0:
            return self._stamp(us / 1e6, arrival)
        first = self._stamp(us / 1e6, arrival) if cut > 0 else np.empty(0)
        self._restart()
        rest = self.map(t_us[cut:], np.asarray(seq)[cut:], arrival)
        return np.concatenate([first, rest])

    def _seq_seconds(self, s: np.ndarray, arrival: float) -> np.ndarray:
        """Sequence count → seconds with the frame period fitted to arrivals (first batch: 1/len spread)."""
        if self._seq_first is None:
            self._seq_first = (int(s[0]), arrival)
        s0, a0 = self._seq_first
        if s[-1] > s0 and arrival > a0:
            self._period = (arrival - a0) / float(s[-1] - s0)
        period = self._period or 1e-3
        return (s - s0) * period

    def _stamp(self, m: np.ndarray, arrival: float) -> np.ndarray:
        if len(m) == 0:
            return m
        self._add_point(float(m[-1]), arrival)
        out = m + self._offset + self._drift * (m - self._m0)
        out = strictly_increasing(out, self._last_out)
        self._last_out = float(out[-1])
        return out

    def resume_after(self, t: float) -> None:
        """Continue after a capture restart: stamps stay after ``t`` (the last time already on disk)."""
        self._last_out = float(t)

    def as_meta(self) -> dict:
        return {
            "source": self.source,
            "offset_s": self._offset,
            "drift_ppm": self._drift * 1e6,
            "segments": self.segments,
            "window_s": self.window_s,
        }


def spread_by_baud(
    arrival: float, line_lengths: list[int], tail_bytes: int, baud: int, last: float = -np.inf
) -> np.ndarray:
    """Per-line stamps for lines of one batch that all arrived by ``arrival`` (UTC s).

    line_lengths: bytes of each complete line (newline excluded); tail_bytes: bytes received after the last
    line's newline (a partial line). Line k's newline left the wire (bytes after it) × 10 / baud s before the
    batch arrived. Stamps stay strictly increasing after ``last`` (the previous batch's last stamp).
    """
    n = len(line_lengths)
    if n == 0:
        return np.empty(0)
    sizes = np.asarray(line_lengths, dtype=float) + 1.0
    after = np.concatenate([np.cumsum(sizes[::-1])[::-1][1:], [0.0]]) + tail_bytes
    return strictly_increasing(arrival - after * 10.0 / float(baud), last)


def strictly_increasing(t: np.ndarray, last: float = -np.inf, eps: float = _EPS) -> np.ndarray:
    """The smallest upward adjustment of ``t`` with every step ≥ ``eps`` and t[0] ≥ last + eps."""
    t = np.asarray(t, dtype=float)
    k = np.arange(1, len(t) + 1) * eps
    return np.maximum.accumulate(np.maximum(t - k, last)) + k
