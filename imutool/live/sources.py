"""Where `imutool live` takes its samples from: a replayed recording, a serial IMU, a polled I2C/Modbus sensor,
and a second port with GNSS velocity and a gyrocompass heading.

A source hands the engine :class:`SampleBlock` s — rows of (time s, gyro rad/s, accel m/s², mag µT) in the
sensor's frame, SI — through ``read(timeout)``; ``None`` means nothing arrived within the timeout. Live times
come from the host's monotonic clock (or the sensor's own clock mapped to it), never from the wall clock, so a
jump of the host clock does not move them: ``t = mono - mono_at_start + utc_at_start``.

A serial IMU protocol is a :class:`FrameDecoder` registered in :data:`DECODERS` (:func:`register_decoder`):
``feed(data, t_mono) -> SampleBlock`` and a ``stats`` dict of counts (``frames``, ``bad_checksum``,
``malformed``, ``garbage_bytes``); factories are called with ``clock=`` and ``baud=``. The port itself (reopened
with backoff when it vanishes) is capture's :class:`imutool.capture.serial_capture.SerialSource`. The raw-IMU
vendor protocols of :mod:`formats.imu_protocols` (``vectornav``, ``witmotion``) are registered through
:class:`VendorFrames`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from formats import Recording
from formats.errors import ImutoolError


@dataclass
class SampleBlock:
    """Rows of one sensor, in time order: t (N,) s; gyro, accel (N,3) rad/s, m/s²; mag (N,3) µT or None."""

    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    mag: np.ndarray | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)  # e.g. heading_true (deg), sog (m/s), cog (deg)

    def __len__(self) -> int:
        return len(self.t)

    @staticmethod
    def empty() -> SampleBlock:
        return SampleBlock(np.empty(0), np.empty((0, 3)), np.empty((0, 3)), None)


class Source(Protocol):
    """What the engine reads: ``read(timeout)`` → a block or None; ``stats`` counts; ``connected``; ``close()``.
    ``finished`` is True when a finite source (a replay) has nothing more to give."""

    stats: dict[str, Any]
    connected: bool
    finished: bool
    description: str

    def read(self, timeout: float) -> SampleBlock | None: ...

    def close(self) -> None: ...


class FrameDecoder(Protocol):
    """A serial IMU protocol: bytes in (with the host monotonic time of the read), samples out, counts kept."""

    stats: dict[str, int]

    def feed(self, data: bytes, t_mono: float) -> SampleBlock: ...


DECODERS: dict[str, Callable[..., FrameDecoder]] = {}
"""Serial IMU protocols by name (``--protocol``); a decoder module adds itself with :func:`register_decoder`."""


def register_decoder(name: str, factory: Callable[..., FrameDecoder]) -> None:
    """Make a serial protocol available to ``imutool live --protocol NAME`` (factory(**options) → decoder)."""
    DECODERS[name] = factory


class BridgeFrames:
    """The capture's bridge protocol (text or binary) as a :class:`FrameDecoder`. ``clock='host'``: the MCU's clock
    mapped to the host's monotonic clock (:class:`imutool.capture.clock.FrameClock`: offset and drift fitted to the
    arrivals), so frames keep their own spacing; ``clock='sensor'``: the MCU's clock alone (unwrapped), offset to
    the host's at the first frame — for a sensor whose clock is trusted, or frames replayed faster than real time."""

    def __init__(self, binary: bool = False, scales: Any = None, clock: str = "host") -> None:
        from imutool.capture.bridge import BridgeDecoder  # numba kernels: only this protocol needs them
        from imutool.capture.clock import FrameClock

        self.dec = BridgeDecoder(binary=binary, scales=scales)
        self.clock = FrameClock()
        if clock not in ("host", "sensor"):
            raise ImutoolError(f"clock {clock!r}: expected host or sensor")
        self.sensor_clock = clock == "sensor"
        self._t0: float | None = None

    @property
    def stats(self) -> dict[str, int]:
        """The decoder's counts (made when asked: a live frame is often decoded alone)."""
        s = self.dec.stats
        return {"frames": s.frames, "bad_checksum": s.bad_checksum, "malformed": s.malformed,
                "garbage_bytes": s.garbage_bytes, "dropped": s.dropped}  # fmt: skip

    def feed(self, data: bytes, t_mono: float) -> SampleBlock:
        from imutool.capture.bridge import counts_to_si

        seq, t_us, counts = self.dec.feed_arrays(data)
        if not len(seq):
            return SampleBlock.empty()
        ch = counts_to_si(seq, t_us, counts, self.dec.scales)
        if self.sensor_clock:
            us, _cut = self.clock._unwrap_us(t_us)  # (a restart of the MCU shows as times that go back: dropped)
            if self._t0 is None:
                self._t0 = t_mono - us[0] * 1e-6
            t = us * 1e-6 + self._t0
        else:
            t = self.clock.map(t_us, seq, t_mono)
        return SampleBlock(np.asarray(t, float), ch["gyro"], ch["accel"], ch["mag"])


