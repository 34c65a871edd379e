"""Stream simulated NMEA sentences or bridge frames into a pseudo-terminal: real serial code, no hardware.

``imutool simulate --serve auto --protocol bridge`` creates a pty pair, prints the port name to open and
streams at the chosen rate. A stable symlink (``--link``) lets a test unplug/replug the port (close the pty
and open a new one behind the same name). Every frame sent is logged (sequence number, MCU time, whether a
byte was corrupted on purpose) so a soak test can account for each one.
"""

from __future__ import annotations

import json
import os
import time
import tty
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from formats import nmea

from .bridge import Frame, Scales, encode_binary, encode_config, encode_text


def open_pty() -> tuple[int, int, str]:
    """A new pseudo-terminal pair in raw mode: (master fd, slave fd, slave device name).

    The caller keeps the slave fd open until it closes the master, so bytes written before a reader opens
    the port wait in the terminal buffer instead of being discarded.
    """
    master, slave = os.openpty()
    tty.setraw(slave)
    return master, slave, os.ttyname(slave)


def bridge_frames(rate_hz: float, scales: Scales, seed: int = 0, start_seq: int = 0) -> Iterator[Frame]:
    """Endless frames of a rolling ship (±15° roll, 10 s period) as raw MPU6050/HMC5883L counts."""
    rng = np.random.default_rng(seed)
    k = 0
    g = 9.80665
    while True:
        t = k / rate_hz
        roll = np.radians(15.0) * np.sin(2 * np.pi * t / 10.0)
        rate = np.radians(15.0) * 2 * np.pi / 10.0 * np.cos(2 * np.pi * t / 10.0)
        acc = np.array([0.0, -g * np.sin(roll), -g * np.cos(roll)]) + rng.normal(0, 0.02, 3)
        gyr = np.array([rate, 0.0, 0.0]) + rng.normal(0, 0.002, 3)
        mag = np.array([20.0, 0.0, 40.0]) + rng.normal(0, 0.1, 3)
        counts = np.concatenate([acc / scales.accel, gyr / scales.gyro, mag / scales.mag_ut, [(20.0 - 36.53) * 340]])
        counts = np.clip(np.round(counts), -32768, 32767).astype(int)
        yield Frame((start_seq + k) & 0xFFFF, int(t * 1e6) & 0xFFFFFFFF, tuple(int(c) for c in counts))
        k += 1


def nmea_lines(rate_hz: float, seed: int = 0) -> Iterator[tuple[int, bytes]]:
    """Endless NMEA sentences (HDT, XDR roll/pitch, HRM-like heel) of a rolling, slowly turning ship."""
    rng = np.random.default_rng(seed)
    k = 0
    while True:
        t = k / rate_hz
        heading = (90.0 + 0.5 * t) % 360.0
        roll = 15.0 * np.sin(2 * np.pi * t / 10.0) + rng.normal(0, 0.05)
        pitch = 2.0 * np.sin(2 * np.pi * t / 7.0)
        kind = k % 3
        if kind == 0:
            s = nmea.format_sentence("HE", "HDT", [f"{heading:.1f}", "T"])
        elif kind == 1:
            s = nmea.xdr_roll_pitch(roll, pitch)
        else:
            s = nmea.format_sentence("HE", "THS", [f"{heading:.1f}", "A"])
        yield k, (s + "\r\n").encode()
        k += 1


@dataclass
class ServeLog:
    """What was sent: frame ids and which were corrupted on purpose (for loss accounting)."""

    sent: int = 0
    corrupted: list[int] = field(default_factory=list)
    first_id: int | None = None
    last_id: int | None = None
    reconnects: int = 0

    def as_dict(self) -> dict:
        return {
            "sent": self.sent,
            "corrupted": self.corrupted,
            "first_id": self.first_id,
            "last_id": self.last_id,
            "reconnects": self.reconnects,
        }


def serve(
    protocol: str = "bridge",
    rate_hz: float = 200.0,
    duration: float | None = None,
    seed: int = 0,
    corrupt_fraction: float = 0.0,
    link: str | None = None,
    replug_every: float | None = None,
    log_path: str | None = None,
    announce=print,
    stop_check=lambda: False,
    start_delay: float = 0.0,
    start_when: str | None = None,
) -> ServeLog:
    """Serve frames into a pty until ``duration`` (s) or ``stop_check()``; returns what was sent.

    protocol: ``nmea``, ``bridge`` (text) or ``bridge-binary``. ``link``: a path kept pointing at the current
    pty slave. ``replug_every``: close and reopen the pty every so many seconds (simulated unplug).
    Frame ids are the bridge sequence numbers' unwrapped count (or the NMEA sentence index).
    ``start_delay`` (s) waits after announcing the port so a reader can open it first (pyserial flushes the
    input buffer when it opens a port, so bytes sent before that are never seen by any reader);
    ``start_when`` waits (up to 120 s) until that file exists, e.g. the capture's events log.
    """
    rng = np.random.default_rng(seed + 1)
    scales = Scales()
    log = ServeLog()
    master, slave, name = open_pty()
    _point(link, name)
    announce(link or name)
    if start_when:
        deadline = time.monotonic() + 120.0
        while not os.path.exists(start_when) and time.monotonic() < deadline:
            time.sleep(0.05)
    time.sleep(start_delay)
    if protocol == "nmea":
        source = ((i, line) for i, line in nmea_lines(rate_hz, seed))
    else:
        enc = encode_binary if protocol == "bridge-binary" else encode_text
        frames = bridge_frames(rate_hz, scales, seed)
        source = ((i, enc(f)) for i, f in enumerate(frames))
        if protocol == "bridge":
            os.write(master, encode_config(scales))
    t0 = time.monotonic()
    last_plug = t0
    period = 1.0 / rate_hz
    next_t = t0
    batch = max(1, int(rate_hz / 200))  # write in small batches at high rates
    try:
        for i, payload in source:
            now = time.monotonic()
            if (duration is not None and now - t0 >= duration) or stop_check():
                break
            if replug_every and now - last_plug >= replug_every:
                os.close(master)
                os.close(slave)
                time.sleep(0.3)
                master, slave, name = open_pty()
                _point(link, name)
                log.reconnects += 1
                last_plug = time.monotonic()
            data = bytearray(payload)
            if corrupt_fraction and rng.random() < corrupt_fraction:
                j = int(rng.integers(1, len(data) - 2))
                flipped = data[j] ^ (1 << int(rng.integers(0, 7)))
                while flipped in (0x0A, 0x0D, 0x24, 0x2A, 0xA5):  # keep line ends, '$', '*' and sync bytes intact
                    flipped = data[j] ^ (1 << int(rng.integers(0, 7)))
                data[j] = flipped
                log.corrupted.append(i)
            try:
                os.write(master, bytes(data))
            except OSError:
                continue
            log.sent += 1
            log.first_id = i if log.first_id is None else log.first_id
            log.last_id = i
            next_t += period
            if i % batch == 0:
                delay = next_t - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
    finally:
        time.sleep(2.0)  # let the reader drain the terminal buffer before the port goes away
        os.close(master)
        os.close(slave)
        if log_path:
            with open(log_path, "w") as f:
                json.dump(log.as_dict(), f)
    return log


def _point(link: str | None, target: str) -> None:
    if not link:
        return
    tmp = link + ".new"
    if os.path.lexists(tmp):
        os.unlink(tmp)
    os.symlink(target, tmp)
    os.replace(tmp, link)
