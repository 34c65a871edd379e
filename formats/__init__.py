"""imutool formats: the in-memory Recording and every reader/writer (CSV, ROS bags, NMEA 0183, bridge frames).

``read(path)`` and ``write(rec, path)`` dispatch on the file extension (a folder is a ROS2 bag).
Knows nothing of filters or the CLI.
"""

from __future__ import annotations

import os
from pathlib import Path

from .errors import ImutoolError
from .recording import Recording, TimeReport, merge, parse_mounting

__all__ = ["ImutoolError", "Recording", "TimeReport", "merge", "parse_mounting", "read", "write", "kind_of"]

BAG_EXT = {".bag": "ros1", ".db3": "ros2", ".mcap": "ros2"}
NMEA_EXT = {".nmea", ".log", ".txt", ".nmea0183"}


def kind_of(path: str | os.PathLike, for_output: bool = False) -> str:
    """'csv', 'ros1', 'ros2' or 'nmea' from the path (a folder holding metadata.yaml is a ROS2 bag)."""
    p = Path(path)
    ext = p.suffix.lower()
    if ext == ".csv":
        return "csv"
    if ext in BAG_EXT:
        return BAG_EXT[ext]
    if ext in NMEA_EXT:
        return "nmea"
    if p.is_dir() or (for_output and ext == ""):
        return "ros2"
    raise ImutoolError(
        f"cannot tell the format from the name {os.fspath(path)!r}; use .csv, .bag (ROS1), .db3/.mcap or a "
        "folder (ROS2), or .nmea/.log (NMEA 0183)"
    )


def read(path: str | os.PathLike, **options) -> Recording:
    """Read any supported file into a Recording (options go to the format's reader)."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise ImutoolError("no such file", path=path)
    kind = kind_of(path)
    if kind == "csv":
        from .csv import read_csv

        return read_csv(path, **options)
    if kind in ("ros1", "ros2"):
        from .rosbag import read_bag

        return read_bag(path, **options)
    from .nmea import read_nmea

    return read_nmea(path, **options)


def write(rec: Recording, path: str | os.PathLike, **options) -> None:
    """Write a Recording; the format follows the output name's extension (atomic: temp file + rename)."""
    path = os.fspath(path)
    kind = kind_of(path, for_output=True)
    if kind == "csv":
        from .csv import write_csv

        return write_csv(rec, path, **options)
    if kind in ("ros1", "ros2"):
        from .rosbag import write_bag

        return write_bag(rec, path, **options)
    from .nmea import write_nmea

    return write_nmea(rec, path, **options)