register_decoder("bridge", lambda baud=None, **kw: BridgeFrames(binary=False, **kw))
register_decoder("bridge-binary", lambda baud=None, **kw: BridgeFrames(binary=True, **kw))


class VendorFrames:
    """A raw-IMU vendor protocol of :mod:`formats.imu_protocols` (VectorNav ASCII, WitMotion binary) as a
    :class:`FrameDecoder`. These frames carry no device clock, so samples are timed by the host. A sample cannot
    be later than its bound B: the read's monotonic arrival less the bytes that followed it (10 bits a byte at
    ``baud``). Until the device's output period is known (``period_s``: the mean spacing of the arrivals since
    the start, after 1 s and 20 samples) a sample is at B. Then the samples are paced: the last of a read
    ``n`` periods after the previous sample, pulled 2 % of the way toward B, the others a period apart before it
    (or, when B comes sooner, evenly up to B) — so a backlog read in pieces after the host stalled keeps its
    true spacing, and arrival jitter does not reach the times; a lead of over ``gap_s`` (the device stopped)
    restarts at B. Times are strictly increasing. The vendor's attitude (deg, imutool's signs) rides along as
    ``extra`` vendor_roll, vendor_pitch, vendor_yaw."""

    PULL = 0.02

    def __init__(
        self, protocol: str, clock: str = "host", baud: int | None = None, gap_s: float = 5.0, **options: Any
    ) -> None:
        from formats.imu_protocols import make_decoder

        if clock != "host":
            raise ImutoolError(f"serial protocol {protocol!r} has no device clock in its frames: use --clock host")
        self.dec = make_decoder(protocol, **options)
        self.byte_s = 10.0 / baud if baud else 0.0
        self.gap_s = gap_s
        self.conventions: str = self.dec.conventions
        self._last = -np.inf
        self._b0: float | None = None
        self._n = 0
        self.period_s: float | None = None
        self.stats: dict[str, int] = {}

    def feed(self, data: bytes, t_mono: float) -> SampleBlock:
        s = self.dec.feed(data)
        self.stats = self.dec.stats.as_dict()
        n = len(s)
        if not n:
            return SampleBlock.empty()
        bound = t_mono - (len(data) - s.end) * self.byte_s
        b = float(bound[-1])
        T = self.period_s
        if T is None:
            t = bound
        else:
            lead = b - (self._last + n * T)
            if lead < 0:  # they arrived sooner than their periods allow: spread evenly up to B
                t = self._last + (b - self._last) / n * np.arange(1, n + 1, dtype=float)
            else:
                t_end = b if lead > self.gap_s else b - lead * (1.0 - self.PULL)
                t = t_end - T * np.arange(n - 1, -1, -1, dtype=float)
        for k in range(n):  # (a few samples a read)
            t[k] = self._last = max(float(t[k]), self._last + 1e-6)
        if self._b0 is None:
            self._b0, self._n = b, 1
        else:
            self._n += n
        if b - self._b0 >= 1.0 and self._n >= 20:
            self.period_s = (b - self._b0) / (self._n - 1)
        mag = s.mag if s.mag is not None and np.isfinite(s.mag).any() else None
        extra = {}
        if s.attitude is not None:
            extra = {f"vendor_{k}": s.attitude[:, i] for i, k in enumerate(("roll", "pitch", "yaw"))}
        return SampleBlock(np.asarray(t, float), s.gyro, s.accel, mag, extra)


def _register_vendor_protocols() -> None:
    from formats.imu_protocols import PROTOCOLS

    for name in PROTOCOLS:
        register_decoder(name, lambda name=name, **kw: VendorFrames(name, **kw))


_register_vendor_protocols()


