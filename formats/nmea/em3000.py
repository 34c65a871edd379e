"""Kongsberg EM3000 (and EM1000/EM950) binary attitude datagrams, read from a file of back-to-back frames.

Layout (Kongsberg EK80/ES80/ST90 reference manuals, "Kongsberg EM Attitude 3000 datagram format"; the Simrad
EM Attitude 3000 telegram in the EM installation manuals), 10 bytes, little-endian (LSB first):

====  ==========================================================================================
byte  content
====  ==========================================================================================
0     sync byte 1 / sensor status: 00h (EM1000: no status), 90h valid full accuracy, 91h–99h valid
      with reduced accuracy, 9Ah–9Fh not valid (normal operation, e.g. configuration), A0h–AFh sensor error
1     sync byte 2: always 90h
2–3   roll, 0.01°, two's complement, + port side up (= imutool's + starboard down), valid ±179.99°
4–5   pitch, 0.01°, two's complement, + bow up, valid ±179.99°
6–7   heave, 1 cm, two's complement, + up, valid ±9.99 m
8–9   heading, 0.01°, 0 to 359.99° clockwise
====  ==========================================================================================

The manuals call every field two's complement, but 359.99° does not fit a signed 16-bit number (its maximum
is 327.67°): the heading is read as unsigned (0–35999), the only reading that covers the documented range.
A value outside its valid range is NaN; a frame whose status says not valid (9Ah–AFh) gives NaN for every
value. Roll may be set on the sender to the TSS (horizontal-plane) convention: ``roll_convention='tss'``
converts it to Euler roll. The frames carry no time: the caller gives the output rate.
"""

from __future__ import annotations

import os
import struct
from datetime import datetime, timezone
from typing import Any

import numpy as np

from ..errors import ImutoolError
from ..recording import Recording
from .motion import CONVENTIONS, tss_roll_to_euler

FRAME_LENGTH = 10
SYNC2 = 0x90
ROLL_CONVENTIONS = ("euler", "tss")


def _sync_ok(b0: np.ndarray, b1: np.ndarray) -> np.ndarray:
    return (b1 == SYNC2) & ((b0 == 0) | ((b0 >= 0x90) & (b0 <= 0xAF)))


def em3000_frame(roll_deg: float, pitch_deg: float, heave_m: float, heading_deg: float, status: int = 0x90) -> bytes:
    """One 10-byte frame (for tests and simulators): roll + starboard down, pitch + bow up, heave + up, heading
    0–359.99°, status byte 00h or 90h–AFh."""
    if not (status == 0 or 0x90 <= status <= 0xAF):
        raise ImutoolError(f"EM3000 status byte {status:#04x} is not 00h or 90h–AFh")
    r, p, h = round(roll_deg * 100), round(pitch_deg * 100), round(heave_m * 100)
    hd = round((heading_deg % 360.0) * 100) % 36000
    for v, what in ((r, "roll"), (p, "pitch"), (h, "heave")):
        if not -32768 <= v <= 32767:
            raise ImutoolError(f"EM3000: {what} does not fit the frame")
    return struct.pack("<BBhhhH", status, SYNC2, r, p, h, hd)


def scan_frames(data: bytes) -> tuple[np.ndarray, int]:
    """Frames found in ``data``: an (n, 10) uint8 array, and the number of bytes skipped between them (bytes that
    do not start a frame: a cut at the start, line noise). Frames back to back from one offset are taken in one
    step; otherwise the scan walks byte by byte, resynchronising on the sync bytes."""
    buf = np.frombuffer(data, dtype=np.uint8)
    n = len(buf)
    if n < FRAME_LENGTH:
        return np.empty((0, FRAME_LENGTH), np.uint8), n
    ok = np.zeros(n, bool)
    ok[: n - 1] = _sync_ok(buf[:-1], buf[1:])
    ok[n - FRAME_LENGTH + 1 :] = False
    for k in range(FRAME_LENGTH):  # fast path: every frame from offset k, nothing in between
        m = (n - k) // FRAME_LENGTH
        if m and ok[k : k + m * FRAME_LENGTH : FRAME_LENGTH].all() and n - k - m * FRAME_LENGTH < FRAME_LENGTH:
            return buf[k : k + m * FRAME_LENGTH].reshape(m, FRAME_LENGTH), n - m * FRAME_LENGTH
    starts = []
    i = 0
    skipped = 0
    cand = np.flatnonzero(ok)
    j = 0
    while j < len(cand):
        c = int(cand[j])
        if c < i:
            j += 1
            continue
        skipped += c - i
        starts.append(c)
        i = c + FRAME_LENGTH
        j += 1
    skipped += n - i if i < n else 0
    idx = np.array(starts, dtype=np.int64)
    frames = buf[idx[:, None] + np.arange(FRAME_LENGTH)] if len(idx) else np.empty((0, FRAME_LENGTH), np.uint8)
    return frames, skipped


