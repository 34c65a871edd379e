"""ROS1 v2.0 ``.bag`` back-end: the whole file read sequentially, every chunk decompressed, records scanned by numba.

Record layout: uint32 header length, header fields ``name=value`` (each uint32-length prefixed), uint32 data
length, data. A file cut short is read up to its last complete chunk (``truncated``); a chunk that does not parse
to its end keeps the records before the damage (noted). The decompressed chunks of the whole bag stay in memory
(about 330 bytes per Imu message).
"""

from __future__ import annotations

import mmap
import os
import struct
from typing import Any

import numpy as np

from formats.jit.decorators import njit

from ..errors import ImutoolError
from ..jit import cache as kernel_cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from .decode import u32
from .protocol import BagBackend, RawMessages, Topic, count_by_id, norm_type


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
        hl = u32(buf, p)
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
            fl = u32(buf, q)
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
                conn = u32(buf, e + 1)
            elif nl == 4 and vl == 8 and buf[f0] == 116 and buf[f0 + 1] == 105 and buf[f0 + 2] == 109:
                sec = u32(buf, e + 1)
                nsec = u32(buf, e + 5)
            q = f1
        if bad:
            break
        dl = u32(buf, h1)
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


def header_fields(block: bytes | memoryview) -> dict[str, bytes]:
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


class Ros1Bag(BagBackend):
    """Sequential ROS1 v2.0 reader (all chunks decompressed and scanned when opened; tolerant of a truncated file)."""

    format = "ros1"
    fmt = "ros1"

    def __init__(self, path: str):
        super().__init__()
        self.path = path
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
                    hdr = header_fields(mv[p + 4 : p + 4 + hl])
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
            hdr = header_fields(buf[cp + 4 : cp + 4 + hl].tobytes())
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
        d = header_fields(data)
        topic = hdr.get("topic", d.get("topic", b"")).decode("utf-8", "replace")
        self.conns[cid] = {
            "topic": topic,
            "type": norm_type(d.get("type", b"").decode("utf-8", "replace")),
            "md5": d.get("md5sum", b"").decode("ascii", "replace"),
        }

    def topics(self) -> dict[str, Topic]:
        out: dict[str, Topic] = {}
        counts = count_by_id(self.recs[:, 0])
        for cid, c in self.conns.items():
            t = out.setdefault(c["topic"], Topic(c["topic"], c["type"], 0, "ros1", md5=c["md5"]))
            t.ids.append(cid)
            t.count += int(counts.get(cid, 0))
        return out

    def raw(self, topic: Topic) -> RawMessages:
        sel = np.isin(self.recs[:, 0], np.array(topic.ids, dtype=np.int64))
        r = self.recs[sel]
        rec_ns = r[:, 1] * 1_000_000_000 + r[:, 2]
        order = np.argsort(rec_ns, kind="stable")
        r = r[order]
        return RawMessages(self.buf, r[:, 3].copy(), r[:, 4].copy(), rec_ns[order], "ros1")
