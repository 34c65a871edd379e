"""ROS2 bags the fast back-ends do not read, through rosbags' own reader: compressed bags (zstd file or message
mode), MCAP with messages outside chunks, other serialisations, multi-file layouts rosbags knows. Slower (one
message at a time) but general; it also gives rosbags' diagnosis of a damaged or unknown storage.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..errors import ImutoolError
from .protocol import BagBackend, Topic, message_errors


class RosbagsBag(BagBackend):
    """rosbags.rosbag2.Reader behind the protocol; messages are yielded lazily as rosbags reads them.

    path: a bag folder or a bare storage file; storage: the storage named by its metadata ('sqlite3', 'mcap',
    or 'unknown' when metadata.yaml could not be read), used only for ``format``.
    """

    def __init__(self, path: str, storage: str):
        super().__init__()
        from rosbags.rosbag2 import Reader  # lazy: rosbags is heavy and only this fallback needs its reader

        self.path = path
        self.format = f"ros2-{storage}"
        self.reader: Any = None
        try:
            self.reader = Reader(Path(path))
            self.reader.open()
        except Exception as exc:
            raise ImutoolError(f"cannot open ROS2 bag: {exc}", path=path) from None

    def topics(self) -> dict[str, Topic]:
        out: dict[str, Topic] = {}
        for c in self.reader.connections:
            t = out.setdefault(c.topic, Topic(c.topic, c.msgtype, 0, "cdr"))
            t.ids.append(c)
            t.count += int(c.msgcount)
        return out

    def messages(self, topic: Topic) -> Iterator[tuple[int, bytes]]:
        with message_errors(self.path, topic.name):
            for _, ts, raw in self.reader.messages(connections=topic.ids):
                yield ts, raw

    def close(self) -> None:
        try:
            if self.reader is not None:
                self.reader.close()
        except Exception:
            pass
