"""The imutool serial bridge protocol: a microcontroller streams raw sensor counts to the host.

Two variants carry the same frame (documented in docs/bridge_protocol.md, firmware sketch in docs/):

Text (one line per frame, NMEA-style XOR checksum, at most 100 characters)::

    $IMB,<seq>,<t_us>,<ax>,<ay>,<az>,<gx>,<gy>,<gz>,<mx>,<my>,<mz>,<temp>*HH\\r\\n

Binary (little-endian, 31 bytes)::

    0xA5 0x5A | len=26 (u8) | seq (u16) | t_us (u32) | ax ay az gx gy gz mx my mz temp (10 × i16)
    | CRC-16/CCITT-FALSE (u16)

The CRC covers the bytes from ``len`` to the last sample. ``seq`` counts frames modulo 65536; a jump in
``seq`` is a dropped-frame gap (counted, never silent). ``t_us`` is the MCU's microsecond clock (mod 2³²).
A configuration line ``$IMBCFG,<imu>,<accel_fs_g>,<gyro_fs_dps>,<mag>,<mag_gain>*HH`` (sent by the sketch at
start-up) or host options give the scale factors that turn counts into SI units.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

from formats.errors import ImutoolError
from formats.units import STANDARD_GRAVITY

# MPU6050 datasheet (RM-MPU-6000A §4.17/4.19): sensitivity per full-scale range.
MPU6050_ACCEL_LSB_PER_G = {2: 16384.0, 4: 8192.0, 8: 4096.0, 16: 2048.0}
MPU6050_GYRO_LSB_PER_DPS = {250: 131.0, 500: 65.5, 1000: 32.8, 2000: 16.4}
# HMC5883L datasheet Table 9: gain setting (CRB bits GN2..GN0) -> LSB/gauss.
HMC5883L_LSB_PER_GAUSS = {0: 1370.0, 1: 1090.0, 2: 820.0, 3: 660.0, 4: 440.0, 5: 390.0, 6: 330.0, 7: 230.0}
# QMC5883L datasheet: RNG = 2 G -> 12000 LSB/G, 8 G -> 3000 LSB/G.
QMC5883L_LSB_PER_GAUSS = {2: 12000.0, 8: 3000.0}
GAUSS_TO_UT = 100.0

SYNC = b"\xa5\x5a"
_BIN_BODY = struct.Struct("<BHI10h")  # len, seq, t_us, 10 samples
BIN_FRAME_LEN = 2 + _BIN_BODY.size + 2
TEXT_TAG = "IMB"
CFG_TAG = "IMBCFG"


@dataclass
class Scales:
    """Counts → SI: accel m/s² per LSB, gyro rad/s per LSB, mag µT per LSB; temp = raw/340 + 36.53 °C."""

    imu: str = "mpu6050"
    accel_fs_g: int = 2
    gyro_fs_dps: int = 250
    mag: str = "hmc5883l"
    mag_gain: int = 1  # HMC5883L gain code 0..7, or QMC5883L range in gauss (2 or 8)

    def __post_init__(self) -> None:
        if self.accel_fs_g not in MPU6050_ACCEL_LSB_PER_G:
            raise ImutoolError(f"MPU6050 accel range ±{self.accel_fs_g} g not one of 2, 4, 8, 16")
        if self.gyro_fs_dps not in MPU6050_GYRO_LSB_PER_DPS:
            raise ImutoolError(f"MPU6050 gyro range ±{self.gyro_fs_dps} °/s not one of 250, 500, 1000, 2000")
        table = HMC5883L_LSB_PER_GAUSS if self.mag == "hmc5883l" else QMC5883L_LSB_PER_GAUSS
        if self.mag not in ("hmc5883l", "qmc5883l"):
            raise ImutoolError(f"magnetometer {self.mag!r} not one of hmc5883l, qmc5883l")
        if self.mag_gain not in table:
            raise ImutoolError(f"{self.mag} gain/range {self.mag_gain} not one of {sorted(table)}")

    @property
    def accel(self) -> float:
        return STANDARD_GRAVITY / MPU6050_ACCEL_LSB_PER_G[self.accel_fs_g]

    @property
    def gyro(self) -> float:
        return np.pi / 180.0 / MPU6050_GYRO_LSB_PER_DPS[self.gyro_fs_dps]

    @property
    def mag_ut(self) -> float:
        table = HMC5883L_LSB_PER_GAUSS if self.mag == "hmc5883l" else QMC5883L_LSB_PER_GAUSS
        return GAUSS_TO_UT / table[self.mag_gain]

    def as_meta(self) -> dict:
        return {"imu": self.imu, "accel_fs_g": self.accel_fs_g, "gyro_fs_dps": self.gyro_fs_dps, "mag": self.mag,
                "mag_gain": self.mag_gain, "accel_m_s2_per_lsb": self.accel, "gyro_rad_s_per_lsb": self.gyro,
                "mag_uT_per_lsb": self.mag_ut}


def xor_checksum(body: bytes) -> int:
    """XOR of all bytes (the NMEA 0183 checksum), by folding the bytes as one big integer."""
    n = len(body)
    if n == 0:
        return 0
    x = int.from_bytes(body, "big")
    width = n
    while width > 1:
        half = (width + 1) // 2
        x = (x >> (8 * half)) ^ (x & ((1 << (8 * half)) - 1))
        width = half
    return x


def _crc_table() -> list[int]:
    table = []
    for i in range(256):
        c = i << 8
        for _ in range(8):
            c = ((c << 1) ^ 0x1021) & 0xFFFF if c & 0x8000 else (c << 1) & 0xFFFF
        table.append(c)
    return table


_CRC_TABLE = _crc_table()


def crc16_ccitt(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor); table-driven."""
    t = _CRC_TABLE
    for b in data:
        crc = ((crc << 8) & 0xFFFF) ^ t[(crc >> 8) ^ b]
    return crc


