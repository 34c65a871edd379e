"""Streamed conversion between the chunked formats (imutool CSV and Parquet) in bounded memory.

:func:`stream_convert` is the library route behind ``imutool convert`` for CSV/Parquet → CSV/Parquet: the input is
read chunk by chunk (:func:`formats.iter_chunks`), each chunk validated (plus a check across chunk boundaries),
calibrated and mounted if asked, and appended to an atomic writer (CSV or Parquet by the output's extension).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator
from typing import Any

import numpy as np

import formats
from formats import Recording
from formats.errors import ImutoolError

STREAMABLE = ("csv", "parquet")


def chunk_writer(path: str | os.PathLike) -> Any:
    """An atomic incremental writer (``with w: w.write(chunk)``; ``w.rows``) for a .csv or .parquet output."""
    kind = formats.kind_of(path, for_output=True)
    if kind == "csv":
        from formats.csv import CsvWriter

        return CsvWriter(os.fspath(path))
    if kind == "parquet":
        from formats.parquet import ParquetWriter

        return ParquetWriter(os.fspath(path))
    raise ImutoolError(f"streamed output must be .csv or .parquet (got {formats.kind_of(path, True)})",
                       path=os.fspath(path))


def stream_convert(src: str, dst: str, *, chunk_rows: int = 500_000, columns: str | None = None,
                   profile: str | None = None, duplicates: str = "drop", backwards: str = "error",
                   mounting: str | None = None, calibration_file: str | None = None,
                   progress: Callable[[Iterable[Recording]], Iterator[Recording]] | None = None) -> dict[str, Any]:
    """Convert ``src`` to ``dst`` (CSV or Parquet each) chunk by chunk; returns the summary dict.

    Validation is per chunk plus a check across chunk boundaries (a time not after the previous chunk's last
    one is dropped, or refused with ``backwards='error'``/``duplicates='error'``); streaming cannot sort.
    """
    if os.path.abspath(src) == os.path.abspath(dst):
        raise ImutoolError("output would overwrite the input", path=dst)
    cal = None
    if calibration_file:
        from calibration import load_calibration

        cal = load_calibration(calibration_file)
    mount = formats.parse_mounting(mounting) if mounting else None
    opts: dict[str, Any] = {"columns": columns, "profile": profile} if formats.kind_of(src) == "csv" else {}
    chunks: Iterable[Recording] = formats.iter_chunks(src, chunk_rows=chunk_rows, **opts)
    if progress is not None:
        chunks = progress(chunks)
    rows_in = 0
    dropped_boundary = 0
    actions: list[str] = []
    channels: list[str] = []
    last_t = -np.inf
    with chunk_writer(dst) as w:
        for chunk in chunks:
            rows_in += len(chunk)
            if len(chunk) and chunk.time[0] <= last_t:
                early = chunk.time <= last_t
                back = chunk.time < last_t
                if back.any() and backwards != "drop":
                    raise ImutoolError(f"time goes backwards across a chunk boundary (row ≈ {rows_in - len(chunk) + 1}"
                                       f"); streaming cannot sort: use --backwards drop or --no-stream", path=src)
                if (early & ~back).any() and duplicates == "error":
                    raise ImutoolError("duplicate timestamp across a chunk boundary", path=src)
                dropped_boundary += int(early.sum())
                chunk = chunk.select(~early)
            if len(chunk) == 0:
                continue
            chunk, rep = chunk.validated(duplicates=duplicates, backwards="error" if backwards == "sort"
                                         else backwards, source=src)
            actions += rep.actions
            if cal is not None:
                chunk = cal.apply(chunk)
            if mount is not None:
                chunk = chunk.mounted(*mount)
            last_t = float(chunk.time[-1])
            channels = list(chunk.channels)
            w.write(chunk)
        if rows_in == 0:
            raise ImutoolError("no data rows", path=src)
        rows_out = w.rows
    if dropped_boundary:
        actions.append(f"dropped {dropped_boundary} rows at chunk boundaries (time not after the previous chunk)")
    return {"rows_in": rows_in, "rows_out": rows_out, "channels": channels, "streamed": True,
            "validation_actions": actions}