class SerialImu:
    """A serial IMU: capture's self-reopening port and a :class:`FrameDecoder`. Times are the host's monotonic
    clock shifted to UTC at start (``utc0 - mono0``), so a host clock jump does not move them."""

    def __init__(
        self,
        port: str,
        baud: int,
        protocol: str = "bridge",
        opener: Callable | None = None,
        log: Callable[[str], None] | None = None,
        clock: str = "host",
    ) -> None:
        from imutool.capture.runtime import CaptureStats
        from imutool.capture.serial_capture import SerialSource

        if protocol not in DECODERS:
            raise ImutoolError(f"serial protocol {protocol!r}: known {', '.join(sorted(DECODERS))}")
        self.decoder = DECODERS[protocol](clock=clock, baud=baud)
        conv = getattr(self.decoder, "conventions", None)
        self.meta: dict[str, str] = {"protocol": protocol, **({"conventions": conv} if conv else {})}
        self._cstats = CaptureStats(started_utc="")
        self.port = SerialSource(port, baud, self._cstats, max_backoff=2.0, opener=opener, log=log)
        self.port.batch_s = 0.0  # the engine wants each frame as soon as it is there (latency)
        self.port.open_first()
        self._offset = time.time() - time.monotonic()
        self.description = f"serial {port} @ {baud} baud ({protocol})"
        self.finished = False

    @property
    def stats(self) -> dict[str, Any]:
        return {**self.decoder.stats, "reopened": self._cstats.reopen_count}

    @property
    def connected(self) -> bool:
        return self.port._ser is not None

    def read(self, timeout: float) -> SampleBlock | None:
        data, _tw, tm = self.port.read()
        if not data:
            return None
        blk = self.decoder.feed(data, tm)
        if not len(blk):
            return None
        if not getattr(self.decoder, "utc_times", False):
            blk.t = blk.t + self._offset  # monotonic → UTC of the start
        return blk

    def close(self) -> None:
        self.port.close()


class PolledImu:
    """A sensor read by polling at a steady rate (I2C MPU6050 + magnetometer, a Modbus inclinometer):
    ``read_row()`` → (gyro (3,), accel (3,), mag (3,) or None); an exception counts as a lost sample."""

    def __init__(self, read_row: Callable[[], tuple], rate_hz: float, description: str, close: Callable = None):
        self._read_row = read_row
        self.dt = 1.0 / rate_hz
        self._next = time.monotonic()
        self._offset = time.time() - time.monotonic()
        self._close = close
        self.description = description
        self.finished = False
        self.connected = True
        self.stats: dict[str, Any] = {"frames": 0, "read_errors": 0}

    def read(self, timeout: float) -> SampleBlock | None:
        wait = self._next - time.monotonic()
        if wait > timeout:
            time.sleep(timeout)
            return None
        if wait > 0:
            time.sleep(wait)
        self._next = max(self._next + self.dt, time.monotonic() - self.dt)
        tm = time.monotonic()
        try:
            g, a, m = self._read_row()
        except Exception:
            self.stats["read_errors"] += 1
            self.connected = False
            return None
        self.connected = True
        self.stats["frames"] += 1
        mag = None if m is None else np.asarray(m, float).reshape(1, 3)
        return SampleBlock(np.array([tm + self._offset]), np.asarray(g, float).reshape(1, 3),
                           np.asarray(a, float).reshape(1, 3), mag)  # fmt: skip

    def close(self) -> None:
        if self._close is not None:
            self._close()


def i2c_source(bus: str, rate_hz: float = 100.0, mag: str | None = "hmc5883l", bus_obj: Any = None) -> PolledImu:
    """An MPU6050 (and an HMC5883L/QMC5883L) on a Linux I2C bus, polled at ``rate_hz`` (capture's drivers)."""
    from imutool.capture.i2c import HMC5883L, MPU6050, QMC5883L, open_bus

    b = bus_obj if bus_obj is not None else open_bus(bus)
    imu = MPU6050(b, 0x68, 2, 250, bus_name=str(bus))
    m = (
        None
        if not mag
        else (HMC5883L(b, 1, bus_name=str(bus)) if mag == "hmc5883l" else QMC5883L(b, 8, bus_name=str(bus)))
    )

    def row() -> tuple:
        a, g, _temp = imu.read()
        return g, a, None if m is None else m.read()

    return PolledImu(row, rate_hz, f"I2C {bus} mpu6050{'+' + mag if mag else ''}", getattr(b, "close", None))


def modbus_source(port: str, profile_path: str, rate_hz: float = 10.0) -> PolledImu:
    """A Modbus RTU sensor (capture's register profile) giving gyro_x..z (rad/s) and accel_x..z (m/s²) (and
    mag_x..z, µT), polled at ``rate_hz``."""
    from imutool.capture.modbus import ModbusPoller, read_profile

    poller = ModbusPoller(port, read_profile(profile_path))
    names = {r.name for r in poller.profile.registers}
    need = [f"{c}_{a}" for c in ("gyro", "accel") for a in "xyz"]
    missing = [n for n in need if n not in names]
    if missing:
        raise ImutoolError(
            f"the Modbus profile has no {', '.join(missing)} (live needs gyro and accel)", path=profile_path
        )
    has_mag = all(f"mag_{a}" in names for a in "xyz")

    def row() -> tuple:
        v = poller.read()
        g = [v[f"gyro_{a}"] for a in "xyz"]
        acc = [v[f"accel_{a}"] for a in "xyz"]
        return g, acc, [v[f"mag_{a}"] for a in "xyz"] if has_mag else None

    return PolledImu(row, rate_hz, f"Modbus {port}", poller.close)