@dataclass
class Frame:
    seq: int
    t_us: int
    counts: tuple[int, ...]  # ax ay az gx gy gz mx my mz temp


def encode_text(frame: Frame) -> bytes:
    body = f"{TEXT_TAG},{frame.seq},{frame.t_us}," + ",".join(str(int(c)) for c in frame.counts)
    return f"${body}*{xor_checksum(body.encode()):02X}\r\n".encode()


def encode_config(scales: Scales) -> bytes:
    body = f"{CFG_TAG},{scales.imu},{scales.accel_fs_g},{scales.gyro_fs_dps},{scales.mag},{scales.mag_gain}"
    return f"${body}*{xor_checksum(body.encode()):02X}\r\n".encode()


def encode_binary(frame: Frame) -> bytes:
    body = _BIN_BODY.pack(_BIN_BODY.size - 1, frame.seq & 0xFFFF, frame.t_us & 0xFFFFFFFF, *frame.counts)
    return SYNC + body + struct.pack("<H", crc16_ccitt(body))


@dataclass
class DecoderStats:
    frames: int = 0
    bad_checksum: int = 0
    malformed: int = 0
    garbage_bytes: int = 0
    repeated: int = 0  # a frame whose sequence number equals the previous one (dropped as a duplicate)
    dropped: int = 0  # frames missing according to the sequence numbers
    gaps: list[tuple[int, int]] = field(default_factory=list)  # (last seq seen, frames missing)
    configs: int = 0

    def as_dict(self) -> dict:
        return {"frames": self.frames, "bad_checksum": self.bad_checksum, "malformed": self.malformed,
                "garbage_bytes": self.garbage_bytes, "repeated": self.repeated, "dropped_by_sequence": self.dropped,
                "sequence_gaps": len(self.gaps), "config_lines": self.configs}


