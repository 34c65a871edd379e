"""ROS2 sqlite3 back-end: rosbag2's ``.db3`` storage, rows read from the database pages by numba (else by SQL).

The page walk (:func:`sqlite_direct`) is taken for a single uncompressed ``.db3`` whose ``messages`` table has
rosbag2's schema, with no pending ``-wal`` file and no overflow pages; its row count is checked against
``SELECT count(*)``. Otherwise one SQL query per storage file yields the rows lazily. Compressed bags and other
serialisations are not read here: :func:`formats.bags.backends.open_bag` gives them to rosbags' reader.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from formats.jit.decorators import njit

from ..jit import cache as kernel_cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from .protocol import BagBackend, RawMessages, Topic, message_errors


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


def sqlite_direct(db: Path, topic_ids: list[int]) -> RawMessages | None:
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
    return RawMessages(buf, out[:, 3].copy(), out[:, 4].copy(), out[:, 2].copy(), "cdr")


class Sqlite3Bag(BagBackend):
    """rosbag2 sqlite3 storage: a bare ``.db3`` or the ``.db3`` files of a bag folder (uncompressed, CDR).

    path: the bag as the user named it; db_files: its storage files; counts: messages per topic from
    ``metadata.yaml`` (None: counted in the database). Opening raises sqlite3.DatabaseError on a storage this
    back-end cannot read (the caller then tries rosbags' reader, which gives its own diagnosis).
    """

    format = "ros2-sqlite3"

    def __init__(self, path: str, db_files: list[Path], counts: dict[str, int] | None):
        super().__init__()
        self.path = path
        self.db_files = db_files
        self._topics = self._db_topics(counts)

    def _db_topics(self, counts: dict[str, int] | None) -> dict[str, Topic]:
        out: dict[str, Topic] = {}
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
                t = out.setdefault(name, Topic(name, typ, 0, "cdr"))
                t.ids.append(tid)
                if counts is None:
                    t.count += int(n_by_id.get(tid, 0))
        if counts is not None:
            for name, t in out.items():
                t.count = counts.get(name, 0)
        return out

    def topics(self) -> dict[str, Topic]:
        return self._topics

    def raw(self, topic: Topic) -> RawMessages:
        if len(self.db_files) == 1 and topic.ids:
            with message_errors(self.path, topic.name):
                fast = sqlite_direct(self.db_files[0], [int(i) for i in topic.ids])
            if fast is not None:
                return fast
        return RawMessages.from_rows(list(self.messages(topic)), "cdr")

    def messages(self, topic: Topic) -> Iterator[tuple[int, bytes]]:
        """(timestamp ns, payload) by SQL, ordered by timestamp within each storage file."""
        with message_errors(self.path, topic.name):
            for db in self.db_files:
                con = sqlite3.connect(f"file:{db}?immutable=1", uri=True)
                try:
                    ids = [r[0] for r in con.execute("SELECT id FROM topics WHERE name = ?", (topic.name,))]
                    if ids:
                        q = (
                            "SELECT timestamp, data FROM messages WHERE topic_id IN "
                            f"({','.join('?' * len(ids))}) ORDER BY timestamp"
                        )
                        yield from con.execute(q, ids)
                finally:
                    con.close()
