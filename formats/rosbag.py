"""ROS bags (ROS1 ``.bag``, ROS2 sqlite3 ``.db3`` and MCAP) ↔ Recording, with REP-103 → FRD/NED at the boundary.

Read: ``sensor_msgs/Imu``, ``sensor_msgs/MagneticField`` and (legacy magnetometer) ``geometry_msgs/Vector3Stamped``.
Write: ``sensor_msgs/Imu`` (+ ``sensor_msgs/MagneticField`` when the recording has ``mag``).

Frames and units (DESIGN.md; REP-103/REP-145):

* ROS body axes are FLU (x forward, y left, z up), world ENU. imutool is FRD / NED. Body vectors
  (angular_velocity, linear_acceleration, magnetic_field) map FLU → FRD as (x, -y, -z).
* ``Imu.orientation`` q_ros rotates FLU body vectors into ENU: R_ros. imutool's ``q`` (body FRD → NED) is
  R = T_ne · R_ros · T_fb with T_ne = ENU→NED and T_fb = FRD→FLU (both their own inverse), i.e.
  q = q_ne ⊗ q_ros ⊗ q_fb.
* Covariances (3×3, row major) rotate as C_frd = R C_flu Rᵀ with R = diag(1, -1, -1) (off-diagonals xy, xz
  change sign). The orientation covariance is read as roll/pitch/yaw variances about the body axes
  (the robot_localization convention), so the same R applies.
* ``MagneticField`` is in tesla; imutool uses µT. ``Vector3Stamped`` has no unit: ``vector3_mag_unit`` (default T).
* ``covariance[0] == -1`` means "this quantity is not provided" (ROS convention): the channel is NaN for those
  messages. An all-zero covariance means "unknown" and gives no covariance channel.

Covariance channels: a diagonal covariance becomes a one-sigma channel in the canonical unit — ``gyro_std``
(rad/s), ``accel_std`` (m/s²), ``mag_std`` (µT) as (N, 3), and ``roll_std``, ``pitch_std``, ``heading_std``
(deg) for the orientation. If any off-diagonal term is non-zero on a topic, the full matrix is kept instead as
``gyro_cov`` / ``accel_cov`` / ``mag_cov`` / ``q_cov`` (N, 9), row major, columns ``*_cov_xx .. *_cov_zz``, in
SI² units ((rad/s)², (m/s²)², µT², rad²), already rotated to FRD.

Time: ``stamp="header"`` (the message header stamp, default) or ``"record"`` (the bag's record/receive time).
Stamps are integer nanoseconds; ``time`` is float64 seconds ``sec + nsec·1e-9`` (at Unix-epoch magnitudes a
float64 resolves ≈ 0.24 µs; within 1 ns for times below ~4e6 s).

Speed: raw message bytes are decoded with numpy on the fixed layout (ROS1 serialisation or little-endian CDR);
the ROS1 chunks are scanned by a small numba kernel and ROS2 sqlite3 rows are fetched with one query. Anything
unusual (big-endian CDR, unexpected lengths, non-standard definitions) falls back to ``rosbags`` deserialisation.
"""

from __future__ import annotations

import mmap
import os
import shutil
import sqlite3
import struct
import tempfile
from dataclasses import dataclass, field
from operator import itemgetter
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit

from . import kernel_cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from .atomic import atomic_path
from .errors import ImutoolError
from .frames import Q_ENU_TO_NED, Q_FLU_TO_FRD, euler_to_quat, quat_conjugate, quat_multiply
from .recording import Recording, merge

IMU = "sensor_msgs/msg/Imu"
MAG = "sensor_msgs/msg/MagneticField"
VEC3 = "geometry_msgs/msg/Vector3Stamped"
_KIND = {IMU: "imu", MAG: "mag", VEC3: "vec3"}
_NFLOAT = {"imu": 37, "mag": 12, "vec3": 3}
# sign pattern of R C Rᵀ for R = diag(1, -1, -1), row-major 3×3
_COV_SIGN = np.outer([1.0, -1.0, -1.0], [1.0, -1.0, -1.0]).ravel()
_FLIP = np.array([1.0, -1.0, -1.0])
_AXES = [a + b for a in "xyz" for b in "xyz"]
_COV_UNITS = {"gyro": "rad^2/s^2", "accel": "m^2/s^4", "mag": "uT^2", "q": "rad^2"}
_STD_NAMES = ("roll_std", "pitch_std", "heading_std")


def _norm_type(t: str) -> str:
    """'sensor_msgs/Imu' (ROS1) → 'sensor_msgs/msg/Imu'."""
    parts = t.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return t


# ---------------------------------------------------------------------------------------------------------------
# raw message access
# ---------------------------------------------------------------------------------------------------------------
@dataclass
class _Topic:
    name: str
    msgtype: str
    count: int
    fmt: str  # 'ros1' or 'cdr'
    ids: list[Any] = field(default_factory=list)
    md5: str = ""


@dataclass
class _Raw:
    """Concatenated raw payloads of one topic: message i is buf[offs[i]: offs[i] + lens[i]]."""

    buf: np.ndarray
    offs: np.ndarray
    lens: np.ndarray
    rec_ns: np.ndarray
    fmt: str


@njit(cache=True)
def _u32(b, p):  # pragma: no cover - numba
    return np.int64(b[p]) | (np.int64(b[p + 1]) << 8) | (np.int64(b[p + 2]) << 16) | (np.int64(b[p + 3]) << 24)


@njit(cache=True)
def _scan_ros1(buf, bounds, out, conn_pos, bad_chunks, fill):  # pragma: no cover - numba
    """Scan ROS1 records (uint32 header_len, header fields 'name=value', uint32 data_len, data) in ``buf``.

    Message-data records (op 0x02) go to ``out`` rows (conn, sec, nsec, data offset, data length);
    connection records (op 0x07) to ``conn_pos``. ``bounds`` holds each decompressed chunk's (start, end) in
    ``buf``; a chunk whose records do not parse to its end is flagged in ``bad_chunks`` (its readable records are
    kept) and the scan goes on with the next chunk. Returns (n_messages, n_connections). fill=False only counts.
    """
    k = 0
    c = 0
    for ci in range(bounds.shape[0]):
        k, c = _scan_chunk(buf, bounds[ci, 0], bounds[ci, 1], out, conn_pos, bad_chunks, ci, k, c, fill)
    return k, c


@njit(cache=True)
def _scan_chunk(buf, p, n, out, conn_pos, bad_chunks, ci, k, c, fill):  # pragma: no cover - numba
    while p + 4 <= n:
        hl = _u32(buf, p)
        h0 = p + 4
        h1 = h0 + hl
        if h1 + 4 > n:
            break
        op = -1
        conn = -1
        sec = 0
        nsec = 0
        q = h0
        bad = False
        while q + 4 <= h1:
            fl = _u32(buf, q)
            f0 = q + 4
            f1 = f0 + fl
            if f1 > h1:
                bad = True
                break
            e = f0
            while e < f1 and buf[e] != 61:
                e += 1
            nl = e - f0
            vl = f1 - e - 1
            if nl == 2 and buf[f0] == 111 and buf[f0 + 1] == 112 and vl == 1:
                op = buf[e + 1]
            elif nl == 4 and vl == 4 and buf[f0] == 99 and buf[f0 + 1] == 111 and buf[f0 + 2] == 110:
                conn = _u32(buf, e + 1)
            elif nl == 4 and vl == 8 and buf[f0] == 116 and buf[f0 + 1] == 105 and buf[f0 + 2] == 109:
                sec = _u32(buf, e + 1)
                nsec = _u32(buf, e + 5)
            q = f1
        if bad:
            break
        dl = _u32(buf, h1)
        d0 = h1 + 4
        if d0 + dl > n:
            break
        if op == 2:
            if fill:
                out[k, 0] = conn
                out[k, 1] = sec
                out[k, 2] = nsec
                out[k, 3] = d0
                out[k, 4] = dl
            k += 1
        elif op == 7:
            if fill:
                conn_pos[c] = p
            c += 1
        p = d0 + dl
    if p != n:
        bad_chunks[ci] = 1
    return k, c


@njit(cache=True)
def _gather(buf, starts, width):  # pragma: no cover - numba
    """Copy ``width`` bytes from each start into one contiguous (n*width,) uint8 array."""
    n = starts.shape[0]
    out = np.empty(n * width, np.uint8)
    for i in range(n):
        s = starts[i]
        o = i * width
        for j in range(width):
            out[o + j] = buf[s + j]
    return out