def decode_frames(frames: np.ndarray) -> dict[str, np.ndarray]:
    """Channels of an (n, 10) frame array: roll, pitch, heading (deg), heave (m), em_status (the status byte);
    NaN where a value is out of its valid range or the status says not valid."""
    f = np.ascontiguousarray(frames, dtype=np.uint8)
    status = f[:, 0].astype(float)
    roll = f[:, 2:4].copy().view("<i2")[:, 0] / 100.0
    pitch = f[:, 4:6].copy().view("<i2")[:, 0] / 100.0
    heave = f[:, 6:8].copy().view("<i2")[:, 0] / 100.0
    heading = f[:, 8:10].copy().view("<u2")[:, 0] / 100.0
    invalid = (status >= 0x9A) & (status <= 0xAF)
    roll[(np.abs(roll) > 179.99) | invalid] = np.nan
    pitch[(np.abs(pitch) > 179.99) | invalid] = np.nan
    heave[(np.abs(heave) > 9.99) | invalid] = np.nan
    heading[(heading > 359.99) | invalid] = np.nan
    return {"roll": roll, "pitch": pitch, "heave": heave, "heading": heading, "em_status": status}


def read_em3000(
    path: str | os.PathLike,
    rate_hz: float,
    roll_convention: str = "euler",
    start_utc: str | None = None,
) -> Recording:
    """Read a file of EM3000/EM1000 attitude frames into a Recording: roll, pitch, heading (deg), heave (m, + up),
    em_status. ``rate_hz``: the sensor's output rate (the frames carry no time; time = frame index / rate, from
    0 or from ``start_utc``, ISO 8601, in Unix seconds). ``roll_convention``: ``euler`` (default, as the EM
    systems use it) or ``tss`` (the sender is set to the TSS / horizontal-plane roll: converted to Euler).
    Raises ImutoolError for an unreadable file, a file with no frame, or a missing rate."""
    spath = os.fspath(path)
    if rate_hz is None or not (float(rate_hz) > 0 and np.isfinite(float(rate_hz))):
        raise ImutoolError("EM3000 frames carry no time: give the output rate (rate_hz > 0)", path=spath)
    if roll_convention not in ROLL_CONVENTIONS:
        raise ImutoolError(f"roll convention must be one of {', '.join(ROLL_CONVENTIONS)}", path=spath)
    try:
        with open(spath, "rb") as fh:
            data = fh.read()
    except OSError as e:
        raise ImutoolError(f"cannot read: {e.strerror or e}", path=spath) from None
    frames, skipped = scan_frames(data)
    if len(frames) == 0:
        raise ImutoolError(f"no EM3000 attitude frame (10 bytes, second byte 90h) in {len(data)} bytes", path=spath)
    ch = decode_frames(frames)
    if roll_convention == "tss":
        ch["roll"] = np.array([tss_roll_to_euler(r, p) for r, p in zip(ch["roll"], ch["pitch"], strict=True)])
    t0 = 0.0
    meta: dict[str, Any] = {}
    if start_utc:
        try:
            d = datetime.fromisoformat(str(start_utc).strip().replace("Z", "+00:00"))
        except ValueError:
            raise ImutoolError(f"start_utc {str(start_utc)[:40]!r} is not an ISO 8601 time", path=spath) from None
        d = d if d.tzinfo else d.replace(tzinfo=timezone.utc)
        t0 = d.timestamp()
        meta["start_utc"] = d.isoformat()
    t = t0 + np.arange(len(frames)) / float(rate_hz)
    st = ch["em_status"]
    rec = Recording(
        t,
        ch,
        {"roll": "deg", "pitch": "deg", "heave": "m", "heading": "deg", "em_status": "1"},
    )
    rec.meta.update(
        {
            "source": spath,
            "format": "em3000",
            "time_source": f"frame index / {float(rate_hz):g} Hz (the frames carry no time)",
            "frames": len(frames),
            "bytes_skipped": int(skipped),
            "status": {
                "valid_full_accuracy": int(np.count_nonzero((st == 0x90) | (st == 0))),
                "valid_reduced_accuracy": int(np.count_nonzero((st >= 0x91) & (st <= 0x99))),
                "not_valid": int(np.count_nonzero((st >= 0x9A) & (st <= 0x9F))),
                "sensor_error": int(np.count_nonzero(st >= 0xA0)),
            },
            "roll_convention": roll_convention,
            "conventions": {"EM3000": CONVENTIONS["EM3000"]},
            "signs": "roll + starboard down, pitch + bow up, heave + up (m), heading deg true",
            **meta,
        }
    )
    return rec
