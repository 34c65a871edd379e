"""imutool formats: the in-memory Recording and every reader/writer (CSV, ROS bags, NMEA 0183, bridge frames).

``read(path)`` and ``write(rec, path)`` dispatch on the file extension (a folder is a ROS2 bag).
Knows nothing of filters or the CLI.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

from .errors import ImutoolError
from .recording import Recording, TimeReport, merge, parse_mounting

__all__ = [
    "ImutoolError",
    "Recording",
    "TimeReport",
    "merge",
    "parse_mounting",
    "read",
    "write",
    "kind_of",
    "iter_chunks",
]

BAG_EXT = {".bag": "ros1", ".db3": "ros2", ".mcap": "ros2"}
NMEA_EXT = {".nmea", ".log", ".txt", ".nmea0183"}
PARQUET_EXT = {".parquet", ".pq"}


def kind_of(path: str | os.PathLike, for_output: bool = False) -> str:
    """'csv', 'parquet', 'ros1', 'ros2' or 'nmea' from the path (a folder holding metadata.yaml is a ROS2 bag)."""
    p = Path(path)
    ext = p.suffix.lower()
    if ext == ".csv":
        return "csv"
    if ext in PARQUET_EXT:
        return "parquet"
    if ext in BAG_EXT:
        return BAG_EXT[ext]
    if ext in NMEA_EXT:
        return "nmea"
    if p.is_dir() or (for_output and ext == ""):
        return "ros2"
    raise ImutoolError(
        f"cannot tell the format from the name {os.fspath(path)!r}; use .csv, .parquet, .bag (ROS1), .db3/.mcap or a "
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

        rec = read_csv(path, **options)
        rec.restore_streams()  # a many-clock recording written by imutool: its streams from meta['streams']
        return rec
    if kind == "parquet":
        from .parquet import read_parquet

        rec = read_parquet(path, **options)
        rec.restore_streams()
        return rec
    if kind in ("ros1", "ros2"):
        from .bags import read_bag

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
    if kind == "parquet":
        from .parquet import write_parquet

        return write_parquet(rec, path, **options)
    if kind in ("ros1", "ros2"):
        from .bags import write_bag

        return write_bag(rec, path, **options)
    from .nmea import write_nmea

    return write_nmea(rec, path, **options)


def iter_chunks(path: str | os.PathLike, chunk_rows: int = 500_000, **options) -> Iterator[Recording]:
    """Stream a CSV or Parquet file as Recordings of at most ``chunk_rows`` rows (bounded memory).

    CSV options (``columns``, ``profile``, ``prefetch``...) go to :func:`formats.csv.iter_csv`; Parquet is read
    row group by row group (:func:`formats.parquet.iter_parquet`). Other formats are read whole and sliced.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise ImutoolError("no such file", path=path)
    kind = kind_of(path)
    if kind == "csv":
        from .csv import iter_csv

        return _restored(iter_csv(path, chunk_rows=chunk_rows, **options))
    if kind == "parquet":
        from .parquet import iter_parquet

        return _restored(iter_parquet(path, chunk_rows=chunk_rows))
    rec = read(path, **options)
    return (rec.select(slice(i, i + chunk_rows)) for i in range(0, len(rec), chunk_rows))


def _restored(chunks: Iterator[Recording]) -> Iterator[Recording]:
    """Each chunk of a many-clock file with its streams' rows (:meth:`Recording.restore_streams`)."""
    for chunk in chunks:
        chunk.restore_streams()
        yield chunk