def _take(buf: np.ndarray, starts: np.ndarray, dtype: str, ncols: int) -> np.ndarray:
    """(n, ncols) values of ``dtype`` read at each byte offset in ``starts`` (contiguous copy).

    Runs of equally spaced starts (the usual case: equal-length messages back to back) are copied through
    strided numpy views; heavily irregular spacing uses the numba byte gather.
    """
    n = starts.shape[0]
    item = np.dtype(dtype).itemsize
    if n == 0:
        return np.empty((0, ncols), dtype)
    if n > 2:
        d = np.diff(starts)
        cp = np.flatnonzero(d[1:] != d[:-1]) + 1
        if cp.size < max(8, n // 256) and np.all(d > 0):
            out = np.empty((n, ncols), dtype)
            bounds = np.concatenate([[0], cp, [n - 1]])
            for p, q in zip(bounds[:-1], bounds[1:], strict=True):
                view = np.ndarray(
                    (q - p + 1, ncols), dtype, buffer=buf, offset=int(starts[p]), strides=(int(d[p]), item)
                )
                out[p : q + 1] = view
            return out
    return _gather(buf, starts, item * ncols).view(dtype).reshape(n, ncols)


def _fields(block: bytes | memoryview) -> dict[str, bytes]:
    """Parse a ROS1 header block: repeated (uint32 len, b'name=value')."""
    out: dict[str, bytes] = {}
    p = 0
    n = len(block)
    while p + 4 <= n:
        (fl,) = struct.unpack_from("<I", block, p)
        f = bytes(block[p + 4 : p + 4 + fl])
        name, _, value = f.partition(b"=")
        out[name.decode("ascii", "replace")] = value
        p += 4 + fl
    return out


class _Ros1Bag:
    """Sequential ROS1 v2.0 reader (all chunks decompressed and scanned; tolerant of a truncated file)."""

    def __init__(self, path: str):
        self.path = path
        self.truncated = False
        self.notes: list[str] = []
        self.conns: dict[int, dict[str, Any]] = {}
        self.buf = np.empty(0, np.uint8)
        self.recs = np.empty((0, 5), np.int64)
        self._read()

    def _read(self) -> None:
        from rosbags.rosbag1.reader import decompressors

        size = os.path.getsize(self.path)
        with open(self.path, "rb") as f:
            magic = f.readline()
            if not magic.startswith(b"#ROSBAG V2.0"):
                raise ImutoolError("not a ROS1 bag (v2.0 magic line missing)", path=self.path)
            start = len(magic)
            if size <= start:
                raise ImutoolError("empty ROS1 bag", path=self.path)
            mm = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        try:
            mv = memoryview(mm)
            chunks: list[bytes] = []
            p = start
            index_pos = None
            lost = 0
            while p + 4 <= size:
                (hl,) = struct.unpack_from("<I", mv, p)
                if p + 8 + hl > size:
                    self.truncated = True
                    break
                try:
                    hdr = _fields(mv[p + 4 : p + 4 + hl])
                except (struct.error, ValueError):
                    hdr = {}
                (dl,) = struct.unpack_from("<I", mv, p + 4 + hl)
                d0 = p + 8 + hl
                if d0 + dl > size:
                    self.truncated = True
                    if hdr.get("op") == b"\x05":
                        lost = size - p
                    break
                op = hdr.get("op", b"")
                if op == b"\x03":
                    ip = hdr.get("index_pos", b"")
                    index_pos = struct.unpack("<Q", ip)[0] if len(ip) == 8 else 0
                elif op == b"\x05":
                    comp = hdr.get("compression", b"none").decode()
                    if comp not in decompressors:
                        raise ImutoolError(f"unsupported chunk compression {comp!r}", path=self.path)
                    try:
                        chunks.append(decompressors[comp](bytes(mv[d0 : d0 + dl])))
                    except Exception as exc:  # corrupt chunk: count and go on
                        self.notes.append(f"chunk at byte {p} could not be decompressed ({exc}); skipped")
                elif op == b"\x07":
                    self._add_conn(hdr, mv[d0 : d0 + dl])
                p = d0 + dl
            del mv
        finally:
            mm.close()
        if index_pos == 0 or (index_pos is not None and index_pos > size):
            self.truncated = True
        if self.truncated:
            msg = "bag is truncated or was not closed (no complete index)"
            if lost:
                msg += f"; the last incomplete chunk ({lost} bytes) was dropped"
            self.notes.append(msg)
        if not chunks:
            if self.truncated:
                raise ImutoolError("ROS1 bag is truncated: no complete chunk of messages to read", path=self.path)
            return
        buf = np.frombuffer(b"".join(chunks), dtype=np.uint8)
        sizes = np.array([len(x) for x in chunks], np.int64)
        ends = np.cumsum(sizes)
        bounds = np.stack([ends - sizes, ends], axis=1)
        bad = np.zeros(len(chunks), np.int64)
        k, c = _scan_ros1(buf, bounds, np.empty((0, 5), np.int64), np.empty(0, np.int64), bad, False)
        out = np.empty((k, 5), np.int64)
        cpos = np.empty(c, np.int64)
        _scan_ros1(buf, bounds, out, cpos, bad, True)
        if bad.any():
            self.notes.append(
                f"{int(bad.sum())} chunk(s) end in an unreadable record (damaged); "
                "the records before the damage were kept"
            )
        for cp in cpos:
            hl = int(buf[cp]) | int(buf[cp + 1]) << 8 | int(buf[cp + 2]) << 16 | int(buf[cp + 3]) << 24
            hdr = _fields(buf[cp + 4 : cp + 4 + hl].tobytes())
            d = cp + 4 + hl
            dl = int(buf[d]) | int(buf[d + 1]) << 8 | int(buf[d + 2]) << 16 | int(buf[d + 3]) << 24
            self._add_conn(hdr, buf[d + 4 : d + 4 + dl].tobytes())
        self.buf = buf
        self.recs = out

    def _add_conn(self, hdr: dict[str, bytes], data: bytes | memoryview) -> None:
        if len(hdr.get("conn", b"")) != 4:
            return
        cid = struct.unpack("<I", hdr["conn"])[0]
        if cid in self.conns:
            return
        d = _fields(data)
        topic = hdr.get("topic", d.get("topic", b"")).decode("utf-8", "replace")
        self.conns[cid] = {
            "topic": topic,
            "type": _norm_type(d.get("type", b"").decode("utf-8", "replace")),
            "md5": d.get("md5sum", b"").decode("ascii", "replace"),
        }

    def topics(self) -> dict[str, _Topic]:
        out: dict[str, _Topic] = {}
        ids = self.recs[:, 0] if len(self.recs) else np.empty(0, np.int64)
        counts = dict(zip(*np.unique(ids, return_counts=True), strict=True)) if ids.size else {}
        for cid, c in self.conns.items():
            t = out.setdefault(c["topic"], _Topic(c["topic"], c["type"], 0, "ros1", md5=c["md5"]))
            t.ids.append(cid)
            t.count += int(counts.get(cid, 0))
        return out

    def raw(self, topic: _Topic) -> _Raw:
        sel = np.isin(self.recs[:, 0], np.array(topic.ids, dtype=np.int64))
        r = self.recs[sel]
        rec_ns = r[:, 1] * 1_000_000_000 + r[:, 2]
        order = np.argsort(rec_ns, kind="stable")
        r = r[order]
        return _Raw(self.buf, r[:, 3].copy(), r[:, 4].copy(), rec_ns[order], "ros1")


@njit(cache=True)
def _scan_mcap(buf, bounds, out, other, bad, fill):  # pragma: no cover - numba
    """Scan MCAP records (u8 opcode, u64 length, content) in each (start, end) segment of ``buf``.

    Message records (0x05) go to ``out`` rows (channel id, log_time ns, data offset, data length, segment);
    schema (0x03), channel (0x04) and chunk (0x06) records to ``other`` rows (opcode, content offset, length,
    segment). A segment stops at Data End (0x0F); one that does not parse to its end is flagged in ``bad``.
    Returns (n_messages, n_other).
    """
    k = 0
    j = 0
    for si in range(bounds.shape[0]):
        p = bounds[si, 0]
        n = bounds[si, 1]
        while p < n:
            if p + 9 > n:
                bad[si] = 1
                break
            op = buf[p]
            ln = _u32(buf, p + 1) | (_u32(buf, p + 5) << 32)
            c = p + 9
            if ln < 0 or c + ln > n:
                bad[si] = 1
                break
            if op == 5 and ln >= 22:
                if fill:
                    out[k, 0] = np.int64(buf[c]) | (np.int64(buf[c + 1]) << 8)
                    out[k, 1] = _u32(buf, c + 6) | (_u32(buf, c + 10) << 32)
                    out[k, 2] = c + 22
                    out[k, 3] = ln - 22
                    out[k, 4] = si
                k += 1
            elif op == 3 or op == 4 or op == 6:
                if fill:
                    other[j, 0] = op
                    other[j, 1] = c
                    other[j, 2] = ln
                    other[j, 3] = si
                j += 1
            elif op == 15:
                break
            p = c + ln
    return k, j


class _McapUnsupported(Exception):
    pass


def _mcap_str(b: bytes | memoryview, p: int) -> tuple[str, int]:
    (n,) = struct.unpack_from("<I", b, p)
    return bytes(b[p + 4 : p + 4 + n]).decode("utf-8", "replace"), p + 4 + n


class _McapScan:
    """Fast MCAP reader: chunks decompressed, records scanned by a numba kernel (ROS2 CDR messages)."""

    MAGIC = b"\x89MCAP0\r\n"

    def __init__(self, files: list[Path]):
        from rosbags.rosbag2.storage_mcap import DECOMPRESSORS

        self.notes: list[str] = []
        self.truncated = False
        chunks: list[bytes] = []
        chunk_file: list[int] = []
        self.schemas: dict[tuple[int, int], str] = {}
        self.channels: dict[tuple[int, int], tuple[str, int, str]] = {}
        for fi, f in enumerate(files):
            data = np.fromfile(f, dtype=np.uint8)
            if data[:8].tobytes() != self.MAGIC:
                raise _McapUnsupported("no MCAP magic")
            bounds = np.array([[8, data.shape[0]]], np.int64)
            bad = np.zeros(1, np.int64)
            k, j = _scan_mcap(data, bounds, np.empty((0, 5), np.int64), np.empty((0, 4), np.int64), bad, False)
            if k:
                raise _McapUnsupported("messages outside chunks")
            other = np.empty((j, 4), np.int64)
            _scan_mcap(data, bounds, np.empty((0, 5), np.int64), other, bad, True)
            if bad[0]:
                self.truncated = True
            raw = memoryview(data)
            for op, c, ln, _ in other.tolist():
                rec = raw[c : c + ln]
                if op == 6:
                    usize = struct.unpack_from("<Q", rec, 16)[0]
                    comp, q = _mcap_str(rec, 28)
                    (clen,) = struct.unpack_from("<Q", rec, q)
                    if comp not in DECOMPRESSORS:
                        raise _McapUnsupported(f"chunk compression {comp!r}")
                    try:
                        body = DECOMPRESSORS[comp](rec[q + 8 : q + 8 + clen], usize)
                    except Exception as exc:
                        self.notes.append(f"{f.name}: a chunk could not be decompressed ({exc}); skipped")
                        continue
                    chunks.append(body)
                    chunk_file.append(fi)
                else:
                    self._meta_record(fi, op, rec)
        if not chunks:
            self.buf = np.empty(0, np.uint8)
            self.recs = np.empty((0, 5), np.int64)
            return
        buf = np.frombuffer(b"".join(chunks), dtype=np.uint8)
        sizes = np.array([len(x) for x in chunks], np.int64)
        ends = np.cumsum(sizes)
        bounds = np.stack([ends - sizes, ends], axis=1)
        bad = np.zeros(len(chunks), np.int64)
        k, j = _scan_mcap(buf, bounds, np.empty((0, 5), np.int64), np.empty((0, 4), np.int64), bad, False)
        out = np.empty((k, 5), np.int64)
        other = np.empty((j, 4), np.int64)
        _scan_mcap(buf, bounds, out, other, bad, True)
        if bad.any():
            self.notes.append(f"{int(bad.sum())} MCAP chunk(s) damaged; records before the damage kept")
        for op, c, ln, si in other.tolist():
            if op in (3, 4):
                self._meta_record(chunk_file[si], op, buf[c : c + ln].tobytes())
        cf = np.array(chunk_file, np.int64)
        out[:, 0] += cf[out[:, 4]] << 16  # channel key = file index << 16 | channel id
        self.buf = buf
        self.recs = out

    def _meta_record(self, fi: int, op: int, rec: bytes | memoryview) -> None:
        if op == 3:
            (sid,) = struct.unpack_from("<H", rec, 0)
            name, _ = _mcap_str(rec, 2)
            self.schemas[(fi, sid)] = name
        elif op == 4:
            cid, sid = struct.unpack_from("<HH", rec, 0)
            topic, q = _mcap_str(rec, 4)
            enc, _ = _mcap_str(rec, q)
            self.channels[(fi, cid)] = (topic, sid, enc)

    def topics(self) -> dict[str, _Topic]:
        keys = self.recs[:, 0]
        counts = dict(zip(*np.unique(keys, return_counts=True), strict=True)) if keys.size else {}
        out: dict[str, _Topic] = {}
        for (fi, cid), (topic, sid, enc) in self.channels.items():
            if enc != "cdr":
                raise _McapUnsupported(f"message encoding {enc!r}")
            typ = self.schemas.get((fi, sid), "")
            t = out.setdefault(topic, _Topic(topic, typ, 0, "cdr"))
            key = (fi << 16) | cid
            t.ids.append(key)
            t.count += int(counts.get(key, 0))
        return out

    def raw(self, topic: _Topic) -> _Raw:
        r = self.recs[np.isin(self.recs[:, 0], np.array(topic.ids, dtype=np.int64))]
        order = np.argsort(r[:, 1], kind="stable")
        r = r[order]
        return _Raw(self.buf, r[:, 2].copy(), r[:, 3].copy(), r[:, 1].copy(), "cdr")


@njit(cache=True)
def _varint(b, p):  # pragma: no cover - numba
    """SQLite varint (big-endian, 7 bits per byte, 9th byte 8 bits) at p → (value, next position)."""
    v = np.int64(0)
    for i in range(8):
        c = np.int64(b[p + i])
        v = (v << 7) | (c & 0x7F)
        if c < 0x80:
            return v, p + i + 1
    return (v << 8) | np.int64(b[p + 8]), p + 9


@njit(cache=True)
def _be_int(b, p, n):  # pragma: no cover - numba
    """Big-endian two's-complement integer of n bytes (SQLite integer serial types)."""
    v = np.int64(0)
    for i in range(n):
        v = (v << 8) | np.int64(b[p + i])
    if n < 8 and v >= (np.int64(1) << (8 * n - 1)):
        v -= np.int64(1) << (8 * n)
    return v


@njit(cache=True)
def _int_col(b, p, st):  # pragma: no cover - numba
    """(value, size) of an integer column with serial type st; size -1 if st is not an integer type."""
    if st == 8:
        return np.int64(0), 0
    if st == 9:
        return np.int64(1), 0
    if st >= 1 and st <= 4:
        return _be_int(b, p, st), st
    if st == 5:
        return _be_int(b, p, 6), 6
    if st == 6:
        return _be_int(b, p, 8), 8
    return np.int64(0), -1


@njit(cache=True)
def _scan_sqlite(buf, page_size, usable, root, out, fill):  # pragma: no cover - numba
    """Walk the table b-tree of rosbag2's ``messages(id INTEGER PRIMARY KEY, topic_id, timestamp, data BLOB)``.

    Rows go to ``out`` (rowid, topic_id, timestamp, data offset, data length). Returns (rows, ok); ok = 0 on
    anything unexpected (overflow pages, other page types, other column types): the caller then uses SQL.
    """
    npages = (buf.shape[0] - 64) // page_size  # the buffer carries 64 bytes of zero padding
    stack = np.empty(1 << 16, np.int64)
    stack[0] = root
    sp = 1
    k = 0
    while sp > 0:
        sp -= 1
        pg = stack[sp]
        if pg < 1 or pg > npages:
            return k, 0
        base = (pg - 1) * page_size
        h = base + (100 if pg == 1 else 0)
        t = buf[h]
        ncell = (np.int64(buf[h + 3]) << 8) | np.int64(buf[h + 4])
        end = base + page_size
        if h + 12 + 2 * ncell > end:
            return k, 0
        if t == 5:
            if sp + ncell + 1 >= stack.shape[0]:
                return k, 0
            stack[sp] = _be_int(buf, h + 8, 4) & 0xFFFFFFFF
            sp += 1
            for i in range(ncell - 1, -1, -1):
                ptr = base + ((np.int64(buf[h + 12 + 2 * i]) << 8) | np.int64(buf[h + 13 + 2 * i]))
                if ptr + 4 > end:
                    return k, 0
                stack[sp] = _be_int(buf, ptr, 4) & 0xFFFFFFFF
                sp += 1
        elif t == 13:
            for i in range(ncell):
                ptr = base + ((np.int64(buf[h + 8 + 2 * i]) << 8) | np.int64(buf[h + 9 + 2 * i]))
                if ptr + 18 > end:
                    return k, 0
                plen, q = _varint(buf, ptr)
                rowid, q = _varint(buf, q)
                if plen < 5 or plen > usable - 35 or q + plen > end:
                    return k, 0
                hs, r = _varint(buf, q)
                if hs < 5 or hs > plen:
                    return k, 0
                st0, r = _varint(buf, r)
                st1, r = _varint(buf, r)
                st2, r = _varint(buf, r)
                st3, r = _varint(buf, r)
                if r != q + hs or st0 != 0 or st3 < 12 or st3 % 2 == 1:
                    return k, 0
                v = q + hs
                topic, n1 = _int_col(buf, v, st1)
                if n1 < 0:
                    return k, 0
                v += n1
                stamp, n2 = _int_col(buf, v, st2)
                if n2 < 0:
                    return k, 0
                v += n2
                dlen = (st3 - 12) // 2
                if v + dlen != q + plen:
                    return k, 0
                if fill:
                    out[k, 0] = rowid
                    out[k, 1] = topic
                    out[k, 2] = stamp
                    out[k, 3] = v
                    out[k, 4] = dlen
                k += 1
        else:
            return k, 0
    return k, 1


def _sqlite_direct(db: Path, topic_ids: list[int]) -> _Raw | None:
    """Rows of ``messages`` for the topic ids, read from the database pages (None → use SQL instead)."""
    wal = Path(str(db) + "-wal")
    if wal.exists() and wal.stat().st_size > 0:
        return None
    con = sqlite3.connect(f"file:{db}?immutable=1", uri=True)
    try:
        row = con.execute("SELECT rootpage FROM sqlite_master WHERE type='table' AND name='messages'").fetchone()
        cols = [(c[1], str(c[2]).upper(), c[5]) for c in con.execute("PRAGMA table_info(messages)")]
        total = con.execute("SELECT count(*) FROM messages").fetchone()[0]
    finally:
        con.close()
    # rowid alias id (stored as NULL in the record), then topic_id, timestamp, data — as rosbag2 creates it
    if row is None or [c[0] for c in cols] != ["id", "topic_id", "timestamp", "data"] or cols[0][1:] != ("INTEGER", 1):
        return None
    size = db.stat().st_size
    buf = np.zeros(size + 64, np.uint8)  # zero padding: a damaged varint never reads past the array
    with open(db, "rb") as f:
        f.readinto(memoryview(buf)[:size])
    if size < 100 or buf[:16].tobytes() != b"SQLite format 3\x00":
        return None
    page_size = (int(buf[16]) << 8) | int(buf[17])
    page_size = 65536 if page_size == 1 else page_size
    usable = page_size - int(buf[20])
    k, ok = _scan_sqlite(buf, page_size, usable, int(row[0]), np.empty((0, 5), np.int64), False)
    if not ok or k != total:
        return None
    out = np.empty((k, 5), np.int64)
    _scan_sqlite(buf, page_size, usable, int(row[0]), out, True)
    out = out[np.isin(out[:, 1], np.array(topic_ids, np.int64))]
    out = out[np.lexsort((out[:, 0], out[:, 2]))]  # ORDER BY timestamp (ties by row id)
    return _Raw(buf, out[:, 3].copy(), out[:, 4].copy(), out[:, 2].copy(), "cdr")


class _Ros2Bag:
    """ROS2 bag: a folder with metadata.yaml, or a bare .db3 / .mcap file. sqlite3 rows are read directly."""

    def __init__(self, path: str):
        self.path = path
        self.notes: list[str] = []
        self.truncated = False
        self.reader: Any = None
        self._direct_topics: dict[str, _Topic] | None = None
        p = Path(path)
        self.storage = "mcap"
        self.db_files: list[Path] = []
        counts: dict[str, int] | None = None
        compressed = False
        self._rel_files: list[str] | None = None
        if p.is_dir():
            try:
                from ruamel.yaml import YAML

                info = YAML(typ="safe").load((p / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
                self.storage = str(info.get("storage_identifier", "mcap"))
                compressed = bool(info.get("compression_mode")) and str(info.get("compression_mode")).lower() != "none"
                self._rel_files = list(info.get("relative_file_paths", []))
                self.db_files = [p / Path(f).name for f in self._rel_files]
                counts = {}
                for t in info.get("topics_with_message_count") or []:
                    name = t["topic_metadata"]["name"]
                    counts[name] = counts.get(name, 0) + int(t["message_count"])
            except Exception:
                self.storage = "unknown"  # let rosbags report what is wrong
        elif p.suffix == ".db3":
            self.storage = "sqlite3"
            self.db_files = [p]
        self.mcap: _McapScan | None = None
        if self.storage == "mcap" and not compressed:
            files = [p] if p.is_file() else [p / Path(f).name for f in (self._rel_files or [])]
            if files and all(f.is_file() for f in files):
                try:
                    self.mcap = _McapScan(files)
                    self._direct_topics = self.mcap.topics()
                    self.notes += self.mcap.notes
                    self.truncated = self.mcap.truncated
                    return
                except (_McapUnsupported, struct.error, ValueError, IndexError):
                    self.mcap = None  # rosbags reads it (or explains what is wrong)
                    self._direct_topics = None
        self.direct = (
            self.storage == "sqlite3"
            and not compressed
            and bool(self.db_files)
            and all(f.is_file() for f in self.db_files)
        )
        if self.direct:
            try:
                self._direct_topics = self._db_topics(counts)
                return
            except sqlite3.DatabaseError:
                self.direct = False  # fall through: rosbags gives its own diagnosis
        from rosbags.rosbag2 import Reader

        try:
            self.reader = Reader(p)
            self.reader.open()
        except Exception as exc:
            raise ImutoolError(f"cannot open ROS2 bag: {exc}", path=path) from None

    def _db_topics(self, counts: dict[str, int] | None) -> dict[str, _Topic]:
        out: dict[str, _Topic] = {}
        for db in self.db_files:
            con = sqlite3.connect(f"file:{db}?immutable=1", uri=True)
            try:
                tops = con.execute("SELECT id, name, type, serialization_format FROM topics").fetchall()
                n_by_id: dict[int, int] = {}
                if counts is None:
                    n_by_id = dict(con.execute("SELECT topic_id, count(*) FROM messages GROUP BY topic_id"))
            finally:
                con.close()
            for tid, name, typ, ser in tops:
                if ser != "cdr":
                    raise sqlite3.DatabaseError(f"serialization {ser!r}")
                t = out.setdefault(name, _Topic(name, typ, 0, "cdr"))
                t.ids.append(tid)
                if counts is None:
                    t.count += int(n_by_id.get(tid, 0))
        if counts is not None:
            for name, t in out.items():
                t.count = counts.get(name, 0)
        return out

    def close(self) -> None:
        try:
            if self.reader is not None:
                self.reader.close()
        except Exception:
            pass

    def topics(self) -> dict[str, _Topic]:
        if self._direct_topics is not None:
            return self._direct_topics
        out: dict[str, _Topic] = {}
        for c in self.reader.connections:
            t = out.setdefault(c.topic, _Topic(c.topic, c.msgtype, 0, "cdr"))
            t.ids.append(c)
            t.count += int(c.msgcount)
        return out

    def raw(self, topic: _Topic) -> _Raw:
        if self.mcap is not None:
            return self.mcap.raw(topic)
        rows: list[tuple[int, bytes]] = []
        try:
            if self.direct and len(self.db_files) == 1 and topic.ids:
                fast = _sqlite_direct(self.db_files[0], [int(i) for i in topic.ids])
                if fast is not None:
                    return fast
            if self.direct:
                for db in self.db_files:
                    con = sqlite3.connect(f"file:{db}?immutable=1", uri=True)
                    try:
                        ids = [r[0] for r in con.execute("SELECT id FROM topics WHERE name = ?", (topic.name,))]
                        if ids:
                            q = (
                                "SELECT timestamp, data FROM messages WHERE topic_id IN "
                                f"({','.join('?' * len(ids))}) ORDER BY timestamp"
                            )
                            rows.extend(con.execute(q, ids).fetchall())
                    finally:
                        con.close()
            else:
                rows = [(ts, raw) for _, ts, raw in self.reader.messages(connections=topic.ids)]
        except sqlite3.DatabaseError as exc:
            raise ImutoolError(f"ROS2 sqlite3 storage is damaged: {exc}", path=self.path) from None
        except ImutoolError:
            raise
        except Exception as exc:
            raise ImutoolError(f"cannot read messages of {topic.name}: {exc}", path=self.path) from None
        rec_ns = np.fromiter(map(itemgetter(0), rows), dtype=np.int64, count=len(rows))
        datas = list(map(itemgetter(1), rows))
        lens = np.fromiter(map(len, datas), dtype=np.int64, count=len(datas))
        offs = np.zeros(len(datas), np.int64)
        if len(datas) > 1:
            np.cumsum(lens[:-1], out=offs[1:])
        buf = np.frombuffer(b"".join(datas), dtype=np.uint8) if datas else np.empty(0, np.uint8)
        return _Raw(buf, offs, lens, rec_ns, "cdr")


def _open(path: str) -> _Ros1Bag | _Ros2Bag:
    p = Path(path)
    if not p.exists():
        raise ImutoolError("no such file or folder", path=path)
    if p.is_file() and p.suffix.lower() == ".bag":
        return _Ros1Bag(path)
    if p.is_dir() and not (p / "metadata.yaml").exists():
        inner = sorted(list(p.glob("*.mcap")) + list(p.glob("*.db3")))
        if len(inner) == 1:
            return _Ros2Bag(os.fspath(inner[0]))
        raise ImutoolError("folder is not a ROS2 bag (no metadata.yaml)", path=path)
    return _Ros2Bag(path)


def list_topics(path: str | os.PathLike) -> list[dict[str, Any]]:
    """Topics of a bag: [{'topic', 'type', 'count', 'kind'}] (kind: imu, mag, vec3 or None)."""
    bag = _open(os.fspath(path))
    try:
        return [
            {"topic": t.name, "type": t.msgtype, "count": t.count, "kind": _KIND.get(t.msgtype)}
            for t in bag.topics().values()
        ]
    finally:
        if isinstance(bag, _Ros2Bag):
            bag.close()


# ---------------------------------------------------------------------------------------------------------------
# decoding
# ---------------------------------------------------------------------------------------------------------------
_TYPESTORES: dict[str, Any] = {}


def _typestore(fmt: str):
    if fmt not in _TYPESTORES:
        from rosbags.typesys import Stores, get_typestore

        _TYPESTORES[fmt] = get_typestore(Stores.ROS1_NOETIC if fmt == "ros1" else Stores.ROS2_HUMBLE)
    return _TYPESTORES[fmt]


def _std_md5(msgtype: str) -> str:
    return _typestore("ros1").generate_msgdef(msgtype)[1]


@dataclass
class _Decoded:
    stamp_ns: np.ndarray
    rec_ns: np.ndarray
    floats: np.ndarray  # (n, nfloat) in message order
    frame_ids: list[str]
    bad: int = 0
    fallback: int = 0


def _floats_of_msg(m: Any, kind: str) -> list[float]:
    if kind == "imu":
        o = m.orientation
        return (
            [o.x, o.y, o.z, o.w]
            + list(m.orientation_covariance)
            + [m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z]
            + list(m.angular_velocity_covariance)
            + [m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z]
            + list(m.linear_acceleration_covariance)
        )
    if kind == "mag":
        v = m.magnetic_field
        return [v.x, v.y, v.z] + list(m.magnetic_field_covariance)
    v = m.vector
    return [v.x, v.y, v.z]


def _decode(raw: _Raw, kind: str, msgtype: str) -> _Decoded:
    """Decode fixed-layout payloads with numpy; irregular ones through rosbags deserialisation."""
    n = raw.offs.shape[0]
    nf = _NFLOAT[kind]
    buf, offs, lens = raw.buf, raw.offs, raw.lens
    ok = lens >= 16
    hdr = np.zeros((n, 4), np.uint32)
    if ok.any():
        hdr[ok] = _take(buf, offs[ok], "<u4", 4)
    flen = hdr[:, 3].astype(np.int64)
    if raw.fmt == "ros1":
        sec = hdr[:, 1].astype(np.int64)
        fstart = 16 + flen
        expected = fstart + 8 * nf
        ok &= lens == expected
    else:
        enc = hdr[:, 0] & 0xFFFF  # bytes 0,1 (little-endian view): b'\x00\x01' = CDR little endian
        sec = hdr[:, 1].view(np.int32).astype(np.int64)
        fstart = 4 + ((12 + flen + 7) // 8) * 8
        expected = fstart + 8 * nf
        ok &= (enc == 0x0100) & (flen >= 1) & (lens >= expected) & (lens <= expected + 7)
    nsec = hdr[:, 2].astype(np.int64)
    stamp = sec * 1_000_000_000 + nsec
    good = np.flatnonzero(ok)
    if good.size == n:
        floats = _take(buf, offs + fstart, "<f8", nf)
    else:
        floats = np.full((n, nf), np.nan)
        if good.size:
            floats[good] = _take(buf, offs[good] + fstart[good], "<f8", nf)
    # frame ids: one check per distinct length
    frame_ids: set[str] = set()
    for L in np.unique(flen[good]):
        sel = good[flen[good] == L]
        width = int(L) - (0 if raw.fmt == "ros1" else 1)
        if width <= 0:
            frame_ids.add("")
            continue
        rows = _take(buf, offs[sel] + 16, "u1", width)
        uniq = rows[:1] if (rows == rows[0]).all() else np.unique(rows, axis=0)
        for u in uniq[:20]:
            frame_ids.add(u.tobytes().decode("utf-8", "replace"))
    # fallback for anything irregular
    badidx = np.flatnonzero(~ok)
    nbad = 0
    keep = np.ones(n, bool)
    if badidx.size:
        ts = _typestore(raw.fmt)
        for i in badidx:
            data = buf[offs[i] : offs[i] + lens[i]].tobytes()
            try:
                m = ts.deserialize_ros1(data, msgtype) if raw.fmt == "ros1" else ts.deserialize_cdr(data, msgtype)
                floats[i] = _floats_of_msg(m, kind)
                stamp[i] = int(m.header.stamp.sec) * 1_000_000_000 + int(m.header.stamp.nanosec)
                frame_ids.add(m.header.frame_id)
            except Exception:
                keep[i] = False
                nbad += 1
    dec = _Decoded(stamp, raw.rec_ns, floats, sorted(frame_ids), bad=nbad, fallback=int(badidx.size) - nbad)
    if nbad:
        dec.stamp_ns, dec.rec_ns, dec.floats = stamp[keep], raw.rec_ns[keep], floats[keep]
    return dec


def _decode_slow(bag_path: str, topic: str, kind: str) -> _Decoded:
    """Reference path: rosbags AnyReader + per-message deserialise (also used for non-standard definitions)."""
    from rosbags.highlevel import AnyReader

    try:
        with AnyReader([Path(bag_path)]) as r:
            cons = [c for c in r.connections if c.topic == topic]
            st, rt, fl, fr = [], [], [], set()
            for c, t, data in r.messages(connections=cons):
                m = r.deserialize(data, c.msgtype)
                st.append(int(m.header.stamp.sec) * 1_000_000_000 + int(m.header.stamp.nanosec))
                rt.append(t)
                fl.append(_floats_of_msg(m, kind))
                fr.add(m.header.frame_id)
    except Exception as exc:
        raise ImutoolError(f"cannot read {topic}: {exc}", path=bag_path) from None
    return _Decoded(
        np.array(st, np.int64), np.array(rt, np.int64), np.array(fl, float).reshape(-1, _NFLOAT[kind]), sorted(fr)
    )


# ---------------------------------------------------------------------------------------------------------------
# conversion ROS (FLU/ENU, T) ↔ imutool (FRD/NED, µT)
# ---------------------------------------------------------------------------------------------------------------
def ros_to_frd_quat(q_xyzw: np.ndarray) -> np.ndarray:
    """ROS orientation [x,y,z,w] (FLU body → ENU) → imutool q [w,x,y,z] (FRD body → NED)."""
    q = np.asarray(q_xyzw, float)[..., [3, 0, 1, 2]]
    return quat_multiply(quat_multiply(Q_ENU_TO_NED, q), Q_FLU_TO_FRD)


def frd_to_ros_quat(q_wxyz: np.ndarray) -> np.ndarray:
    """imutool q [w,x,y,z] (FRD → NED) → ROS orientation [x,y,z,w] (FLU → ENU)."""
    q = quat_multiply(quat_multiply(quat_conjugate(Q_ENU_TO_NED), q_wxyz), quat_conjugate(Q_FLU_TO_FRD))
    return q[..., [1, 2, 3, 0]]


def _ns_to_seconds(ns: np.ndarray) -> np.ndarray:
    ns = np.asarray(ns, np.int64)
    sec = ns // 1_000_000_000
    return sec.astype(np.float64) + (ns - sec * 1_000_000_000).astype(np.float64) * 1e-9


def _seconds_to_sec_nsec(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float64 seconds → (sec, nsec) integers, rounding to the nearest ns without losing float precision."""
    t = np.asarray(t, np.float64)
    sec = np.floor(t)
    nsec = np.rint((t - sec) * 1e9).astype(np.int64)
    sec = sec.astype(np.int64)
    carry = nsec >= 1_000_000_000
    sec[carry] += 1
    nsec[carry] -= 1_000_000_000
    return sec, nsec


def _cov_channels(rec: Recording, cov: np.ndarray, absent: np.ndarray, name: str, scale: float) -> str | None:
    """Add the covariance of a quantity (FLU, ROS units) as *_std or *_cov channels; returns what was added."""
    present = ~absent
    anyabsent = bool(absent.any())
    cp = cov[present] if anyabsent else cov
    if cp.shape[0] == 0 or not np.any(cp != 0):
        return None
    if np.any(cp[:, [1, 2, 3, 5, 6, 7]] != 0):
        c = cov * (_COV_SIGN * scale)
        c[absent] = np.nan
        rec.add(f"{name}_cov", c, _COV_UNITS[name], columns=[f"{name}_cov_{a}" for a in _AXES])
        return f"{name}_cov"
    var = cov[:, [0, 4, 8]] * scale
    var[absent] = np.nan
    with np.errstate(invalid="ignore"):
        std = np.sqrt(var)
    if name == "q":
        for j, nm in enumerate(_STD_NAMES):
            rec.add(nm, np.degrees(std[:, j]), "deg")
        return "roll_std,pitch_std,heading_std"
    rec.add(f"{name}_std", std)
    return f"{name}_std"


def _to_recording(dec: _Decoded, kind: str, stamp: str, topic: str, path: str, mag_unit_scale: float) -> Recording:
    if stamp == "header":
        zero = dec.stamp_ns == 0
        # one zero stamp at the start is a legitimate t = 0 (simulated data); more means unfilled stamps
        if zero.sum() > 1 or (zero.any() and len(zero) == 1) or (zero.any() and not zero[0]):
            raise ImutoolError(
                f"{int(zero.sum())} of {len(zero)} messages on {topic} have a zero header stamp; "
                "use --stamp record (the bag's record time) instead",
                path=path,
            )
        ns = dec.stamp_ns
    elif stamp == "record":
        ns = dec.rec_ns
    else:
        raise ImutoolError(f"unknown stamp choice {stamp!r} (header, record)")
    rec = Recording(_ns_to_seconds(ns))
    f = dec.floats
    conv: list[str] = []
    if kind == "imu":
        q_abs = f[:, 4] == -1
        g_abs = f[:, 17] == -1
        a_abs = f[:, 28] == -1
        if not q_abs.all():
            q = ros_to_frd_quat(f[:, 0:4])
            q[q_abs] = np.nan
            rec.add("q", q)
            conv.append("orientation: q_frd_ned = q(ENU→NED) ⊗ q_ros ⊗ q(FRD→FLU)")
        if not g_abs.all():
            g = f[:, 13:16] * _FLIP
            g[g_abs] = np.nan
            rec.add("gyro", g)
            conv.append("angular_velocity FLU → FRD (x,-y,-z)")
        if not a_abs.all():
            a = f[:, 25:28] * _FLIP
            a[a_abs] = np.nan
            rec.add("accel", a)
            conv.append("linear_acceleration FLU → FRD (x,-y,-z)")
        for name, sl, absent in (("gyro", slice(16, 25), g_abs), ("accel", slice(28, 37), a_abs)):
            if name in rec:
                _cov_channels(rec, f[:, sl], absent, name, 1.0)
        if "q" in rec:
            _cov_channels(rec, f[:, 4:13], q_abs, "q", 1.0)
        if len(rec.channels) == 0:
            raise ImutoolError(f"{topic}: every Imu field is marked absent (covariance[0] = -1)", path=path)
    else:
        absent = f[:, 3] == -1 if kind == "mag" else np.zeros(len(f), bool)
        m = f[:, 0:3] * _FLIP * mag_unit_scale
        m[absent] = np.nan
        rec.add("mag", m)
        conv.append(f"{'magnetic_field' if kind == 'mag' else 'vector'} FLU → FRD (x,-y,-z), ×{mag_unit_scale:g} → µT")
        if kind == "mag":
            _cov_channels(rec, f[:, 3:12], absent, "mag", mag_unit_scale**2)
    rec.meta["_conv"] = conv
    return rec


# ---------------------------------------------------------------------------------------------------------------
# public reader
# ---------------------------------------------------------------------------------------------------------------
def _select(topics: dict[str, _Topic], topic: str | None, path: str) -> tuple[_Topic | None, _Topic | None, list[str]]:
    def listing() -> str:
        return "; ".join(f"{t.name} ({t.msgtype}, {t.count} msgs)" for t in topics.values()) or "none"

    notes: list[str] = []
    wanted = [s.strip() for s in topic.split(",") if s.strip()] if topic else []
    imu_t: _Topic | None = None
    mag_t: _Topic | None = None
    for w in wanted:
        if w not in topics:
            raise ImutoolError(f"topic {w!r} not in bag; topics: {listing()}", path=path)
        t = topics[w]
        kind = _KIND.get(t.msgtype)
        if kind is None:
            raise ImutoolError(
                f"topic {w} has type {t.msgtype}; imutool reads sensor_msgs/Imu, "
                "sensor_msgs/MagneticField and geometry_msgs/Vector3Stamped",
                path=path,
            )
        if kind == "imu":
            if imu_t is not None:
                raise ImutoolError(f"two Imu topics named ({imu_t.name}, {w}); name one", path=path)
            imu_t = t
        else:
            if mag_t is not None:
                raise ImutoolError(f"two magnetometer topics named ({mag_t.name}, {w}); name one", path=path)
            mag_t = t
    imus = [t for t in topics.values() if t.msgtype == IMU and t.count > 0]
    mags = [
        t
        for t in topics.values()
        if t.count > 0 and (t.msgtype == MAG or (t.msgtype == VEC3 and "mag" in t.name.lower()))
    ]
    for kind_name, cands, chosen in (("Imu", imus, imu_t), ("magnetometer", mags, mag_t)):
        if chosen is not None:
            continue
        if len(cands) > 1:
            if not wanted:
                raise ImutoolError(
                    f"{len(cands)} {kind_name} topics; choose with --topic IMU[,MAG]. Topics: {listing()}", path=path
                )
            notes.append(f"{kind_name} topic not chosen among " + ", ".join(t.name for t in cands) + "; not read")
        elif len(cands) == 1:
            if kind_name == "Imu":
                imu_t = cands[0]
            else:
                mag_t = cands[0]
    if imu_t is None and mag_t is None:
        raise ImutoolError(
            "no sensor_msgs/Imu, sensor_msgs/MagneticField or magnetometer Vector3Stamped "
            f"topic with messages; topics: {listing()}",
            path=path,
        )
    return imu_t, mag_t, notes


def read_bag(
    path: str | os.PathLike,
    topic: str | None = None,
    stamp: str = "header",
    vector3_mag_unit: str = "T",
    fast: bool = True,
) -> Recording:
    """Read IMU (+ magnetometer) messages from a ROS1 .bag or a ROS2 bag (folder, .db3 or .mcap).

    topic: None (auto: the only Imu topic and the only magnetometer topic; several → ImutoolError listing
    them) or 'IMU_TOPIC[,MAG_TOPIC]'. stamp: 'header' (message stamp) or 'record' (bag record time).
    vector3_mag_unit: unit of a Vector3Stamped magnetometer (T, gauss, uT, nT...). fast=False forces rosbags
    per-message deserialisation (reference path). Output: FRD body / NED world, SI (mag µT), see module doc.
    With an IMU and a magnetometer topic the magnetometer is interpolated onto the IMU clock
    (formats.recording.merge; only the common time span is kept).
    """
    path = os.fspath(path)
    if stamp not in ("header", "record"):
        raise ImutoolError(f"unknown stamp choice {stamp!r} (header, record)")
    from . import units as _units

    try:
        vscale = _units.factor_to_si(vector3_mag_unit, "magnetic")
    except ImutoolError:
        raise
    bag = _open(path)
    try:
        topics = bag.topics()
        if getattr(bag, "truncated", False) and not any(t.count for t in topics.values()):
            raise ImutoolError("bag is truncated: no complete chunk of messages to read", path=path)
        imu_t, mag_t, notes = _select(topics, topic, path)
        fmt_name = "ros1" if isinstance(bag, _Ros1Bag) else f"ros2-{bag.storage}"
        recs: list[Recording] = []
        info: dict[str, Any] = {}
        frame_ids: list[str] = []
        for t in (imu_t, mag_t):
            if t is None:
                continue
            kind = _KIND[t.msgtype]
            nonstd = isinstance(bag, _Ros1Bag) and t.md5 and t.md5 != _std_md5(t.msgtype)
            if not fast or nonstd:
                if isinstance(bag, _Ros1Bag) and bag.truncated:
                    raise ImutoolError("truncated bag: only the fast reader can recover it", path=path)
                dec = _decode_slow(path, t.name, kind)
            else:
                dec = _decode(bag.raw(t), kind, t.msgtype)
            if len(dec.stamp_ns) == 0:
                raise ImutoolError(f"topic {t.name} has no readable messages", path=path)
            r = _to_recording(dec, kind, stamp, t.name, path, vscale if kind == "vec3" else 1e6)
            info[kind if kind == "imu" else "mag"] = {
                "topic": t.name,
                "type": t.msgtype,
                "messages": int(len(dec.stamp_ns)),
                "frame_id": dec.frame_ids[0] if len(dec.frame_ids) == 1 else dec.frame_ids,
                "undecodable_skipped": dec.bad,
                "decoded_by_rosbags": dec.fallback,
            }
            frame_ids += dec.frame_ids
            recs.append(r)
        conv = [c for r in recs for c in r.meta.pop("_conv", [])]
        if len(recs) == 2:
            n_imu = len(recs[0])
            rec = merge(recs, clock=recs[0])
            if len(rec) < n_imu:
                notes.append(f"{n_imu - len(rec)} IMU messages outside the magnetometer's time span dropped")
            conv.append("magnetometer interpolated onto the IMU clock")
        else:
            rec = recs[0]
        rec.meta = {
            "source": path,
            "sensor": "ROS bag",
            "frame": "body FRD / world NED (converted from ROS REP-103 FLU/ENU)",
            "bag": {
                "format": fmt_name,
                "stamp": stamp,
                "topics": info,
                "frame_id": sorted(set(frame_ids)),
                "conversions": conv,
                "truncated": bool(getattr(bag, "truncated", False)),
                "notes": notes + list(getattr(bag, "notes", [])),
            },
        }
        if getattr(bag, "truncated", False):
            rec.meta["bag"]["partial_read"] = (
                f"truncated bag: {sum(v['messages'] for v in info.values())} messages recovered from complete chunks"
            )
        return rec
    finally:
        if isinstance(bag, _Ros2Bag):
            bag.close()


# ---------------------------------------------------------------------------------------------------------------
# writer
# ---------------------------------------------------------------------------------------------------------------
def _cov_from(rec: Recording, name: str, unit_scale: float) -> np.ndarray | None:
    """(N, 9) covariance in FRD (SI² imutool units) from *_cov, 9 scalar columns, or *_std; None if absent."""
    n = len(rec)
    cn = f"{name}_cov"
    if cn in rec and rec[cn].shape[1:] == (9,):
        c = rec[cn].astype(float)
    elif all(f"{cn}_{a}" in rec for a in _AXES):
        c = np.stack([rec[f"{cn}_{a}"] for a in _AXES], axis=1).astype(float)
    elif name == "q" and all(s in rec for s in _STD_NAMES):
        c = np.zeros((n, 9))
        for j, s in enumerate(_STD_NAMES):
            c[:, 4 * j] = np.radians(rec.get(s, "deg")) ** 2
        return c
    elif name != "q" and f"{name}_std" in rec and rec[f"{name}_std"].shape[1:] == (3,):
        unit = {"gyro": "rad/s", "accel": "m/s^2", "mag": "uT"}[name]
        s = rec.get(f"{name}_std", unit) if rec.units.get(f"{name}_std") else rec[f"{name}_std"]
        c = np.zeros((n, 9))
        c[:, [0, 4, 8]] = s**2
        return c
    else:
        return None
    return c


def _cov_names(rec: Recording, name: str) -> list[str]:
    cn = f"{name}_cov"
    out = [cn] + [f"{cn}_{a}" for a in _AXES]
    out += list(_STD_NAMES) if name == "q" else [f"{name}_std"]
    return [x for x in out if x in rec]


def _imu_payloads(rec: Recording, fmt: str, frame_id: str) -> tuple[np.ndarray, int, list[str]]:
    """Serialise Imu messages with numpy (fixed layout); returns (bytes as (n, size) uint8, size, used channels)."""
    n = len(rec)
    used: list[str] = []
    floats = np.zeros((n, 37))
    floats[:, 3] = 1.0  # identity orientation when absent (covariance[0] = -1 marks it absent)
    if "q" in rec and rec["q"].shape[1:] == (4,):
        floats[:, 0:4] = frd_to_ros_quat(rec["q"])
        used.append("q")
        qsrc = True
    elif all(k in rec for k in ("roll", "pitch", "heading")):
        q = euler_to_quat(rec.get("roll", "rad"), rec.get("pitch", "rad"), rec.get("heading", "rad"))
        floats[:, 0:4] = frd_to_ros_quat(q)
        used += ["roll", "pitch", "heading"]
        qsrc = True
    else:
        floats[:, 4] = -1.0
        qsrc = False
    if qsrc:
        c = _cov_from(rec, "q", 1.0)
        if c is not None:
            floats[:, 4:13] = c * _COV_SIGN
            used += _cov_names(rec, "q")
    for name, vs, cs in (("gyro", 13, 16), ("accel", 25, 28)):
        if name in rec and rec[name].shape[1:] == (3,):
            unit = "rad/s" if name == "gyro" else "m/s^2"
            v = rec.in_unit(name, unit)
            floats[:, vs : vs + 3] = v * _FLIP
            used.append(name)
            c = _cov_from(rec, name, 1.0)
            if c is not None:
                floats[:, cs : cs + 9] = c * _COV_SIGN
                used += _cov_names(rec, name)
        else:
            floats[:, cs] = -1.0
    return _serialise(rec.time, floats, fmt, frame_id), used


def _mag_payloads(rec: Recording, fmt: str, frame_id: str) -> tuple[np.ndarray, np.ndarray, list[str]]:
    m = rec.get("mag", "uT") if rec.units.get("mag") else rec["mag"]
    keep = ~np.all(np.isnan(m), axis=1)
    floats = np.zeros((len(rec), 12))
    floats[:, 0:3] = m * _FLIP * 1e-6
    used = ["mag"]
    c = _cov_from(rec, "mag", 1.0)
    if c is not None:
        floats[:, 3:12] = c * _COV_SIGN * 1e-12
        used += _cov_names(rec, "mag")
    return _serialise(rec.time[keep], floats[keep], fmt, frame_id), keep, used


def _serialise(t: np.ndarray, floats: np.ndarray, fmt: str, frame_id: str) -> np.ndarray:
    """Messages as rows of a (n, size) uint8 array: header (stamp, frame_id) + float64 block."""
    n, nf = floats.shape
    sec, nsec = _seconds_to_sec_nsec(t)
    fid = frame_id.encode("utf-8")
    if fmt == "ros1":
        L = len(fid)
        fstart = 16 + L
        size = fstart + 8 * nf
        out = np.zeros((n, size), np.uint8)
        out[:, 0:4] = np.arange(n, dtype="<u4").view(np.uint8).reshape(n, 4)
        if np.any(sec < 0) or np.any(sec > 0xFFFFFFFF):
            raise ImutoolError("time is outside the ROS1 stamp range (0 .. 2^32 s)")
        out[:, 4:8] = sec.astype("<u4").view(np.uint8).reshape(n, 4)
    else:
        L = len(fid) + 1
        fstart = 4 + ((12 + L + 7) // 8) * 8
        size = fstart + 8 * nf
        out = np.zeros((n, size), np.uint8)
        out[:, 1] = 1  # CDR little endian
        if np.any(sec < -(2**31)) or np.any(sec >= 2**31):
            raise ImutoolError("time is outside the ROS2 stamp range (int32 seconds)")
        out[:, 4:8] = sec.astype("<i4").view(np.uint8).reshape(n, 4)
    out[:, 8:12] = nsec.astype("<u4").view(np.uint8).reshape(n, 4)
    out[:, 12:16] = np.frombuffer(struct.pack("<I", L), np.uint8)
    if fid:
        out[:, 16 : 16 + len(fid)] = np.frombuffer(fid, np.uint8)
    out[:, fstart:] = np.ascontiguousarray(floats, dtype="<f8").view(np.uint8).reshape(n, 8 * nf)
    return out


def _stamps_ns(t: np.ndarray) -> np.ndarray:
    sec, nsec = _seconds_to_sec_nsec(t)
    return sec * 1_000_000_000 + nsec


def write_bag(
    rec: Recording,
    path: str | os.PathLike,
    topic: str = "/imu/data",
    mag_topic: str = "/imu/mag",
    frame_id: str | None = None,
    storage: str | None = None,
    compression: str | None = None,
) -> dict[str, Any]:
    """Write a Recording as sensor_msgs/Imu (+ MagneticField) to a ROS1 .bag or a ROS2 bag.

    path: ``*.bag`` ROS1; ``*.db3`` / ``*.mcap`` a single ROS2 storage file; any other name a ROS2 bag folder
    (storage ``sqlite3`` unless ``storage='mcap'``). FRD/NED → FLU/ENU (inverse of :func:`read_bag`); mag µT → T.
    Orientation from ``q`` (or roll/pitch/heading), its covariance from ``q_cov`` or roll/pitch/heading_std.
    compression: ROS1 chunk compression 'bz2' or 'lz4'. Atomic. Returns a summary with the channels written
    and those that an Imu/MagneticField message cannot carry (``channels_not_written``).
    """
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    path = os.fspath(path)
    p = Path(path)
    ext = p.suffix.lower()
    ros1 = ext == ".bag"
    if len(rec) == 0:
        raise ImutoolError("nothing to write: the recording has no rows", path=path)
    has_imu = any(k in rec for k in ("gyro", "accel", "q")) or all(k in rec for k in ("roll", "pitch", "heading"))
    has_mag = "mag" in rec and rec["mag"].shape[1:] == (3,)
    if not has_imu and not has_mag:
        raise ImutoolError(
            "nothing to write as Imu/MagneticField: needs gyro, accel, q/roll,pitch,heading or mag; "
            f"has {', '.join(rec.channels) or 'none'}",
            path=path,
        )
    if len(rec) > 1 and np.any(np.diff(rec.time) < 0):
        raise ImutoolError("time goes backwards; validate the recording first (--backwards sort)", path=path)
    fid = frame_id or _meta_frame_id(rec) or "imu_link"
    fmt = "ros1" if ros1 else "cdr"
    if ext in (".db3", ".mcap"):
        storage = ext[1:].replace("db3", "sqlite3")
    elif storage is None:
        storage = "sqlite3"
    if storage not in ("sqlite3", "mcap"):
        raise ImutoolError(f"unknown ROS2 storage {storage!r} (sqlite3, mcap)")
    used: list[str] = []
    msgs: list[tuple[str, str, np.ndarray, np.ndarray]] = []
    if has_imu:
        pay, u = _imu_payloads(rec, fmt, fid)
        used += u
        msgs.append((topic, IMU, pay, _stamps_ns(rec.time)))
    if has_mag:
        pay, keep, u = _mag_payloads(rec, fmt, fid)
        used += u
        msgs.append((mag_topic, MAG, pay, _stamps_ns(rec.time[keep])))
    not_written = [k for k in rec.channels if k not in used]
    ts = _typestore("ros1" if ros1 else "cdr")
    try:
        if ros1:
            with atomic_path(path) as tmp:
                os.unlink(tmp)
                w = Writer1(tmp)
                if compression:
                    if compression not in ("bz2", "lz4"):
                        raise ImutoolError(f"unknown ROS1 compression {compression!r} (bz2, lz4)")
                    w.set_compression(Writer1.CompressionFormat[compression.upper()])
                with w:
                    _write_all(w, msgs, ts)
        elif ext in (".db3", ".mcap"):
            with atomic_path(path) as tmp:
                os.unlink(tmp)
                d = Path(tempfile.mkdtemp(prefix=".imutool-bag.", dir=p.parent if str(p.parent) else "."))
                try:
                    folder = d / p.stem
                    plugin = StoragePlugin.MCAP if ext == ".mcap" else StoragePlugin.SQLITE3
                    with Writer2(folder, version=9, storage_plugin=plugin) as w:
                        _write_all(w, msgs, ts)
                    inner = next(folder.glob("*" + ext))
                    os.replace(inner, tmp)
                finally:
                    shutil.rmtree(d, ignore_errors=True)
        else:
            with atomic_path(path, is_dir=True) as tmp:
                plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
                inner_name = p.name or "bag"
                with Writer2(tmp, version=9, storage_plugin=plugin) as w:
                    _write_all(w, msgs, ts)
                _rename_storage(tmp, inner_name)
    except ImutoolError:
        raise
    except OSError as exc:
        raise ImutoolError(f"cannot write bag: {exc}", path=path) from None
    return {
        "format": "ros1" if ros1 else f"ros2-{storage}",
        "messages": {t: int(len(pay)) for t, _, pay, _ in msgs},
        "frame_id": fid,
        "channels_written": used,
        "channels_not_written": not_written,
        "conversions": _out_conversions(used),
    }


def _out_conversions(used: list[str]) -> list[str]:
    conv = [f"{k} FRD → FLU (x,-y,-z)" for k in ("gyro", "accel", "mag") if k in used]
    if "mag" in used:
        conv.append("mag µT → T")
    if "q" in used:
        conv.append("q (FRD→NED) → orientation (FLU→ENU)")
    elif "roll" in used:
        conv.append("roll/pitch/heading → q (FRD→NED) → orientation (FLU→ENU)")
    if any(k.endswith(("_std", "_cov")) or "_cov_" in k for k in used):
        conv.append("covariances R C Rᵀ, R = diag(1,-1,-1) (std → variance on the diagonal)")
    return conv


def _rename_storage(folder: Path, name: str) -> None:
    """rosbags names the storage file after the (temporary) folder; give it the final bag name."""
    import re

    meta = folder / "metadata.yaml"
    for f in folder.iterdir():
        if f.suffix in (".db3", ".mcap") and f.stem != name:
            new = f.with_name(name + f.suffix)
            os.replace(f, new)
            text = meta.read_text()
            text = re.sub(re.escape(f.name), new.name, text)
            meta.write_text(text)


def _meta_frame_id(rec: Recording) -> str | None:
    b = rec.meta.get("bag")
    if isinstance(b, dict):
        f = b.get("frame_id")
        if isinstance(f, list) and len(f) == 1:
            return str(f[0])
        if isinstance(f, str):
            return f
    return None


def _write_all(w: Any, msgs: list[tuple[str, str, np.ndarray, np.ndarray]], ts: Any) -> None:
    for topic, msgtype, pay, stamps in msgs:
        conn = w.add_connection(topic, msgtype, typestore=ts)
        flat = pay.tobytes()
        size = pay.shape[1]
        write = w.write
        for i, t in enumerate(stamps.tolist()):
            write(conn, t, flat[i * size : (i + 1) * size])
