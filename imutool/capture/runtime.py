"""Capture run-time helpers: counters, the live status line and clean stop on SIGINT/SIGTERM."""

from __future__ import annotations

import signal
import sys
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone

from formats.errors import ImutoolError


def iso_utc(t: float | None) -> str:
    """ISO-8601 UTC with milliseconds ('' for None)."""
    if t is None:
        return ""
    return datetime.fromtimestamp(t, tz=timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")


@dataclass
class CaptureStats:
    started_utc: str = ""
    lines: int = 0
    frames: int = 0
    errors: int = 0
    dropped: int = 0
    reopen_count: int = 0
    port_gaps: list[dict] = field(default_factory=list)
    error_kinds: dict[str, int] = field(default_factory=dict)

    def count_error(self, kind: str, n: int = 1) -> None:
        if n:
            self.errors += n
            self.error_kinds[kind] = self.error_kinds.get(kind, 0) + n


class StopFlag:
    """Set by SIGINT/SIGTERM so the capture loop can finish its files."""

    def __init__(self) -> None:
        self.stop = False
        self.reason = ""
        self._old: dict = {}

    def install(self) -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                self._old[sig] = signal.signal(sig, self._handler)
            except ValueError:  # not the main thread (tests)
                pass

    def restore(self) -> None:
        for sig, h in self._old.items():
            signal.signal(sig, h)

    def _handler(self, signum, frame) -> None:
        self.stop = True
        self.reason = signal.Signals(signum).name


class StatusLine:
    """A live one-line status on stderr every ``interval`` s (overwritten on a TTY)."""

    def __init__(self, interval: float | None, quiet: bool):
        self.interval = interval
        self.quiet = quiet or not interval
        self.tty = sys.stderr.isatty()
        self._last = time.monotonic()
        self._last_count = 0

    def update(self, stats: CaptureStats, size_bytes: int, force: bool = False) -> None:
        if self.quiet:
            return
        now = time.monotonic()
        if not force and now - self._last < self.interval:
            return
        count = stats.frames
        rate = (count - self._last_count) / max(now - self._last, 1e-9)
        self._last, self._last_count = now, count
        msg = (
            f"{datetime.now(timezone.utc).strftime('%H:%M:%S')}Z {rate:8.1f}/s  frames {count}  "
            f"drops {stats.dropped}  errors {stats.errors}  reopen {stats.reopen_count}  "
            f"{size_bytes / 1e6:.2f} MB"
        )
        sys.stderr.write(("\r" + msg) if self.tty else (msg + "\n"))
        sys.stderr.flush()

    def finish(self) -> None:
        if not self.quiet and self.tty:
            sys.stderr.write("\n")


@dataclass
class PollStats:
    samples: int = 0
    overruns: int = 0
    read_errors: int = 0
    achieved_hz: float = 0.0


def poll(
    read_fn,
    rate_hz: float,
    on_sample,
    duration: float | None,
    stop_check=lambda: False,
    clock=time.monotonic,
    sleep=time.sleep,
) -> PollStats:
    """Call ``read_fn()`` at a steady rate; a tick later than one period is an overrun (counted).

    ``on_sample(t_mono, value)`` receives each reading. A read error is counted and the loop goes on.
    """
    st = PollStats()
    period = 1.0 / rate_hz
    t0 = clock()
    nxt = t0
    while not stop_check():
        now = clock()
        if duration is not None and now - t0 >= duration:
            break
        if now < nxt:
            sleep(nxt - now)
            now = clock()
        missed = int((now - nxt) // period)
        if missed > 0:
            st.overruns += missed
            nxt += missed * period
        try:
            value = read_fn()
        except ImutoolError:
            st.read_errors += 1
            value = None
        if value is not None:
            on_sample(now, value)
            st.samples += 1
        nxt += period
    elapsed = clock() - t0
    st.achieved_hz = st.samples / elapsed if elapsed > 0 else 0.0
    return st


def finish_poll_capture(csv, stats: CaptureStats, stop: StopFlag, ps: PollStats, rate_hz: float) -> dict:
    """Close a polled capture's CSV with its summary trailer; returns the summary (with the file names)."""
    summary = {
        "started_utc": stats.started_utc,
        "stopped_utc": iso_utc(time.time()),
        "stop_reason": stop.reason or "duration reached",
        "samples": ps.samples,
        "rate_hz": rate_hz,
        "achieved_hz": round(ps.achieved_hz, 3),
        "overruns": ps.overruns,
        "read_errors": ps.read_errors,
    }
    csv.close(summary)
    summary["files"] = csv.file.files
    return summary
