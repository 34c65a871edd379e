"""ROS2 MCAP back-end: chunks decompressed (none, lz4 or zstd with rosbags' decompressors), records scanned by numba.

Reads chunked MCAP files with CDR messages (one file, or every file of a bag folder). Anything else — messages
outside chunks, another message encoding, an unknown chunk compression — raises :class:`McapUnsupported` when
opened, and :func:`formats.bags.backends.open_bag` hands the bag to rosbags' reader instead. A file cut short is
read up to its last complete chunk (``truncated``).
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from formats.jit.decorators import njit

from ..jit import cache as kernel_cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from .decode import u32
from .protocol import BagBackend, RawMessages, Topic, count_by_id


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
            ln = u32(buf, p + 1) | (u32(buf, p + 5) << 32)
            c = p + 9
            if ln < 0 or c + ln > n:
                bad[si] = 1
                break
            if op == 5 and ln >= 22:
                if fill:
                    out[k, 0] = np.int64(buf[c]) | (np.int64(buf[c + 1]) << 8)
                    out[k, 1] = u32(buf, c + 6) | (u32(buf, c + 10) << 32)
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


class McapUnsupported(Exception):
    """This MCAP file needs rosbags' general reader (raised while opening, never to the user)."""


def _mcap_str(b: bytes | memoryview, p: int) -> tuple[str, int]:
    (n,) = struct.unpack_from("<I", b, p)
    return bytes(b[p + 4 : p + 4 + n]).decode("utf-8", "replace"), p + 4 + n


class McapBag(BagBackend):
    """Fast MCAP reader: chunks decompressed, records scanned by a numba kernel (ROS2 CDR messages).

    path: the bag as the user named it (folder or file); files: its MCAP storage files.
    """

    MAGIC = b"\x89MCAP0\r\n"
    format = "ros2-mcap"

    def __init__(self, path: str, files: list[Path]):
        super().__init__()
        self.path = path
        self.buf = np.empty(0, np.uint8)
        self.recs = np.empty((0, 5), np.int64)
        self.schemas: dict[tuple[int, int], str] = {}
        self.channels: dict[tuple[int, int], tuple[str, int, str]] = {}
        self._scan(files)
        self._topics = self._channel_topics()

    def _scan(self, files: list[Path]) -> None:
        from rosbags.rosbag2.storage_mcap import DECOMPRESSORS  # lazy, as every rosbags import here

        chunks: list[bytes] = []
        chunk_file: list[int] = []
        for fi, f in enumerate(files):
            data = np.fromfile(f, dtype=np.uint8)
            if data[:8].tobytes() != self.MAGIC:
                raise McapUnsupported("no MCAP magic")
            bounds = np.array([[8, data.shape[0]]], np.int64)
            bad = np.zeros(1, np.int64)
            k, j = _scan_mcap(data, bounds, np.empty((0, 5), np.int64), np.empty((0, 4), np.int64), bad, False)
            if k:
                raise McapUnsupported("messages outside chunks")
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
                        raise McapUnsupported(f"chunk compression {comp!r}")
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

    def topics(self) -> dict[str, Topic]:
        return self._topics

    def _channel_topics(self) -> dict[str, Topic]:
        counts = count_by_id(self.recs[:, 0])
        out: dict[str, Topic] = {}
        for (fi, cid), (topic, sid, enc) in self.channels.items():
            if enc != "cdr":
                raise McapUnsupported(f"message encoding {enc!r}")
            typ = self.schemas.get((fi, sid), "")
            t = out.setdefault(topic, Topic(topic, typ, 0, "cdr"))
            key = (fi << 16) | cid
            t.ids.append(key)
            t.count += int(counts.get(key, 0))
        return out

    def raw(self, topic: Topic) -> RawMessages:
        r = self.recs[np.isin(self.recs[:, 0], np.array(topic.ids, dtype=np.int64))]
        order = np.argsort(r[:, 1], kind="stable")
        r = r[order]
        return RawMessages(self.buf, r[:, 2].copy(), r[:, 3].copy(), r[:, 1].copy(), "cdr")
