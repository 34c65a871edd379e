"""WitMotion binary serial output (WT901, JY901 and their relatives: WT901C, WT901SDCL, HWT901B…).

Source: WitMotion *WT901 Datasheet* v20-0702 (wiki.wit-motion.com/english), §5.1 "Output data" (5.1.2
acceleration 0x51, 5.1.3 angular velocity 0x52, 5.1.4 angle 0x53, 5.1.5 magnetic 0x54; 0x50 time) and §5.2.8
"Return content"; the WT901SDCL datasheet v20-0605 §6.1 has the same tables. Written from those documents.

Packets are 11 bytes: ``0x55, type, d0…d7, sum`` where ``sum`` is the low byte of the sum of the 10 bytes before
it; the data are four little-endian int16 (``(short)(H << 8 | L)``):

- 0x51 acceleration: ax, ay, az × 16 g / 32768 (g taken as standard gravity 9.80665 m/s²), T / 100 °C
- 0x52 angular velocity: wx, wy, wz × 2000 °/s / 32768, then T (or the supply voltage on newer firmware)
- 0x53 angle: roll (about X), pitch (about Y), yaw (about Z) × 180° / 32768, then a version number
- 0x54 magnetic field: hx, hy, hz in counts (no unit in the WT901 datasheet; the WT901BLECL datasheet gives mG:
  ``mag_ut_per_count`` = 0.1 µT by default), then T / 100 °C
- 0x50 time: YY MM DD hh mm ss, ms (uint16) — used as the device clock (time of day) when present.

The device sends one packet of each enabled type per output cycle, in ascending type order (0x51, 0x52, 0x53,
0x54 by default), so a type not above the last one starts a new cycle. A sample is made as soon as the cycle's
packets have all arrived (the set of a cycle's types is learned from the second cycle seen: accel + gyro needed,
mag and angle when sent; until then a cycle is closed by the next one's start); a cycle that loses its accel or
gyro packet is dropped (``incomplete``), one that loses its mag or angle gives NaN there.

Signs and axes: the module's axes are printed on it, right-handed with Z up out of the board (a module lying
flat at rest reads az = +1 g: the specific force, +up) and roll about X, pitch about Y, yaw about Z. Mounted
flat with its X arrow toward the bow (then Y points to port), its frame is FLU; imutool's body frame is FRD, so
``v_FRD = (x, −y, −z)`` for accel, gyro and mag (at rest level: accel_z = −9.81). The vendor angles, right-hand
rotations about those axes (the datasheet's Z-Y-X Euler angles in an east-north-up frame), become imutool's:
roll = roll (+ starboard down), pitch = −pitch (a right-hand turn about a port-pointing Y puts the bow down),
yaw = −yaw (counter-clockwise → clockwise from above). Another mounting: give imutool's ``--mounting``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from formats.units import STANDARD_GRAVITY

from .base import DecoderStats, ImuSamples, SampleRows

NAME = "witmotion"
CONVENTIONS = (
    "WitMotion WT901/JY901 binary 0x55 packets (WT901 datasheet v20-0702 §5.1): module axes X (arrow, to the "
    "bow), Y (port), Z (up) = FLU; converted to imutool FRD as (x,-y,-z) for accel, gyro, mag; accel counts "
    "x16 g/32768 (g=9.80665) specific force (+1 g on module Z at rest -> accel_z=-9.81); gyro x2000 deg/s/32768 "
    "-> rad/s; mag counts x mag_ut_per_count; vendor roll = roll, pitch = -pitch, yaw = -yaw (imutool signs); "
    "times: host arrival (device time of day from 0x50 when sent)"
)
ACCEL_PER_COUNT = 16.0 * STANDARD_GRAVITY / 32768.0  # m/s² per count
GYRO_PER_COUNT = math.radians(2000.0) / 32768.0  # rad/s per count
ANGLE_PER_COUNT = 180.0 / 32768.0  # deg per count
HEADER = 0x55
TYPES = range(0x50, 0x60)
_FLU_TO_FRD = (1.0, -1.0, -1.0)


def _i16(buf: bytes | bytearray, k: int) -> int:
    v = buf[k] | (buf[k + 1] << 8)
    return v - 65536 if v & 0x8000 else v


class WitMotionDecoder:
    """Incremental decoder of WitMotion 11-byte packets into samples (one per output cycle)."""

    name = NAME
    conventions = CONVENTIONS

    def __init__(self, mag_ut_per_count: float = 0.1) -> None:
        self.mag_scale = float(mag_ut_per_count)
        self._buf = bytearray()
        self._cycle: dict[int, tuple] = {}
        self._types: frozenset[int] | None = None
        self._last_type = 0
        self._closed = 0
        self._in_sync = False
        self.stats = DecoderStats()

    def feed(self, data: bytes) -> ImuSamples:
        """Decode the packets ``data`` completes; keep a partial packet for the next call."""
        base = len(self._buf)
        buf = self._buf
        buf += data
        rows = SampleRows()
        st = self.stats
        i, n = 0, len(buf)
        while n - i >= 1:
            if buf[i] != HEADER:
                j = buf.find(HEADER, i)
                stop = n if j < 0 else j
                st.garbage_bytes += stop - i
                if self._in_sync:
                    st.resyncs += 1
                    self._in_sync = False
                i = stop
                continue
            if n - i < 11:
                break
            t = buf[i + 1]
            if t in TYPES and (sum(buf[i : i + 10]) & 0xFF) == buf[i + 10]:
                st.frames += 1
                self._in_sync = True
                self._packet(t, bytes(buf[i + 2 : i + 10]), i + 11 - base, rows)
                i += 11
                continue
            if self._in_sync:  # at a packet boundary, yet not a good packet: a corrupted one
                if t in TYPES:
                    st.bad_checksum += 1
                st.resyncs += 1
                self._in_sync = False
            st.garbage_bytes += 1
            i += 1
        del buf[:i]
        out = rows.samples()
        st.samples += len(out)
        return out

    def _packet(self, t: int, d: bytes, end: int, rows: SampleRows) -> None:
        if t == 0x51:
            v = (_i16(d, 0) * ACCEL_PER_COUNT, _i16(d, 2) * ACCEL_PER_COUNT, _i16(d, 4) * ACCEL_PER_COUNT)
            val: tuple = (_frd(v), _i16(d, 6) / 100.0)
        elif t == 0x52:
            val = (_frd((_i16(d, 0) * GYRO_PER_COUNT, _i16(d, 2) * GYRO_PER_COUNT, _i16(d, 4) * GYRO_PER_COUNT)),)
        elif t == 0x53:
            r, p, y = (_i16(d, k) * ANGLE_PER_COUNT for k in (0, 2, 4))
            val = ((r, -p, -y),)
        elif t == 0x54:
            val = (_frd((_i16(d, 0) * self.mag_scale, _i16(d, 2) * self.mag_scale, _i16(d, 4) * self.mag_scale)),)
        elif t == 0x50:
            ms = d[6] | (d[7] << 8)
            val = (d[3] * 3600.0 + d[4] * 60.0 + d[5] + ms / 1000.0,)
        else:
            self.stats.other += 1
            return
        cyc = self._cycle
        if cyc and t <= self._last_type:  # types come in ascending order: a new cycle began
            self._emit(end, rows)
        cyc[t] = val
        self._last_type = t
        if self._types is not None and self._types.issubset(cyc):
            self._emit(end, rows)

    def _emit(self, end: int, rows: SampleRows) -> None:
        cyc = self._cycle
        self._closed += 1
        if self._types is None and self._closed == 2 and 0x51 in cyc and 0x52 in cyc:
            self._types = frozenset(cyc)  # (the first cycle may have begun before the first read)
        if 0x51 in cyc and 0x52 in cyc:
            acc, temp = cyc[0x51]
            mag = cyc[0x54][0] if 0x54 in cyc else None
            att = cyc[0x53][0] if 0x53 in cyc else None
            t_dev = cyc[0x50][0] if 0x50 in cyc else None
            rows.add(end, cyc[0x52][0], acc, mag, att, temp, t_dev)
        else:
            self.stats.incomplete += 1
        cyc.clear()


def _frd(v: Sequence[float]) -> tuple[float, float, float]:
    return (v[0] * _FLU_TO_FRD[0], v[1] * _FLU_TO_FRD[1], v[2] * _FLU_TO_FRD[2])


def packet(ptype: int, values: Sequence[int]) -> bytes:
    """One 11-byte packet of type ``ptype`` with four int16 ``values`` (the checksum added)."""
    body = bytearray([HEADER, ptype])
    for v in values:
        v = int(max(-32768, min(32767, round(v))))
        body += (v & 0xFFFF).to_bytes(2, "little")
    return bytes(body) + bytes([sum(body) & 0xFF])


def encode_witmotion(
    accel: Sequence[float],
    gyro: Sequence[float],
    mag_ut: Sequence[float] | None = None,
    roll_pitch_yaw_deg: Sequence[float] | None = None,
    temp_c: float = 25.0,
    mag_ut_per_count: float = 0.1,
) -> bytes:
    """One output cycle (0x51, 0x52, then 0x53 and 0x54 when given) from imutool-convention values (m/s²
    specific force FRD, rad/s FRD, µT FRD, roll/pitch/yaw deg imutool signs), converted to the module's FLU."""
    a = _frd(accel)  # the map is its own inverse
    g = _frd(gyro)
    tc = temp_c * 100.0
    out = packet(0x51, [a[0] / ACCEL_PER_COUNT, a[1] / ACCEL_PER_COUNT, a[2] / ACCEL_PER_COUNT, tc])
    out += packet(0x52, [g[0] / GYRO_PER_COUNT, g[1] / GYRO_PER_COUNT, g[2] / GYRO_PER_COUNT, tc])
    if roll_pitch_yaw_deg is not None:
        r, p, y = roll_pitch_yaw_deg
        y = (-y + 180.0) % 360.0 - 180.0
        out += packet(0x53, [r / ANGLE_PER_COUNT, -p / ANGLE_PER_COUNT, y / ANGLE_PER_COUNT, 0])
    if mag_ut is not None:
        m = _frd(mag_ut)
        out += packet(0x54, [m[0] / mag_ut_per_count, m[1] / mag_ut_per_count, m[2] / mag_ut_per_count, tc])
    return out
