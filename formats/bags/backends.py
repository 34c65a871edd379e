"""Which back-end reads a path: :func:`open_bag` returns an open :class:`~formats.bags.protocol.BagReader`.

``*.bag`` → ROS1. A ROS2 bag (a folder with ``metadata.yaml``, a folder holding one ``.db3``/``.mcap``, or such a
file itself) → the MCAP or sqlite3 back-end when the storage is uncompressed and readable by them, otherwise
rosbags' own reader. To add a back-end: a module implementing the protocol, and one branch here.
"""

from __future__ import annotations

import os
import sqlite3
import struct
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import ImutoolError
from .protocol import BagReader
from .ros1 import Ros1Bag
from .ros2_mcap import McapBag, McapUnsupported
from .ros2_rosbags import RosbagsBag
from .ros2_sqlite3 import Sqlite3Bag


def open_bag(path: str | os.PathLike) -> BagReader:
    """Open a ROS1 or ROS2 bag (use it as a context manager); ImutoolError if it is none."""
    path = os.fspath(path)
    p = Path(path)
    if not p.exists():
        raise ImutoolError("no such file or folder", path=path)
    if p.is_file() and p.suffix.lower() == ".bag":
        return Ros1Bag(path)
    if p.is_dir() and not (p / "metadata.yaml").exists():
        inner = sorted(list(p.glob("*.mcap")) + list(p.glob("*.db3")))
        if len(inner) == 1:
            return _open_ros2(os.fspath(inner[0]))
        raise ImutoolError("folder is not a ROS2 bag (no metadata.yaml)", path=path)
    return _open_ros2(path)


@dataclass
class Ros2Layout:
    """What a ROS2 bag's metadata says: storage ('sqlite3', 'mcap', 'unknown'), compression, storage files and
    messages per topic (None for a bare storage file)."""

    storage: str = "mcap"
    compressed: bool = False
    files: list[Path] = field(default_factory=list)
    counts: dict[str, int] | None = None

    @classmethod
    def of(cls, p: Path) -> Ros2Layout:
        if p.is_dir():
            try:
                from ruamel.yaml import YAML  # installed with rosbags; lazy as rosbags is

                info = YAML(typ="safe").load((p / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
                mode = info.get("compression_mode")
                counts: dict[str, int] = {}
                for t in info.get("topics_with_message_count") or []:
                    name = t["topic_metadata"]["name"]
                    counts[name] = counts.get(name, 0) + int(t["message_count"])
                return cls(
                    storage=str(info.get("storage_identifier", "mcap")),
                    compressed=bool(mode) and str(mode).lower() != "none",
                    files=[p / Path(f).name for f in info.get("relative_file_paths", [])],
                    counts=counts,
                )
            except Exception:
                return cls(storage="unknown")  # rosbags reports what is wrong
        if p.suffix == ".db3":
            return cls(storage="sqlite3", files=[p])
        return cls(storage="mcap", files=[p])


def _open_ros2(path: str) -> BagReader:
    lay = Ros2Layout.of(Path(path))
    readable = not lay.compressed and bool(lay.files) and all(f.is_file() for f in lay.files)
    if lay.storage == "mcap" and readable:
        try:
            return McapBag(path, lay.files)
        except (McapUnsupported, struct.error, ValueError, IndexError):
            pass  # rosbags reads it (or explains what is wrong)
    if lay.storage == "sqlite3" and readable:
        try:
            return Sqlite3Bag(path, lay.files, lay.counts)
        except sqlite3.DatabaseError:
            pass  # rosbags gives its own diagnosis
    return RosbagsBag(path, lay.storage)
