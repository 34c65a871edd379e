"""The one reader protocol every bag back-end implements, and the message types imutool reads.

A back-end is a context manager that lists its topics when opened and hands out a topic's messages on request:
``raw(topic)`` gives all payloads at once as one byte buffer with offsets (what the fast numpy decoder wants),
``messages(topic)`` yields ``(record time ns, payload bytes)`` one at a time (lazy). A back-end implements
whichever of the two is natural for its storage; :class:`BagBackend` derives the other. See ``docs/bags.md``,
"Where to add a bag back-end".
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from operator import itemgetter
from typing import Any, Protocol, runtime_checkable

import numpy as np

from ..errors import ImutoolError

IMU = "sensor_msgs/msg/Imu"
MAG = "sensor_msgs/msg/MagneticField"
VEC3 = "geometry_msgs/msg/Vector3Stamped"
KIND = {IMU: "imu", MAG: "mag", VEC3: "vec3"}


def norm_type(t: str) -> str:
    """'sensor_msgs/Imu' (ROS1) → 'sensor_msgs/msg/Imu'."""
    parts = t.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return t


@dataclass
class Topic:
    """One topic of a bag: its message type, message count, payload format ('ros1' or 'cdr') and the back-end's
    own keys for it (connection ids, channel keys, topic ids or rosbags connections)."""

    name: str
    msgtype: str
    count: int
    fmt: str
    ids: list[Any] = field(default_factory=list)
    md5: str = ""  # ROS1 message definition md5 ('' for ROS2)


@dataclass
class RawMessages:
    """Concatenated raw payloads of one topic in record-time order: message i is buf[offs[i]: offs[i] + lens[i]],
    recorded at rec_ns[i] (int64 ns); fmt 'ros1' or 'cdr'."""

    buf: np.ndarray
    offs: np.ndarray
    lens: np.ndarray
    rec_ns: np.ndarray
    fmt: str

    @classmethod
    def from_rows(cls, rows: list[tuple[int, bytes]], fmt: str) -> RawMessages:
        """From (record time ns, payload) pairs, kept in their order."""
        rec_ns = np.fromiter(map(itemgetter(0), rows), dtype=np.int64, count=len(rows))
        datas = list(map(itemgetter(1), rows))
        lens = np.fromiter(map(len, datas), dtype=np.int64, count=len(datas))
        offs = np.zeros(len(datas), np.int64)
        if len(datas) > 1:
            np.cumsum(lens[:-1], out=offs[1:])
        buf = np.frombuffer(b"".join(datas), dtype=np.uint8) if datas else np.empty(0, np.uint8)
        return cls(buf, offs, lens, rec_ns, fmt)

    def rows(self) -> Iterator[tuple[int, bytes]]:
        """(record time ns, payload bytes), one message at a time."""
        for o, n, t in zip(self.offs.tolist(), self.lens.tolist(), self.rec_ns.tolist(), strict=True):
            yield t, self.buf[o : o + n].tobytes()


@runtime_checkable
class BagReader(Protocol):
    """What :func:`formats.bags.read_bag` needs of a back-end.

    format: 'ros1', 'ros2-sqlite3', 'ros2-mcap' (or 'ros2-<storage>' as the bag's metadata names it);
    truncated: the file was cut short and only complete chunks were read; notes: one-line remarks for the
    recording's metadata (damaged chunks, dropped bytes).
    """

    path: str
    format: str
    truncated: bool
    notes: list[str]

    def topics(self) -> dict[str, Topic]: ...

    def raw(self, topic: Topic) -> RawMessages: ...

    def messages(self, topic: Topic) -> Iterator[tuple[int, bytes]]: ...

    def close(self) -> None: ...

    def __enter__(self) -> BagReader: ...

    def __exit__(self, *exc: object) -> None: ...


class BagBackend:
    """Shared part of the back-ends: context manager, no-op close, and each of raw()/messages() from the other.

    A subclass overrides at least one of :meth:`raw` (bulk, for storages read whole into memory) and
    :meth:`messages` (lazy, for storages read through a query or another library).
    """

    path: str = ""
    format: str = ""
    fmt: str = "cdr"  # payload serialisation of every topic: 'ros1' or 'cdr'

    def __init__(self) -> None:
        self.truncated = False
        self.notes: list[str] = []

    def topics(self) -> dict[str, Topic]:
        raise NotImplementedError

    def raw(self, topic: Topic) -> RawMessages:
        if type(self).messages is BagBackend.messages:
            raise NotImplementedError(f"{type(self).__name__} implements neither raw() nor messages()")
        return RawMessages.from_rows(list(self.messages(topic)), self.fmt)

    def messages(self, topic: Topic) -> Iterator[tuple[int, bytes]]:
        if type(self).raw is BagBackend.raw:
            raise NotImplementedError(f"{type(self).__name__} implements neither raw() nor messages()")
        yield from self.raw(topic).rows()

    def close(self) -> None:
        return None

    def __enter__(self) -> BagBackend:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@contextmanager
def message_errors(path: str, topic: str) -> Iterator[None]:
    """Turn a storage failure while reading a topic's messages into one ImutoolError line."""
    try:
        yield
    except sqlite3.DatabaseError as exc:
        raise ImutoolError(f"ROS2 sqlite3 storage is damaged: {exc}", path=path) from None
    except ImutoolError:
        raise
    except Exception as exc:
        raise ImutoolError(f"cannot read messages of {topic}: {exc}", path=path) from None


def count_by_id(ids: Iterable[int] | np.ndarray) -> dict[int, int]:
    """Messages per back-end key (connection/channel id)."""
    ids = np.asarray(ids)
    return dict(zip(*np.unique(ids, return_counts=True), strict=True)) if ids.size else {}