class ReplaySource:
    """A recording imutool reads, handed out paced by its own time stamps (``speed`` × real time; 0 = as fast
    as it goes). Loaded as ``filter`` loads it (calibration and mounting are applied by the engine, as live)."""

    def __init__(self, rec: Recording, speed: float = 1.0, block_s: float = 0.01, description: str = "") -> None:
        for ch in ("gyro", "accel"):
            if ch not in rec.channels:
                raise ImutoolError(f"a replay needs channel {ch!r}; the recording has {', '.join(rec.channels)}")
        self.t = np.asarray(rec.time, float)
        self.gyro = np.asarray(rec.in_unit("gyro", "rad/s"), float)
        self.accel = np.asarray(rec.in_unit("accel", "m/s^2"), float)
        self.mag = np.asarray(rec["mag"], float) if "mag" in rec.channels else None
        self.extra = {k: np.asarray(rec[k], float) for k in ("heading_true", "sog", "cog", "vel_n", "vel_e")
                      if k in rec.channels}  # fmt: skip
        self.speed = float(speed)
        self.block_s = block_s
        self.i = 0
        self._w0: float | None = None
        self.description = description or f"replay of {rec.meta.get('source', 'a recording')}"
        self.finished = len(self.t) == 0
        self.connected = True
        self.stats: dict[str, Any] = {"frames": 0}

    def read(self, timeout: float) -> SampleBlock | None:
        if self.finished:
            return None
        n = len(self.t)
        if self._w0 is None:
            self._w0 = time.monotonic()
        if self.speed <= 0:  # as fast as it goes: blocks of block_s of input time
            j = int(np.searchsorted(self.t, self.t[self.i] + max(self.block_s, 1e-9), side="left"))
        else:
            due = self.t[0] + (time.monotonic() - self._w0) * self.speed
            if self.t[self.i] > due:
                time.sleep(min(timeout, (self.t[self.i] - due) / self.speed))
                due = self.t[0] + (time.monotonic() - self._w0) * self.speed
            j = int(np.searchsorted(self.t, due, side="right"))
        j = min(max(j, self.i + (1 if self.speed <= 0 else 0)), n)
        if j <= self.i:
            return None
        s = slice(self.i, j)
        self.i = j
        self.finished = j >= n
        self.stats["frames"] = j
        return SampleBlock(self.t[s], self.gyro[s], self.accel[s], None if self.mag is None else self.mag[s],
                           {k: v[s] for k, v in self.extra.items()})  # fmt: skip

    def close(self) -> None:
        self.finished = True


class AuxNmea:
    """The second port: GNSS velocity (RMC/VTG: sog m/s, cog deg) and a gyrocompass heading (HDT/THS, deg),
    decoded as they come (``formats.nmea.decode_fast``), kept with their host monotonic arrival time; the engine
    takes the latest at each IMU row (:meth:`latest`) and ignores values older than ``max_age_s``."""

    def __init__(self, port: str, baud: int = 4800, opener: Callable | None = None, max_age_s: float = 5.0) -> None:
        from imutool.capture.runtime import CaptureStats
        from imutool.capture.serial_capture import SerialSource

        self._cstats = CaptureStats(started_utc="")
        self.port = SerialSource(port, baud, self._cstats, max_backoff=2.0, opener=opener)
        self.port.open_first()
        self.max_age_s = max_age_s
        self._buf = bytearray()
        self.values: dict[str, tuple[float, float]] = {}  # name → (value, mono time)
        self.stats = {"sentences": 0, "bad": 0}
        self.description = f"NMEA {port} @ {baud}"

    def poll(self) -> None:
        """Read what arrived (non-blocking enough: the port's timeout) and decode whole lines."""
        from formats.nmea import decode_fast

        data, _tw, tm = self.port.read()
        if not data:
            return
        self._buf += data
        *lines, rest = bytes(self._buf).split(b"\n")
        self._buf = bytearray(rest[-4096:])
        for raw in lines:
            text = raw.decode("ascii", "replace").strip()
            if not text.startswith("$"):
                continue
            try:
                vals = decode_fast(text)
            except Exception:
                vals = None
            if not vals:
                self.stats["bad"] += 1
                continue
            self.stats["sentences"] += 1
            for k in ("sog", "cog", "heading_true"):
                if k in vals and np.isfinite(vals[k]):
                    self.values[k] = (float(vals[k]), tm)

    def latest(self, now_mono: float) -> dict[str, float]:
        """The values no older than ``max_age_s`` (sog m/s, cog deg, heading_true deg)."""
        return {k: v for k, (v, tm) in self.values.items() if now_mono - tm <= self.max_age_s}

    def close(self) -> None:
        self.port.close()
