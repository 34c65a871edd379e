"""Serial capture (pyserial): NMEA 0183 instruments and the bridge protocol, for hours, losing nothing.

Every frame gets its own time (:mod:`imutool.capture.clock`): bridge frames the MCU clock mapped to UTC by an
offset and drift fitted to the arrival times; NMEA lines their arrival time, the lines of one read spread back
by the bytes that followed them at the baud rate. ``time_mono`` is the host's monotonic clock at the read. A port
that disappears (USB unplugged) is reopened with exponential backoff and the outage is recorded as a gap.
Corrupted input is counted, never fatal. SIGINT/SIGTERM stop cleanly with the files finalised.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from formats.errors import ImutoolError

from .clock import FrameClock, spread_by_baud
from .runtime import CaptureStats, StatusLine, StopFlag, iso_utc
from .sink import CaptureCsv, EventLog, RotatingFile, last_complete_row

if TYPE_CHECKING:
    from .bridge import Scales

NMEA_COLUMNS = [
    "heading_true",
    "heading_mag",
    "heading_sensor",
    "deviation",
    "variation",
    "rot",
    "roll",
    "pitch",
    "heel",
    "heave",
    "roll_period",
    "amp_port",
    "amp_stbd",
    "sog",
    "cog",
]
NMEA_UNITS = {
    "heading_true": "deg",
    "heading_mag": "deg",
    "heading_sensor": "deg",
    "deviation": "deg",
    "variation": "deg",
    "rot": "deg/min",
    "roll": "deg",
    "pitch": "deg",
    "heel": "deg",
    "heave": "m",
    "roll_period": "s",
    "amp_port": "deg",
    "amp_stbd": "deg",
    "sog": "m/s",
    "cog": "deg",
}
BRIDGE_COLUMNS = [
    "time",
    "time_mono",
    "seq",
    "t_mcu",
    "accel_x",
    "accel_y",
    "accel_z",
    "gyro_x",
    "gyro_y",
    "gyro_z",
    "mag_x",
    "mag_y",
    "mag_z",
    "temp",
]


class SerialSource:
    """A serial port that reopens itself with backoff; yields (bytes, t_wall, t_mono) chunks."""

    def __init__(
        self,
        port: str,
        baud: int,
        stats: CaptureStats,
        max_backoff: float = 5.0,
        opener: Callable | None = None,
        log: Callable[[str], None] | None = None,
        events: EventLog | None = None,
    ):
        self.port_name = port
        self.baud = baud
        self.stats = stats
        self.max_backoff = max_backoff
        self._opener = opener
        self._ser = None
        self._down_since: float | None = None
        self._down_wall: float | None = None
        self._next_try = 0.0
        self._backoff = 0.1
        self.batch_s = 0.01
        self.log = log or (lambda s: None)
        self.events = events

    def _open(self):
        if self._opener is not None:
            return self._opener(self.port_name, self.baud)
        import serial

        return serial.Serial(self.port_name, self.baud, timeout=0.05)

    def open_first(self) -> None:
        try:
            self._ser = self._open()
        except Exception as e:  # serial.SerialException / OSError: name the port
            raise ImutoolError(f"cannot open serial port at {self.baud} baud: {e}", path=self.port_name) from None

    def read(self) -> tuple[bytes, float, float]:
        """Bytes available now (may be empty), with arrival times; handles disconnects."""
        if self._ser is None:
            now = time.monotonic()
            if now < self._next_try:
                time.sleep(min(0.05, self._next_try - now))
                return b"", time.time(), time.monotonic()
            try:
                self._ser = self._open()
            except Exception:
                self._backoff = min(self._backoff * 2, self.max_backoff)
                self._next_try = time.monotonic() + self._backoff
                return b"", time.time(), time.monotonic()
            gap = {
                "start_utc": iso_utc(self._down_wall),
                "end_utc": iso_utc(time.time()),
                "length_s": round(time.monotonic() - (self._down_since or time.monotonic()), 3),
            }
            self.stats.port_gaps.append(gap)
            self.stats.reopen_count += 1
            self.log(f"port {self.port_name} reopened after {gap['length_s']} s")
            if self.events:
                self.events.add("port_reopened", **gap)
            self._backoff = 0.1
        try:
            data = self._ser.read(1)  # blocks up to the port timeout (50 ms) for the first byte
            if data:
                if self.batch_s > 0:
                    time.sleep(self.batch_s)  # let a batch accumulate: far fewer wake-ups at high rates
                n = self._ser.in_waiting
                if n:
                    data += self._ser.read(n)
        except Exception as e:  # port vanished
            self.log(f"port {self.port_name} lost: {e}")
            if self.events:
                self.events.add("port_lost", error=str(e))
            try:
                self._ser.close()
            except Exception:
                pass
            self._ser = None
            self._down_since = time.monotonic()
            self._down_wall = time.time()
            self._next_try = self._down_since + self._backoff
            return b"", time.time(), time.monotonic()
        return data, time.time(), time.monotonic()

    def close(self) -> None:
        if self._ser is not None:
            try:
                self._ser.close()
            except Exception:
                pass
            self._ser = None


def _split_text(buf: bytearray, data: bytes) -> list[str]:
    """Complete lines received so far, decoded once per chunk (ASCII, one U+FFFD per bad byte); the partial
    last line stays in ``buf``. A line over 8 KiB without an end is garbage: it is passed on whole so the stream
    can resynchronise."""
    buf.extend(data)
    end = buf.rfind(b"\n")
    lines = []
    if end >= 0:
        lines = buf[:end].decode("ascii", "replace").split("\n")
        del buf[: end + 1]
    if len(buf) > 8192:
        lines.append(buf.decode("ascii", "replace"))
        buf.clear()
    return lines


def run_loop(
    source: SerialSource,
    on_data: Callable[[bytes, float, float], None],
    stats: CaptureStats,
    duration: float | None,
    status: StatusLine,
    size: Callable[[], int],
    stop: StopFlag,
) -> None:
    t_end = None if duration is None else time.monotonic() + duration
    while not stop.stop:
        if t_end is not None and time.monotonic() >= t_end:
            stop.reason = stop.reason or "duration reached"
            break
        data, tw, tm = source.read()
        if data:
            on_data(data, tw, tm)
        status.update(stats, size())


def capture_nmea(
    port: str,
    baud: int,
    out: str,
    duration: float | None = None,
    rotate_s: float | None = None,
    status_s: float | None = 10.0,
    quiet: bool = False,
    append: bool = False,
    force: bool = False,
    checksum_policy: str = "require",
    opener: Callable | None = None,
    stop: StopFlag | None = None,
) -> dict:
    """Record NMEA 0183 from a serial port.

    ``out`` is a folder (created) or a ``.csv`` path. Writes ``<name>.nmea`` — the raw log, every line as
    received, prefixed by its UTC arrival time (``2026-11-21T10:00:00.123456Z <line>``) — and ``<name>.csv``
    with the decoded values (degrees, m, m/s; ``time`` = UTC epoch s, ``time_mono`` = monotonic s).
    """
    from formats import nmea

    base = Path(out)
    if base.suffix.lower() != ".csv":
        base = base / f"nmea_{utc_name()}.csv"
    stats = CaptureStats(started_utc=iso_utc(time.time()))
    columns = ["time", "time_mono"] + NMEA_COLUMNS
    meta = {
        "source": f"serial {port} @ {baud} baud (NMEA 0183)",
        "time": "UTC epoch seconds at arrival (lines of one read spread back by the baud rate, 10 bits/byte)",
        "units": ", ".join(f"{k}={v}" for k, v in NMEA_UNITS.items()),
        "captured_by": "imutool capture serial",
    }
    kw = {"rotate_s": rotate_s, "append": append, "overwrite": force}
    src = SerialSource(port, baud, stats, opener=opener, log=(lambda s: None) if quiet else _log)
    src.open_first()  # before any file or folder is made: a missing or non-serial port leaves nothing behind
    try:
        csv = CaptureCsv(base, columns, meta, array_rows=False, **kw)  # rows come as text (see NmeaRows)
        raw = RotatingFile(base.with_suffix(".nmea"), "", **kw)
    except BaseException:
        src.close()
        raise
    status = StatusLine(status_s, quiet)
    stop = stop or StopFlag()
    stop.install()
    buf = bytearray()
    to_row = NmeaRows(NMEA_COLUMNS)
    # a clean sentence takes the fast path; anything else (and any unknown policy) the full one, which counts it
    fast = nmea.decode_fast if checksum_policy in nmea.CHECKSUM_POLICIES else (lambda line: None)

    def full(text: str) -> dict | None:
        """parse_sentence + decode, with every failure counted by kind (never fatal); None when no values."""
        try:
            sentence = nmea.parse_sentence(text, checksum_policy=checksum_policy)
        except Exception as e:
            stats.count_error(type(e).__name__)
            return None
        if sentence is None:
            stats.count_error("unparsed")
            return None
        stats.frames += 1
        try:
            return nmea.decode(sentence)
        except Exception as e:
            stats.count_error(f"decode {type(e).__name__}")
            return None

    last = [-np.inf]

    def on_data(data: bytes, tw: float, tm: float) -> None:
        lines = _split_text(buf, data)
        if not lines:
            return
        stamps = spread_by_baud(tw, [len(ln) for ln in lines], len(buf), baud, last[0])
        last[0] = float(stamps[-1])
        mono = tm + (stamps - tw)
        raw.write("".join(f"{_iso_us(t)} {ln.rstrip()}\n" for t, ln in zip(stamps, lines, strict=True)))
        stats.lines += len(lines)
        rows = []
        n_fast = 0
        for i, ln in enumerate(lines):
            text = ln.strip()
            if not text:
                continue
            values = fast(text)
            if values is None:
                values = full(text)
                if not values:
                    continue
            else:
                n_fast += 1
            row = to_row(values)
            if row:
                rows.append(f"{float(stamps[i])!r},{float(mono[i])!r},{row}")
        stats.frames += n_fast
        if rows:
            csv.write_lines("\n".join(rows) + "\n", len(rows))

    try:
        run_loop(src, on_data, stats, duration, status, lambda: raw.bytes_written + csv.file.bytes_written, stop)
    finally:
        stop.restore()
        src.close()
        status.update(stats, raw.bytes_written + csv.file.bytes_written, force=True)
        status.finish()
        summary = _summary(stats, stop.reason)
        csv.close({k: v for k, v in summary.items() if not isinstance(v, (list, dict))})
        raw.close()
    summary["files"] = csv.file.files + raw.files
    summary["rows"] = csv.rows
    return summary


class NmeaRows:
    """Decoded values → the CSV cells after ``time,time_mono`` (shortest exact float text, empty = NaN);
    '' when none of the values has a column (no row is written then)."""

    def __init__(self, columns: list[str]):
        self.index = {c: i for i, c in enumerate(columns)}
        self.empty = [""] * len(columns)

    def __call__(self, values: dict) -> str:
        cells = None
        for k, v in values.items():
            j = self.index.get(k)
            if j is not None and isinstance(v, (int, float)):
                if cells is None:
                    cells = self.empty.copy()
                cells[j] = repr(float(v))
        return "" if cells is None else ",".join(cells)


def capture_bridge(
    port: str,
    baud: int,
    out: str,
    binary: bool = False,
    scales: Scales | None = None,
    duration: float | None = None,
    rotate_s: float | None = None,
    status_s: float | None = 10.0,
    quiet: bool = False,
    append: bool = False,
    force: bool = False,
    opener: Callable | None = None,
    stop: StopFlag | None = None,
) -> dict:
    """Record bridge-protocol frames (text or binary) from a serial port into an imutool CSV in SI units."""
    from .bridge import BridgeDecoder, counts_to_si  # numba kernels: only the bridge protocol needs them

    base = Path(out)
    if base.suffix.lower() != ".csv":
        base = base / f"bridge_{utc_name()}.csv"
    stats = CaptureStats(started_utc=iso_utc(time.time()))
    dec = BridgeDecoder(binary=binary, scales=scales)
    meta = {
        "source": f"serial {port} @ {baud} baud (imutool bridge, {'binary' if binary else 'text'})",
        "time": "UTC epoch seconds per frame: MCU clock (t_mcu) mapped to UTC by an offset and drift fitted to "
        "the arrival times (lower envelope; docs/capture.md)",
        "time_mono": "host monotonic clock at the read that carried the frame",
        "scales": dec.scales.as_meta(),
        "units": "seq=1, t_mcu=s, time_mono=s",
        "captured_by": "imutool capture serial --protocol bridge",
    }
    resume = last_complete_row(base) if append and not rotate_s else None
    src = SerialSource(port, baud, stats, opener=opener, log=(lambda s: None) if quiet else _log)
    src.open_first()  # before any file or folder is made: a missing or non-serial port leaves nothing behind
    try:
        csv = CaptureCsv(base, BRIDGE_COLUMNS, meta, rotate_s=rotate_s, append=append, overwrite=force)
        events = EventLog(base.with_suffix(".events.jsonl"), append=True)
    except BaseException:
        src.close()
        raise
    src.events = events
    events.add(
        "started",
        port=port,
        baud=baud,
        protocol="bridge-binary" if binary else "bridge",
        file=csv.file.current,
        truncated_partial_bytes=csv.file.truncated_bytes,
    )
    if resume is not None:
        try:
            dec.resume_after(int(float(resume[BRIDGE_COLUMNS.index("seq")])))
            events.add("resumed", after_seq=dec.last_seq)
        except (ValueError, IndexError):
            events.add("resume_failed", last_row=",".join(resume)[:200])
    status = StatusLine(status_s, quiet)
    stop = stop or StopFlag()
    stop.install()
    clock = FrameClock()
    if resume is not None:  # continue after the last stamp on disk
        try:
            clock.resume_after(float(resume[0]))
        except (ValueError, IndexError):
            pass

    def on_data(data: bytes, tw: float, tm: float) -> None:
        n_gaps = len(dec.stats.gaps)
        seq, t_us, counts = dec.feed_arrays(data)
        s = dec.stats
        for after, missing in s.gaps[n_gaps:]:
            events.add("sequence_gap", after_seq=after, missing=missing)
        stats.frames = s.frames
        stats.dropped = s.dropped
        stats.errors = s.bad_checksum + s.malformed
        stats.error_kinds = {
            "bad_checksum": s.bad_checksum,
            "malformed": s.malformed,
            "garbage_bytes": s.garbage_bytes,
            "repeated": s.repeated,
        }
        n = len(seq)
        if not n:
            return
        ch = counts_to_si(seq, t_us, counts, dec.scales)
        block = np.column_stack(
            [
                clock.map(t_us, seq, tw),
                np.full(n, tm),
                ch["seq"],
                ch["t_mcu"],
                ch["accel"],
                ch["gyro"],
                ch["mag"],
                ch["temp"],
            ]
        )
        csv.write_rows(block)

    try:
        run_loop(src, on_data, stats, duration, status, lambda: csv.file.bytes_written, stop)
    finally:
        stop.restore()
        src.close()
        status.update(stats, csv.file.bytes_written, force=True)
        status.finish()
        summary = _summary(stats, stop.reason)
        summary["decoder"] = dec.stats.as_dict()
        summary["clock"] = clock.as_meta()
        summary["sequence_gaps"] = [{"after_seq": a, "missing": m} for a, m in dec.stats.gaps[:100]]
        csv.close({k: v for k, v in summary.items() if not isinstance(v, (list, dict))})
        events.add("stopped", reason=summary["stop_reason"], frames=stats.frames, dropped=stats.dropped)
        events.close()
    summary["files"] = csv.file.files + events.file.files
    summary["rows"] = csv.rows
    return summary


def _summary(stats: CaptureStats, reason: str) -> dict:
    return {
        "started_utc": stats.started_utc,
        "stopped_utc": iso_utc(time.time()),
        "stop_reason": reason or "stopped",
        "lines": stats.lines,
        "frames": stats.frames,
        "errors": stats.errors,
        "dropped": stats.dropped,
        "reopened": stats.reopen_count,
        "port_gaps": stats.port_gaps,
        "error_kinds": dict(stats.error_kinds),
    }


def utc_name() -> str:
    return datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")


def _iso_us(t: float) -> str:
    return datetime.fromtimestamp(t, tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def _log(msg: str) -> None:
    sys.stderr.write(f"\nimutool capture: {msg}\n")
