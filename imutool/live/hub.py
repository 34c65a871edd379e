"""The live hub: the latest estimate of `imutool live` for any number of readers.

The engine publishes one `LiveSnapshot` per output tick; a bridge display, a Signal K server or a test
reads them through `LiveHub.latest`, `LiveHub.subscribe` (a bounded queue per reader, the oldest
dropped and counted when a reader falls behind) or `LiveHub.history` (~1 Hz trend). Nothing here
blocks the publisher. A reader asks for the peak-hold reset with `request_reset`; the engine takes
the request at its next block (`take_resets`), performs it, logs it with its UTC and reports it on HRM.
"""

from __future__ import annotations

import collections
import threading
from collections.abc import Callable
from dataclasses import asdict, dataclass

__all__ = ["LiveHub", "LiveSnapshot", "Subscription"]


@dataclass(frozen=True)
class LiveSnapshot:
    """One live estimate, degrees and seconds at this surface.

    utc: host UTC (epoch s) when the snapshot was made; t: input time (s, the sensor's clock).
    roll + starboard down, pitch + bow up, heading clockwise from north (None without one);
    rot_deg_min: rate of turn (deg/min, + clockwise); heave_m: + up (None if not measured);
    roll amplitudes are positive degrees to each side over the trailing window; peak_* are the
    peak-hold since `peak_reset_utc` (ISO 8601, None if never reset); status 'A' or 'V' with its
    cause in words ('' when A); settled: the filter's start-up settling time has passed.
    """

    utc: float
    t: float
    roll_deg: float
    pitch_deg: float
    heading_deg: float | None
    heading_ref: str
    rot_deg_min: float | None
    heave_m: float | None
    roll_amp_port_deg: float | None
    roll_amp_stbd_deg: float | None
    roll_period_s: float | None
    peak_port_deg: float | None
    peak_stbd_deg: float | None
    peak_reset_utc: str | None
    status: str
    cause: str
    settled: bool

    def as_dict(self) -> dict:
        """A JSON-able dict (NaN floats become None)."""
        out = asdict(self)
        for k, v in out.items():
            if isinstance(v, float) and v != v:
                out[k] = None
        return out


class Subscription:
    """A reader's bounded queue of snapshots; the oldest is dropped (and counted) when full."""

    def __init__(self, hub: LiveHub, maxsize: int = 64) -> None:
        self._hub = hub
        self._items: collections.deque[LiveSnapshot] = collections.deque()
        self._maxsize = max(1, int(maxsize))
        self._cond = threading.Condition()
        self.dropped = 0
        self.closed = False

    def _put(self, snap: LiveSnapshot) -> None:
        with self._cond:
            if len(self._items) >= self._maxsize:
                self._items.popleft()
                self.dropped += 1
            self._items.append(snap)
            self._cond.notify()

    def _close(self) -> None:
        with self._cond:
            self.closed = True
            self._cond.notify_all()

    def get(self, timeout: float | None = None) -> LiveSnapshot | None:
        """The next snapshot, waiting up to `timeout` s; None on timeout or once the hub closed and drained."""
        with self._cond:
            if not self._items and not self.closed:
                self._cond.wait(timeout)
            if self._items:
                return self._items.popleft()
            return None

    def unsubscribe(self) -> None:
        """Stop receiving snapshots."""
        self._hub._remove(self)
        self._close()


class LiveHub:
    """Fan-out of live snapshots; thread-safe; `publish` never blocks."""

    def __init__(self, history_s: float = 3600.0) -> None:
        self._lock = threading.Lock()
        self._latest: LiveSnapshot | None = None
        self._subs: list[Subscription] = []
        self._trend: collections.deque[LiveSnapshot] = collections.deque(maxlen=int(history_s) + 1)
        self._resets: collections.deque[tuple[str, float]] = collections.deque(maxlen=16)
        self._stop_callbacks: list[Callable[[], None]] = []
        self.closed = False
        self.stop_reason = ""

    def publish(self, snap: LiveSnapshot) -> None:
        """Hand a snapshot to every reader (drop-oldest per reader); keeps ~1 Hz for the trend."""
        with self._lock:
            self._latest = snap
            if not self._trend or snap.t - self._trend[-1].t >= 1.0 or snap.t < self._trend[-1].t:
                self._trend.append(snap)
            subs = list(self._subs)
        for sub in subs:
            sub._put(snap)

    def latest(self) -> LiveSnapshot | None:
        """The last snapshot published, or None."""
        return self._latest

    def subscribe(self, maxsize: int = 64) -> Subscription:
        """A new reader's queue of the snapshots published from now on."""
        sub = Subscription(self, maxsize)
        with self._lock:
            if self.closed:
                sub._close()
            self._subs.append(sub)
        return sub

    def _remove(self, sub: Subscription) -> None:
        with self._lock:
            if sub in self._subs:
                self._subs.remove(sub)

    def history(self, seconds: float = 600.0) -> list[LiveSnapshot]:
        """The snapshots of the last `seconds` of input time, ~1 Hz, oldest first."""
        with self._lock:
            trend = list(self._trend)
        if not trend:
            return []
        t_end = trend[-1].t
        return [s for s in trend if s.t >= t_end - seconds]

    def request_reset(self, who: str) -> None:
        """Ask the engine to reset the peak-hold (queued; the engine performs and logs it)."""
        import time

        with self._lock:
            self._resets.append((str(who), time.time()))

    def take_resets(self) -> list[tuple[str, float]]:
        """The engine's side: the reset requests (who, host UTC s) queued since the last call."""
        with self._lock:
            out = list(self._resets)
            self._resets.clear()
        return out

    def on_stop(self, callback: Callable[[], None]) -> None:
        """Call `callback()` (from the engine's thread) when the source stops; at once if it has."""
        with self._lock:
            if not self.closed:
                self._stop_callbacks.append(callback)
                return
        callback()

    def close(self, reason: str = "stopped") -> None:
        """The engine's side: the source stopped; wake every reader and run the stop callbacks."""
        with self._lock:
            if self.closed:
                return
            self.closed = True
            self.stop_reason = reason
            subs = list(self._subs)
            callbacks = list(self._stop_callbacks)
            self._stop_callbacks.clear()
        for sub in subs:
            sub._close()
        for cb in callbacks:
            try:
                cb()
            except Exception:  # a reader's callback never stops the engine
                pass
