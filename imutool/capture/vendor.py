"""Serial capture of a raw-IMU vendor protocol (VectorNav ASCII ``$VNYMR``/``$VNIMU``, WitMotion 0x55 packets;
:mod:`formats.imu_protocols`) into an imutool CSV in SI units, body FRD, as ``imutool capture serial --protocol
vectornav|witmotion``.

These frames carry no usable device clock: each sample's ``time`` is the UTC arrival of the read that completed
it, less the bytes that followed it in that read at 10 bits a byte at the baud rate, kept strictly increasing;
``time_mono`` is the host's monotonic clock at the read. The vendor's axes, signs and units and their conversion
are written into the file's metadata (``conventions``); the vendor's own attitude, when sent, is kept as
``vendor_roll``, ``vendor_pitch``, ``vendor_yaw`` (deg, imutool's signs).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from formats.imu_protocols import make_decoder

from .runtime import CaptureStats, StatusLine, StopFlag, iso_utc
from .serial_capture import SerialSource, _log, _summary, run_loop, utc_name
from .sink import CaptureCsv, EventLog

VENDOR_COLUMNS = ["time", "time_mono"]
VENDOR_COLUMNS += [f"{c}_{a}" for c in ("gyro", "accel", "mag") for a in "xyz"]
VENDOR_COLUMNS += ["temp", "vendor_roll", "vendor_pitch", "vendor_yaw"]


def capture_vendor(
    port: str,
    baud: int,
    out: str,
    protocol: str,
    duration: float | None = None,
    rotate_s: float | None = None,
    status_s: float | None = 10.0,
    quiet: bool = False,
    append: bool = False,
    force: bool = False,
    opener: Callable | None = None,
    stop: StopFlag | None = None,
) -> dict:
    """Record a VectorNav/WitMotion IMU from a serial port; ``out`` a folder or a ``.csv`` path."""
    dec = make_decoder(protocol)
    base = Path(out)
    if base.suffix.lower() != ".csv":
        base = base / f"{protocol}_{utc_name()}.csv"
    stats = CaptureStats(started_utc=iso_utc(time.time()))
    meta = {
        "source": f"serial {port} @ {baud} baud ({protocol})",
        "time": "UTC epoch seconds at arrival, less the bytes after the sample in its read at 10 bits/byte",
        "time_mono": "host monotonic clock at the read that carried the sample",
        "frame": "body FRD (x forward, y starboard, z down); accel = specific force (+g up at rest: accel_z<0)",
        "conventions": dec.conventions,
        "units": "gyro=rad/s, accel=m/s^2, mag=uT, temp=degC, vendor_roll/pitch/yaw=deg",
        "captured_by": f"imutool capture serial --protocol {protocol}",
    }
    src = SerialSource(port, baud, stats, opener=opener, log=(lambda s: None) if quiet else _log)
    src.open_first()  # before any file or folder is made
    try:
        csv = CaptureCsv(base, VENDOR_COLUMNS, meta, rotate_s=rotate_s, append=append, overwrite=force)
        events = EventLog(base.with_suffix(".events.jsonl"), append=True)
    except BaseException:
        src.close()
        raise
    src.events = events
    events.add("started", port=port, baud=baud, protocol=protocol, file=csv.file.current)
    status = StatusLine(status_s, quiet)
    stop = stop or StopFlag()
    stop.install()
    byte_s = 10.0 / baud if baud else 0.0
    last = [-np.inf]

    def on_data(data: bytes, tw: float, tm: float) -> None:
        s = dec.feed(data)
        d = dec.stats
        stats.frames = d.frames
        stats.errors = d.bad_checksum + d.malformed
        stats.error_kinds = {k: v for k, v in d.as_dict().items() if k not in ("frames", "samples") and v}
        n = len(s)
        if not n:
            return
        back = (len(data) - s.end) * byte_s
        t = tw - back
        for k in range(n):
            t[k] = last[0] = max(float(t[k]), last[0] + 1e-6)
        nan3 = np.full((n, 3), np.nan)
        block = np.column_stack(
            [
                t,
                tm - back,
                s.gyro,
                s.accel,
                s.mag if s.mag is not None else nan3,
                s.temp if s.temp is not None else np.full(n, np.nan),
                s.attitude if s.attitude is not None else nan3,
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
        csv.close({k: v for k, v in summary.items() if not isinstance(v, (list, dict))})
        events.add("stopped", reason=summary["stop_reason"], frames=stats.frames)
        events.close()
    summary["files"] = csv.file.files + events.file.files
    summary["rows"] = csv.rows
    return summary