class BridgeDecoder:
    """Incremental decoder for both variants; feed bytes, get frames. Corruption is counted, never fatal."""

    def __init__(self, binary: bool = False, scales: Scales | None = None):
        self.binary = binary
        self.scales = scales or Scales()
        self.stats = DecoderStats()
        self._buf = bytearray()
        self._last_seq: int | None = None

    def _track(self, seq: int) -> bool:
        """Update sequence bookkeeping; False for a repeated frame (to be dropped)."""
        if self._last_seq is not None:
            step = (seq - self._last_seq) & 0xFFFF
            if step == 0:
                self.stats.repeated += 1
                return False
            if step > 1:
                self.stats.dropped += step - 1
                self.stats.gaps.append((self._last_seq, step - 1))
        self._last_seq = seq
        return True

    @property
    def last_seq(self) -> int | None:
        return self._last_seq

    def resume_after(self, seq: int) -> None:
        """Continue sequence tracking after a restart (the last frame already on disk had ``seq``)."""
        self._last_seq = seq & 0xFFFF

    def feed(self, data: bytes) -> list[Frame]:
        self._buf.extend(data)
        return self._decode_binary() if self.binary else self._decode_text()

    def _decode_text(self) -> list[Frame]:
        buf = self._buf
        cut = buf.rfind(b"\n")
        if cut < 0:
            if len(buf) > 4096:  # no line end in a long run: garbage
                self.stats.garbage_bytes += len(buf)
                buf.clear()
            return []
        lines = bytes(buf[:cut]).split(b"\n")
        del buf[: cut + 1]
        out = []
        for line in lines:
            f = self.decode_line(line.strip())
            if f is not None:
                out.append(f)
        return out

    def decode_line(self, line: bytes) -> Frame | None:
        if not line:
            return None
        start = line.rfind(b"$")
        if start < 0:
            self.stats.garbage_bytes += len(line)
            return None
        if start > 0:
            self.stats.garbage_bytes += start
            line = line[start:]
        star = line.rfind(b"*")
        if star < 0 or len(line) - star < 3:
            self.stats.malformed += 1
            return None
        body = line[1:star]
        try:
            cs = int(line[star + 1:star + 3], 16)
        except ValueError:
            self.stats.malformed += 1
            return None
        if xor_checksum(body) != cs:
            self.stats.bad_checksum += 1
            return None
        parts = body.decode("ascii", errors="replace").split(",")
        if parts[0] == CFG_TAG and len(parts) == 6:
            try:
                self.scales = Scales(parts[1], int(parts[2]), int(parts[3]), parts[4], int(parts[5]))
                self.stats.configs += 1
            except (ValueError, ImutoolError):
                self.stats.malformed += 1
            return None
        if parts[0] != TEXT_TAG or len(parts) != 13:
            self.stats.malformed += 1
            return None
        try:
            vals = [int(p) for p in parts[1:]]
        except ValueError:
            self.stats.malformed += 1
            return None
        if not self._track(vals[0] & 0xFFFF):
            return None
        self.stats.frames += 1
        return Frame(vals[0], vals[1], tuple(vals[2:]))

    def _decode_binary(self) -> list[Frame]:
        out = []
        buf = self._buf
        pos = 0
        n = len(buf)
        body_len = _BIN_BODY.size
        while True:
            i = buf.find(SYNC, pos)
            if i < 0:
                keep = 1 if buf[-1:] == SYNC[:1] else 0
                self.stats.garbage_bytes += n - pos - keep
                pos = n - keep
                break
            if i > pos:
                self.stats.garbage_bytes += i - pos
            if n - i < BIN_FRAME_LEN:
                pos = i
                break
            body = bytes(buf[i + 2: i + 2 + body_len])
            (crc,) = struct.unpack_from("<H", buf, i + 2 + body_len)
            if body[0] != body_len - 1 or crc16_ccitt(body) != crc:
                self.stats.bad_checksum += 1
                pos = i + 1  # resynchronise on the next sync word
                continue
            vals = _BIN_BODY.unpack(body)
            pos = i + BIN_FRAME_LEN
            if self._track(vals[1]):
                self.stats.frames += 1
                out.append(Frame(vals[1], vals[2], vals[3:]))
        del buf[:pos]
        return out


def frames_to_si(frames: list[Frame], scales: Scales) -> dict[str, np.ndarray]:
    """Channels in SI from frames: seq, t_mcu (s, unwrapped), accel (m/s²), gyro (rad/s), mag (µT), temp (°C)."""
    if not frames:
        return {}
    c = np.array([f.counts for f in frames], dtype=float)
    t_us = np.array([f.t_us for f in frames], dtype=np.int64)
    return {
        "seq": np.array([f.seq for f in frames], dtype=float),
        "t_mcu": t_us / 1e6,
        "accel": c[:, 0:3] * scales.accel,
        "gyro": c[:, 3:6] * scales.gyro,
        "mag": c[:, 6:9] * scales.mag_ut,
        "temp": c[:, 9] / 340.0 + 36.53,
    }
