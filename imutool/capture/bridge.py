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

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.errors import ImutoolError
from formats.jit.decorators import njit
from formats.nmea import checksum_value
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
        return {
            "imu": self.imu,
            "accel_fs_g": self.accel_fs_g,
            "gyro_fs_dps": self.gyro_fs_dps,
            "mag": self.mag,
            "mag_gain": self.mag_gain,
            "accel_m_s2_per_lsb": self.accel,
            "gyro_rad_s_per_lsb": self.gyro,
            "mag_uT_per_lsb": self.mag_ut,
        }


def xor_checksum(body: bytes) -> int:
    """XOR of all bytes (the NMEA 0183 checksum, :func:`formats.nmea.checksum_value`)."""
    return checksum_value(body)


def _crc_table() -> list[int]:
    table = []
    for i in range(256):
        c = i << 8
        for _ in range(8):
            c = ((c << 1) ^ 0x1021) & 0xFFFF if c & 0x8000 else (c << 1) & 0xFFFF
        table.append(c)
    return table


_CRC_TABLE = _crc_table()
_CRC_ARRAY = np.array(_CRC_TABLE, dtype=np.int64)


def crc16_ccitt(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor); table-driven."""
    t = _CRC_TABLE
    for b in data:
        crc = ((crc << 8) & 0xFFFF) ^ t[(crc >> 8) ^ b]
    return crc


# -- compiled scanners (the per-frame loops): one call per received chunk ------------------------------------
@njit(cache=True)
def _parse_text_line(buf: np.ndarray, s: int, e: int, row: np.ndarray) -> int:
    """1 if buf[s:e] is exactly ``$IMB,<12 ints>*HH`` with a good checksum (values in row), else 0."""
    if e - s < 9 or buf[s] != 36 or buf[s + 1] != 73 or buf[s + 2] != 77 or buf[s + 3] != 66 or buf[s + 4] != 44:
        return 0
    star = e - 3
    if buf[star] != 42:
        return 0
    x = 0
    for i in range(s + 1, star):
        x ^= buf[i]
    cs = 0
    for i in range(star + 1, e):
        c = buf[i]
        if 48 <= c <= 57:
            d = c - 48
        elif 65 <= c <= 70:
            d = c - 55
        elif 97 <= c <= 102:
            d = c - 87
        else:
            return 0
        cs = cs * 16 + d
    if cs != x:
        return 0
    p = s + 5
    for k in range(12):
        neg = False
        if p < star and buf[p] == 45:
            neg = True
            p += 1
        start = p
        v = 0
        while p < star and 48 <= buf[p] <= 57:
            v = v * 10 + (buf[p] - 48)
            p += 1
        if p == start or p - start > 10:
            return 0
        row[k] = -v if neg else v
        if k < 11:
            if p >= star or buf[p] != 44:
                return 0
            p += 1
    return 1 if p == star else 0


@njit(cache=True)
def _scan_text(buf: np.ndarray, vals: np.ndarray, status: np.ndarray, bounds: np.ndarray) -> int:
    """Split buf (ending in a newline) into lines; status 1 = good frame (vals), 0 = empty, 2 = other."""
    n = buf.size
    k = 0
    i = 0
    while i < n:
        j = i
        while j < n and buf[j] != 10:
            j += 1
        s, e = i, j
        while e > s and (buf[e - 1] == 13 or buf[e - 1] == 32):
            e -= 1
        while s < e and buf[s] == 32:
            s += 1
        bounds[k, 0] = s
        bounds[k, 1] = e
        if e == s:
            status[k] = 0
        else:
            status[k] = 1 if _parse_text_line(buf, s, e, vals[k]) else 2
        k += 1
        i = j + 1
    return k


@njit(cache=True)
def _crc16(buf: np.ndarray, s: int, n: int, table: np.ndarray) -> int:
    crc = 0xFFFF
    for i in range(s, s + n):
        crc = ((crc << 8) & 0xFFFF) ^ table[(crc >> 8) ^ buf[i]]
    return crc


@njit(cache=True)
def _scan_binary(buf: np.ndarray, vals: np.ndarray, table: np.ndarray, counts: np.ndarray) -> tuple[int, int]:
    """Frames in buf: (frames found, bytes consumed). vals rows: seq, t_us, 10 samples.
    counts: [garbage bytes, bad CRC]."""
    n = buf.size
    pos = 0
    k = 0
    while True:
        i = pos
        while i + 1 < n and not (buf[i] == 0xA5 and buf[i + 1] == 0x5A):
            i += 1
        if i + 1 >= n:  # no sync word: keep a trailing 0xA5 that may start one
            keep = 1 if n > 0 and buf[n - 1] == 0xA5 else 0
            counts[0] += max(0, n - pos - keep)
            return k, max(pos, n - keep)
        counts[0] += i - pos
        if n - i < 31:
            return k, i
        if buf[i + 2] != 26 or _crc16(buf, i + 2, 27, table) != (buf[i + 29] | (buf[i + 30] << 8)):
            counts[1] += 1
            pos = i + 1
            continue
        vals[k, 0] = buf[i + 3] | (buf[i + 4] << 8)
        vals[k, 1] = buf[i + 5] | (buf[i + 6] << 8) | (buf[i + 7] << 16) | (np.int64(buf[i + 8]) << 24)
        for j in range(10):
            v = buf[i + 9 + 2 * j] | (buf[i + 10 + 2 * j] << 8)
            vals[k, 2 + j] = v - 65536 if v >= 32768 else v
        k += 1
        pos = i + 31


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
        return {
            "frames": self.frames,
            "bad_checksum": self.bad_checksum,
            "malformed": self.malformed,
            "garbage_bytes": self.garbage_bytes,
            "repeated": self.repeated,
            "dropped_by_sequence": self.dropped,
            "sequence_gaps": len(self.gaps),
            "config_lines": self.configs,
        }


class BridgeDecoder:
    """Incremental decoder for both variants; feed bytes, get frames. Corruption is counted, never fatal."""

    def __init__(self, binary: bool = False, scales: Scales | None = None):
        self.binary = binary
        self.scales = scales or Scales()
        self.stats = DecoderStats()
        self._buf = bytearray()
        self._last_seq: int | None = None

    @property
    def last_seq(self) -> int | None:
        return self._last_seq

    def resume_after(self, seq: int) -> None:
        """Continue sequence tracking after a restart (the last frame already on disk had ``seq``)."""
        self._last_seq = seq & 0xFFFF

    def feed(self, data: bytes) -> list[Frame]:
        """Decode what has arrived; returns complete, valid, non-repeated frames in order."""
        seq, t_us, counts = self.feed_arrays(data)
        return [Frame(int(a), int(b), tuple(int(x) for x in c)) for a, b, c in zip(seq, t_us, counts, strict=True)]

    def feed_arrays(self, data: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As :meth:`feed`, as arrays: seq (n,), t_us (n,), counts (n, 10) — the capture's fast path."""
        self._buf.extend(data)
        vals = self._scan_binary() if self.binary else self._scan_text()
        if len(vals) == 0:
            return vals[:, 0], vals[:, 1], vals[:, 2:]
        keep = self._track_block(vals[:, 0] & 0xFFFF)
        vals = vals[keep]
        self.stats.frames += len(vals)
        return vals[:, 0], vals[:, 1], vals[:, 2:]

    def _track_block(self, seq: np.ndarray) -> np.ndarray:
        """Vectorised sequence bookkeeping; returns the mask of frames to keep (repeats dropped)."""
        prev = np.empty_like(seq)
        prev[1:] = seq[:-1]
        prev[0] = seq[0] - 1 if self._last_seq is None else self._last_seq
        step = (seq - prev) & 0xFFFF
        keep = step != 0
        self.stats.repeated += int((~keep).sum())
        for i in np.flatnonzero(step > 1):
            self.stats.dropped += int(step[i] - 1)
            self.stats.gaps.append((int(prev[i]), int(step[i] - 1)))
        self._last_seq = int(seq[-1])
        return keep

    def _scan_text(self) -> np.ndarray:
        buf = self._buf
        cut = buf.rfind(b"\n")
        if cut < 0:
            if len(buf) > 4096:  # no line end in a long run: garbage
                self.stats.garbage_bytes += len(buf)
                buf.clear()
            return np.empty((0, 12), np.int64)
        arr = np.frombuffer(bytes(buf[: cut + 1]), dtype=np.uint8)
        del buf[: cut + 1]
        nl = int(np.count_nonzero(arr == 10))
        vals = np.empty((nl, 12), np.int64)
        status = np.empty(nl, np.int64)
        bounds = np.empty((nl, 2), np.int64)
        k = _scan_text(arr, vals, status, bounds)
        other = np.flatnonzero(status[:k] == 2)
        if len(other) == 0:
            return vals[:k][status[:k] == 1]
        rows = []  # rare lines (config, damaged, garbage before '$'): the exact Python path, in order
        for i in range(k):
            if status[i] == 1:
                rows.append(vals[i])
            elif status[i] == 2:
                f = self._decode_line_raw(arr[bounds[i, 0] : bounds[i, 1]].tobytes())
                if f is not None:
                    rows.append(np.array([f.seq, f.t_us, *f.counts], dtype=np.int64))
        return np.array(rows, dtype=np.int64).reshape(-1, 12)

    def _scan_binary(self) -> np.ndarray:
        arr = np.frombuffer(bytes(self._buf), dtype=np.uint8)
        vals = np.empty((arr.size // BIN_FRAME_LEN + 1, 12), np.int64)
        counts = np.zeros(2, np.int64)
        k, consumed = _scan_binary(arr, vals, _CRC_ARRAY, counts)
        del self._buf[:consumed]
        self.stats.garbage_bytes += int(counts[0])
        self.stats.bad_checksum += int(counts[1])
        return vals[:k]

    def _decode_line_raw(self, line: bytes) -> Frame | None:
        """Parse one line (no sequence bookkeeping); counts what is wrong with it."""
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
            cs = int(line[star + 1 : star + 3], 16)
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
        return Frame(vals[0], vals[1], tuple(vals[2:]))


def frames_to_si(frames: list[Frame], scales: Scales) -> dict[str, np.ndarray]:
    """Channels in SI from frames: seq, t_mcu (s), accel (m/s²), gyro (rad/s), mag (µT), temp (°C)."""
    if not frames:
        return {}
    return counts_to_si(
        np.array([f.seq for f in frames]),
        np.array([f.t_us for f in frames]),
        np.array([f.counts for f in frames]),
        scales,
    )


def counts_to_si(seq: np.ndarray, t_us: np.ndarray, counts: np.ndarray, scales: Scales) -> dict[str, np.ndarray]:
    """As :func:`frames_to_si` for the arrays of :meth:`BridgeDecoder.feed_arrays`."""
    c = np.asarray(counts, dtype=float)
    return {
        "seq": np.asarray(seq, dtype=float),
        "t_mcu": np.asarray(t_us, dtype=np.int64) / 1e6,
        "accel": c[:, 0:3] * scales.accel,
        "gyro": c[:, 3:6] * scales.gyro,
        "mag": c[:, 6:9] * scales.mag_ut,
        "temp": c[:, 9] / 340.0 + 36.53,
    }
