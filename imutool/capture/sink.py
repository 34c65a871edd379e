"""Durable, incremental capture output: an imutool CSV (and a raw log) that a power cut cannot corrupt.

Rows are appended as whole lines and flushed after every batch; ``os.fsync`` runs at most every
``fsync_interval`` seconds (default 1 s), so a power cut loses at most the last second. Files are readable by
every other command while the capture runs (the CSV reader skips a partial last line and counts it).
Rotation starts a new file every ``rotate_s`` seconds (name suffix ``_YYYYmmddTHHMMSSZ``). A clean stop
appends a ``# capture_end: ...`` comment line with the counts. Disk full raises :class:`DiskFull`.
"""

from __future__ import annotations

import errno
import json
import os
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from formats.csv import MAGIC, format_array
from formats.errors import ImutoolError


class DiskFull(ImutoolError):
    """The output device is full (ENOSPC) or over quota."""


def utc_stamp(t: float | None = None) -> str:
    return datetime.fromtimestamp(time.time() if t is None else t, tz=timezone.utc).strftime("%Y%m%dT%H%M%SZ")


class RotatingFile:
    """An append-only text file with periodic fsync and time-based rotation.

    ``header`` is written at the top of every new file. ``append=True`` continues an existing file (after
    cutting a partial last line left by a crash; the cut is reported in ``truncated_bytes``).
    """

    def __init__(
        self,
        path: str | os.PathLike,
        header: str = "",
        rotate_s: float | None = None,
        fsync_interval: float = 1.0,
        append: bool = False,
        overwrite: bool = False,
    ):
        self.base = Path(path)
        self.header = header
        self.rotate_s = rotate_s
        self.fsync_interval = fsync_interval
        self.append = append
        self.overwrite = overwrite
        self.files: list[str] = []
        self.bytes_written = 0
        self.truncated_bytes = 0
        self._f = None
        self._opened_at = 0.0
        self._last_sync = 0.0
        self._open_new()

    @property
    def current(self) -> str:
        return self.files[-1]

    def _name_for_now(self) -> Path:
        if self.rotate_s:
            return self.base.with_name(f"{self.base.stem}_{utc_stamp()}{self.base.suffix}")
        return self.base

    def _open_new(self) -> None:
        p = self._name_for_now()
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
            if p.exists() and self.append:
                self._cut_partial_line(p)
                self._f = open(p, "a", encoding="utf-8", newline="\n")
                if p.stat().st_size == 0:
                    self._f.write(self.header)
            else:
                if p.exists() and not self.overwrite and not self.rotate_s:
                    raise ImutoolError("exists; use --append to continue it or --force to replace it", path=str(p))
                self._f = open(p, "w", encoding="utf-8", newline="\n")
                self._f.write(self.header)
            self._f.flush()
        except OSError as e:
            self._raise(e, p)
        self.files.append(str(p))
        self._opened_at = time.monotonic()
        self._last_sync = self._opened_at

    def _cut_partial_line(self, p: Path) -> None:
        with open(p, "rb+") as f:
            size = f.seek(0, os.SEEK_END)
            if size == 0:
                return
            pos = size
            while pos > 0:
                step = min(4096, pos)
                f.seek(pos - step)
                chunk = f.read(step)
                nl = chunk.rfind(b"\n")
                if nl >= 0:
                    keep = pos - step + nl + 1
                    if keep < size:
                        f.truncate(keep)
                        self.truncated_bytes += size - keep
                    return
                pos -= step
            f.truncate(0)
            self.truncated_bytes += size

    @staticmethod
    def _raise(e: OSError, p: Path) -> None:
        if e.errno in (errno.ENOSPC, errno.EDQUOT):
            raise DiskFull(
                "disk full: capture stopped; everything up to the last complete line is kept", path=str(p)
            ) from None
        raise ImutoolError(f"cannot write: {e.strerror}", path=str(p)) from None

    def write(self, text: str) -> None:
        """Append whole lines; flush; fsync when the interval has passed; rotate when due."""
        if not text:
            return
        assert self._f is not None
        try:
            self._f.write(text)
            self._f.flush()
            now = time.monotonic()
            if now - self._last_sync >= self.fsync_interval:
                os.fsync(self._f.fileno())
                self._last_sync = now
        except OSError as e:
            self._raise(e, Path(self.current))
        self.bytes_written += len(text)
        if self.rotate_s and time.monotonic() - self._opened_at >= self.rotate_s:
            self.close()
            self._open_new()

    def close(self, trailer: str = "") -> None:
        if self._f is None:
            return
        try:
            if trailer:
                self._f.write(trailer)
            self._f.flush()
            os.fsync(self._f.fileno())
        except OSError as e:
            self._raise(e, Path(self.current))
        finally:
            self._f.close()
            self._f = None


def csv_header(columns: list[str], meta: dict) -> str:
    lines = [MAGIC] + [f"# {k}: {v}" for k, v in meta.items()]
    return "\n".join(lines) + "\n" + ",".join(columns) + "\n"


class CaptureCsv:
    """imutool CSV written row by row (columns fixed at start), durable and rotating."""

    def __init__(self, path: str | os.PathLike, columns: list[str], meta: dict, array_rows: bool = True, **kw):
        """``array_rows``: rows will come as float arrays (:meth:`write_rows`), so the compiled formatter is loaded
        now, before any data is waiting; False when the caller writes ready text lines (:meth:`write_lines`)."""
        if array_rows:
            format_array(np.zeros((1, len(columns))))
        self.columns = columns
        self.rows = 0
        self.file = RotatingFile(path, csv_header(columns, meta), **kw)

    def write_lines(self, text: str, n_rows: int) -> None:
        """Append ``n_rows`` complete CSV lines already formatted (``text`` ends with a newline)."""
        self.file.write(text)
        self.rows += n_rows

    def write_rows(self, data: np.ndarray) -> None:
        """data: (n, len(columns)) floats; NaN written as an empty field."""
        if len(data) == 0:
            return
        self.file.write(format_array(np.asarray(data, dtype=float)).decode("ascii"))
        self.rows += len(data)

    def close(self, summary: dict | None = None) -> None:
        trailer = ""
        if summary is not None:
            items = ", ".join(f"{k}={v}" for k, v in summary.items())
            trailer = f"# capture_end: {datetime.now(timezone.utc).isoformat(timespec='seconds')} {items}\n"
        self.file.close(trailer)


def last_complete_row(path: str | os.PathLike) -> list[str] | None:
    """The last complete data row (fields) of a CSV, skipping comment lines; None if there is none."""
    p = Path(path)
    if not p.exists():
        return None
    with open(p, "rb") as f:
        size = f.seek(0, os.SEEK_END)
        f.seek(max(0, size - 65536))
        tail = f.read().split(b"\n")
    for line in reversed(tail[:-1]):  # the piece after the last newline is incomplete (or empty)
        text = line.decode("utf-8", "replace").strip()
        if text and not text.startswith("#") and not text.startswith("time,"):
            return text.split(",")
    return None


class EventLog:
    """JSON-lines log of capture events (port lost/reopened, sequence gaps, restarts), flushed per event."""

    def __init__(self, path: str | os.PathLike, append: bool = True):
        self.file = RotatingFile(path, "", append=append, overwrite=not append, fsync_interval=0.0)

    def add(self, event: str, **fields) -> None:

        rec = {
            "utc": datetime.now(timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z"),
            "event": event,
            **fields,
        }
        self.file.write(json.dumps(rec) + "\n")

    def close(self) -> None:
        self.file.close()
