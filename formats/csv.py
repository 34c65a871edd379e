"""imutool CSV and foreign CSV: read (whole or streamed in chunks) and write (atomic).

imutool CSV (docs/formats.md)::

    # imutool-csv: 1
    # key: value                   (metadata: sensor, rate_hz, frame, mounting, source, units, ...)
    time,gyro_x,gyro_y,gyro_z,...

Canonical columns carry canonical units (time s, gyro rad/s, accel m/s², mag µT, angles deg, heave m up).
Other channels' units are listed in the ``# units:`` line (``name=unit, ...``). Empty field or ``nan`` =
missing. A foreign CSV (any header) is read through a :class:`formats.columns.Mapping`.
"""

from __future__ import annotations

import csv as _csvmod
import io
import json
import os
import queue
import shutil
import sys
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import csv_engine as _eng
from . import units as _units
from .atomic import AtomicChunkWriter, atomic_path
from .columns import (
    Mapping,
    _unit_in,
    clean_name,
    infer_mapping,
    load_profile,
    mapping_from_profile,
    parse_mapping_option,
    resolve_unit,
)
from .errors import ImutoolError
from .jit.threads import thread_budget
from .recording import Recording, canonical_unit, group_columns

MAGIC = "# imutool-csv: 1"


@dataclass
class CsvHeader:
    """What precedes the data rows."""

    is_imutool: bool
    meta: dict[str, Any]
    names: list[str]
    data_line: int  # 1-based line number of the first data row
    mapping: Mapping | None = None
    skipped_comment_lines: int = 0
    data_offset: int = 0  # byte offset of the first data row
    sep: str = ","
    decimal: str = "."
    rate_hz: float | None = None  # a file without a time column: time = n / rate_hz


@dataclass
class ReadReport:
    bad_rows: int = 0
    first_bad: list[str] = field(default_factory=list)


def _parse_meta_value(v: str) -> Any:
    v = v.strip()
    if v[:1] in "[{":
        try:
            return json.loads(v)
        except ValueError:
            return v
    return v


def _split_header(line: str, sep: str) -> list[str]:
    """Header names, honouring double quotes (``"Time (s)","Gyro X"``)."""
    try:
        row = next(_csvmod.reader([line], delimiter=sep, skipinitialspace=True))
    except (_csvmod.Error, StopIteration):
        row = line.split(sep)
    return [h.strip().strip('"').strip() for h in row]


def read_header(
    path: str,
    columns: str | None = None,
    profile: str | None = None,
    *,
    rate_hz: float | None = None,
    time_column: str | None = None,
    header_rows: int | None = None,
) -> CsvHeader:
    """Read metadata and column names; infer or apply the column mapping for a foreign CSV.

    Handles a UTF-8 BOM, CRLF line ends, ``,``/``;``/tab separators (``;`` with decimal commas too) and
    quoted header names. Records the byte offset of the first data row for the compiled reader.

    ``header_rows`` (default 1, or the profile's ``header_rows``): rows of column headings; the first names the
    columns, a later one may give their units (RepoIMU: ``s;;;;;m/s^2;...``) — a cell that is a known unit is
    used where the name states none. ``time_column`` ``NAME[:UNIT]`` (s, ms, us, ns; default the unit in the
    name, else s; or the profile's ``time_column``/``time_unit``): the column that holds the time.
    ``rate_hz`` (or the profile's ``rate_hz``): a file without a time column gets ``time = n / rate`` (n the data
    row from 0), recorded in the metadata.
    """
    prof = load_profile(profile) if profile else {}
    rows_given = header_rows is not None or prof.get("header_rows") is not None
    header_rows = _header_rows(header_rows if header_rows is not None else prof.get("header_rows", 1), profile)
    if rate_hz is None and prof.get("rate_hz") is not None:
        rate_hz = prof["rate_hz"]
    if rate_hz is not None:
        try:
            rate_hz = float(rate_hz)
        except (TypeError, ValueError):
            rate_hz = float("nan")
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise ImutoolError(f"the sample rate must be a positive number of Hz, got {rate_hz!r}", path=path)
    if time_column is None and prof.get("time_column"):
        time_column = str(prof["time_column"]) + (f":{prof['time_unit']}" if prof.get("time_unit") else "")
    try:
        f = open(path, "rb")
    except OSError as e:
        raise ImutoolError(f"cannot open: {e.strerror}", path=path) from None
    with f:
        meta: dict[str, Any] = {}
        is_imutool = False
        lineno = 0
        comments = 0
        heading: list[tuple[str, int]] = []  # (text, line number) of the header rows
        offset = 0
        first_data = b""
        for raw in f:
            lineno += 1
            offset += len(raw)
            if lineno == 1 and raw.startswith(b"\xef\xbb\xbf"):
                raw = raw[3:]
            try:
                line = raw.decode("utf-8").strip()
            except UnicodeDecodeError:  # e.g. a Latin-1 "°/s" from a Windows logger
                line = raw.decode("latin-1").strip()
            if not line:
                continue
            if line.startswith("#"):
                if heading:  # a comment between header rows
                    continue
                comments += 1
                if line.startswith("# imutool-csv:"):
                    is_imutool = True
                    continue
                body = line[1:].strip()
                if ":" in body:
                    k, _, v = body.partition(":")
                    meta[k.strip()] = _parse_meta_value(v)
                continue
            heading.append((line, lineno))
            if len(heading) == 1 and header_rows == 1 and not rows_given and _has_blank_cells(line):
                header_rows = 2  # a row of group names with blank cells: the axis row follows (module doc)
            if len(heading) < header_rows:
                continue
            for nxt in f:
                if nxt.strip() and not nxt.lstrip().startswith(b"#"):
                    first_data = nxt
                    break
            break
    if not heading:
        raise ImutoolError("no header row (the file is empty or has only comments)", path=path)
    if len(heading) < header_rows:
        raise ImutoolError(f"--header-rows {header_rows}: the file has only {len(heading)} row(s)", path=path)
    header_line, lineno = heading[0]
    printable = sum(ch.isprintable() or ch == "\t" for ch in header_line)
    if "\x00" in header_line or printable < 0.9 * len(header_line):
        raise ImutoolError("the header row is not text (binary file?)", path=path, line=lineno)
    if "," in header_line:
        sep = ","
    elif ";" in header_line:
        sep = ";"
    elif "\t" in header_line:
        sep = "\t"
    else:
        sep = ","
    decimal = "."
    if sep == ";" and b"," in first_data and b"." not in first_data:
        decimal = ","
    names = _split_header(header_line, sep)
    grouped = False
    if len(heading) == 2 and any(not n for n in names):
        combined = _group_names(names, _split_header(heading[1][0], sep))
        if combined is not None:
            names, grouped = combined, True
    if any(not n for n in names):
        raise ImutoolError("the header row has an empty column name", path=path, line=lineno)
    if len(set(names)) < len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise ImutoolError(
            f"the header row names {', '.join(map(repr, twice))} more than once: which one is meant? "
            "rename or remove the extra column",
            path=path,
            line=lineno,
        )
    if _looks_numeric(names):
        raise ImutoolError("the first row is numbers, not column names; add a header row", path=path, line=lineno)
    unit_row = _unit_row(heading[2 if grouped else 1 :], names, sep, path)
    lineno = heading[-1][1]
    mapping = None
    if not is_imutool or columns or profile or time_column or unit_row:
        if profile:
            mapping = mapping_from_profile(prof, names, profile)
        elif columns:
            mapping = parse_mapping_option(columns, names)
        else:
            mapping = infer_mapping(names)
        if unit_row:
            _apply_unit_row(mapping, unit_row, path)
        if time_column:
            _apply_time_column(mapping, time_column, names, path)
    elif "time" not in names and rate_hz is None:
        raise ImutoolError("imutool CSV without a 'time' column", path=path, line=lineno)
    hdr = CsvHeader(is_imutool, meta, names, lineno + 1, mapping, comments, offset, sep, decimal)
    hdr.meta["_sep"] = sep
    hdr.rate_hz = rate_hz
    if header_rows > 1:
        hdr.meta["source_header_rows"] = header_rows
    if grouped:
        hdr.meta["source_header"] = "group names (blanks carried forward) + axis row"
    targets = [c.target for c in mapping.columns] if mapping is not None else names
    if rate_hz is not None and "time" in targets:
        src = mapping.columns[targets.index("time")].source if mapping is not None else "time"
        raise ImutoolError(
            f"--rate is for a file without a time column; this one has {src!r} (name another with --time-column)",
            path=path,
        )
    return hdr


def _has_blank_cells(line: str) -> bool:
    """A header row with an empty cell between or after names (``Time;Orientation;;;;Accelerometer;;;``)."""
    sep = "," if "," in line else (";" if ";" in line else ("\t" if "\t" in line else ","))
    cells = _split_header(line, sep)
    return len(cells) > 1 and bool(cells[0]) and any(not c for c in cells)


def _group_names(groups: list[str], axes: list[str]) -> list[str] | None:
    """Column names of a two-row header: a row of group names whose blank cells continue the group to their
    left (``Time (s);Vicon Orientation;;;;IMU Acceleration;;;...``), then a row of axis labels
    (``;W;X;Y;Z;X;Y;Z;...``): ``Time (s)``, ``Vicon Orientation W``, ..., ``IMU Acceleration X``. Trailing cells
    empty in both rows (a trailing separator) are dropped. None when the second row is not such a row (numbers,
    or a blank group name over a blank axis)."""
    n = max(len(groups), len(axes))
    groups = groups + [""] * (n - len(groups))
    axes = axes + [""] * (n - len(axes))
    while n and not groups[n - 1] and not axes[n - 1]:
        n -= 1
    if n < 2 or _looks_numeric([a for a in axes[:n] if a] or ["x"]):
        return None
    out: list[str] = []
    group = ""
    for g, a in zip(groups[:n], axes[:n], strict=True):
        if g:
            group = g
        if not group and not a:
            return None
        out.append(f"{group} {a}".strip() if a else group)
    return out


def _header_rows(n: Any, profile: str | None) -> int:
    """The number of header rows, checked (an integer ≥ 1)."""
    try:
        k = int(n)
    except (TypeError, ValueError):
        k = 0
    if k < 1 or k != n:
        where = f" (profile {profile})" if profile else ""
        raise ImutoolError(f"header rows{where}: expected a whole number ≥ 1, got {n!r}")
    return k


def _unit_row(rows: list[tuple[str, int]], names: list[str], sep: str, path: str) -> list[str | None]:
    """Per column, the first cell of the header rows after the names that is a known unit (None: none)."""
    if not rows:
        return []
    out: list[str | None] = [None] * len(names)
    for text, ln in rows:
        cells = _split_header(text, sep)
        if _looks_numeric([c for c in cells if c] or ["x"]):
            raise ImutoolError(
                f"header row {ln} is numbers: the file has fewer header rows than --header-rows says",
                path=path,
                line=ln,
            )
        for j, c in enumerate(cells[: len(names)]):
            if out[j] is None and c and _units.is_known(c):
                out[j] = c
    return out


def _apply_unit_row(mapping: Mapping, units: list[str | None], path: str) -> None:
    """Units from a header's units row, for the columns whose unit was inferred (not one the user gave)."""
    for cm, u in zip(mapping.columns, units, strict=False):
        if u is None or not cm.inferred or (cm.unit and not cm.unit_assumed):
            continue
        q = _expected_quantity_of(cm.target)
        u = resolve_unit(u, q)
        if q:
            try:
                _units.factor_to_si(u, q)
            except ImutoolError:
                continue  # a unit of another quantity: not this column's (kept as it was)
        cm.unit, cm.unit_assumed = u, False


def _apply_time_column(mapping: Mapping, spec: str, names: list[str], path: str) -> None:
    """``NAME[:UNIT]`` becomes the time column (unit s, ms, us or ns; default: the one inferred, else s); a
    column the inference had taken for the time keeps its own name."""
    name, _, unit = spec.rpartition(":") if spec.rpartition(":")[0] in names else (spec, "", "")
    name, unit = name.strip(), unit.strip()
    if name not in names:
        raise ImutoolError(f"--time-column: no column {name!r} in the file (has: {', '.join(names)})", path=path)
    for cm in mapping.columns:
        if cm.target == "time" and cm.source != name:
            cm.target = "file_time" if clean_name(cm.source) == "time" else clean_name(cm.source)
    cm = mapping.columns[names.index(name)]
    if unit:
        if unit not in ("s", "ms", "us", "µs", "ns"):
            raise ImutoolError(f"--time-column {spec!r}: the unit must be s, ms, us or ns", path=path)
    else:
        guess = _infer_time_unit(name)
        unit = guess or "s"
    cm.target, cm.unit, cm.unit_assumed, cm.inferred, cm.scale = "time", unit, False, False, 1.0


def _infer_time_unit(header: str) -> str | None:
    """A time unit stated in the column name (``Time (ms)``, ``t_us``), if any."""
    u = _unit_in(header) or (clean_name(header).rsplit("_", 1)[-1] if "_" in clean_name(header) else None)
    if u and _units.is_known(u):
        try:
            _units.factor_to_si(u, "time")
            return u
        except ImutoolError:
            return None
    return None


def _looks_numeric(names: list[str]) -> bool:
    try:
        [float(n) for n in names]
        return True
    except ValueError:
        return False


_REASON = {1: "wrong number of fields", 2: "not a number"}


class _BlockParser:
    """Drives the compiled kernel over byte blocks: grows the output, resolves rare tokens with float(),
    counts bad rows (first few with line numbers) or raises under ``strict``."""

    def __init__(self, hdr: CsvHeader, path: str, strict: bool, rep: ReadReport):
        self.hdr = hdr
        self.ncol = len(hdr.names)
        self.sep = ord(hdr.sep)
        self.dec = ord(hdr.decimal)
        self.path = path
        self.strict = strict
        self.rep = rep
        self.line = hdr.data_line  # line number of the next unparsed line
        # room for at least one whole row of fallback tokens: with fewer slots than columns the kernel could
        # never finish a row (a file with more than 4 096 columns used to loop for ever)
        self.fb = np.empty((max(4096, 2 * self.ncol), 4), np.int64)
        self.bad = np.empty((8, 3), np.int64)

    def parse(self, buf: np.ndarray, end: int, rows_hint: int) -> np.ndarray:
        """Parse whole lines in buf[:end]; returns an (n, ncol) float64 array."""
        out = np.empty((max(rows_hint, 16), self.ncol))
        pos = 0
        row = 0
        while True:
            res = _eng.parse_block(
                buf,
                pos,
                end,
                self.ncol,
                self.sep,
                self.dec,
                out,
                row,
                self.strict,
                self.fb,
                self.bad,
                _eng.T_HI,
                _eng.T_LO,
            )
            new_pos, new_row, lines, nbad, nfb, stop = (int(v) for v in res)
            for k in range(nfb):
                r, c, s0, s1 = (int(v) for v in self.fb[k])
                tok = bytes(buf[s0:s1])
                if self.dec != 46:
                    tok = tok.replace(b",", b".")
                try:
                    out[r, c] = float(tok)
                except ValueError:  # cannot happen for tokens the kernel accepted; be safe anyway
                    out[r, c] = np.nan
            if nbad:
                for k in range(min(nbad, self.bad.shape[0])):
                    ln = self.line + int(self.bad[k, 0])
                    reason = int(self.bad[k, 1])
                    msg = _REASON.get(reason, "bad row")
                    if reason == 1:
                        msg += f" ({int(self.bad[k, 2])} fields, expected {self.ncol})"
                    if self.strict:
                        raise ImutoolError(msg, path=self.path, line=ln)
                    if len(self.rep.first_bad) < 5:
                        self.rep.first_bad.append(f"line {ln}: {msg}")
                self.rep.bad_rows += nbad
            self.line += lines
            pos, row = new_pos, new_row
            if stop == 1:
                grown = np.empty((out.shape[0] * 2, self.ncol))
                grown[:row] = out[:row]
                out = grown
            elif stop == 0 or pos >= end:
                break
        return out[:row]


def _parse_parallel(
    parser: _BlockParser, buf: np.ndarray, end: int, pool: ThreadPoolExecutor | None = None
) -> list[np.ndarray]:
    """Parse the whole lines of buf[:end] with ``parser`` (its running line number and report are updated); big
    buffers are cut at line ends into pieces parsed by threads (the kernel releases the GIL; ``pool``: threads to
    use, else made here), bad-row line numbers made absolute afterwards. ``strict`` parses in one piece (it stops
    at the first bad row). Returns the pieces' rows, (n_i, ncol) float64 arrays in file order, not joined: the
    caller copies them once, into the channels (:func:`_gather`)."""
    n = _threads()
    if parser.strict or n == 1 or end < (8 << 20):
        return [parser.parse(buf, end, _rows_hint(buf, end))]
    cuts = [0]
    for k in range(1, n):
        c = int(end * k // n)
        nl = np.flatnonzero(buf[c : min(end, c + (1 << 20))] == 10)
        if nl.size:
            cuts.append(c + int(nl[0]) + 1)
    cuts.append(end)
    cuts = sorted(set(cuts))
    pieces = [buf[a:b] for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
    reps = [ReadReport() for _ in pieces]
    parsers = [_BlockParser(parser.hdr, parser.path, False, r) for r in reps]
    for p in parsers:
        p.line = 0  # relative line numbers; made absolute below

    def one(k: int) -> np.ndarray:
        return parsers[k].parse(pieces[k], pieces[k].size, _rows_hint(pieces[k], pieces[k].size))

    if pool is None:
        with ThreadPoolExecutor(len(pieces)) as own:
            arrays = list(own.map(one, range(len(pieces))))
    else:
        arrays = list(pool.map(one, range(len(pieces))))
    for p, r in zip(parsers, reps, strict=True):
        for msg in r.first_bad:
            if len(parser.rep.first_bad) < 5:
                ln, _, rest = msg[5:].partition(":")
                parser.rep.first_bad.append(f"line {int(ln) + parser.line}:{rest}")
        parser.rep.bad_rows += r.bad_rows
        parser.line += p.line
    return arrays


def _gather(pieces: list[np.ndarray], cols: list[int], rows: int) -> np.ndarray:
    """The columns ``cols`` of the first ``rows`` rows of ``pieces`` ((n_i, ncol) arrays, in order) as one new
    C-contiguous array, (rows,) for one column, else (rows, len(cols)): the one copy of the parsed values."""
    k = len(cols)
    out = np.empty((rows, k)) if k > 1 else np.empty(rows)
    run = cols == list(range(cols[0], cols[0] + k))  # adjacent columns: a slice, no index array
    r = 0
    for a in pieces:
        if r >= rows:
            break
        m = min(a.shape[0], rows - r)
        if k == 1:
            out[r : r + m] = a[:m, cols[0]]
        elif run:
            out[r : r + m] = a[:m, cols[0] : cols[0] + k]
        else:
            out[r : r + m] = a[:m][:, cols]
        r += m
    return out


def _rows_hint(buf: np.ndarray, end: int) -> int:
    """Expected number of rows from the mean length of the first lines (over-estimated a little)."""
    head = buf[: min(end, 1 << 16)]
    n = int(np.count_nonzero(head == 10))
    if n == 0:
        return 16
    return int(end / (head.size / n) * 1.05) + 16


def _to_recording(
    hdr: CsvHeader, pieces: list[np.ndarray], path: str, rep: ReadReport, first_row: int = 0, rows: int | None = None
) -> Recording:
    """The parsed rows (``pieces``: (n_i, ncol) arrays in file order, the first ``rows`` of them; all by
    default) as a Recording, each channel copied once out of them (``first_row``: the index of the first row in
    the file, for the times of a file read at ``--rate``)."""
    if rows is None:
        rows = sum(a.shape[0] for a in pieces)
    names = hdr.names
    # a mapped column's scale, then its unit's factor to SI, applied to the column in that order
    factors: dict[int, list[float]] = {}
    if hdr.mapping is not None:
        targets = []
        unit_of: dict[str, str | None] = {}
        for j, cm in enumerate(hdr.mapping.columns):
            if cm.scale != 1.0:
                factors.setdefault(j, []).append(cm.scale)
            q = _expected_quantity_of(cm.target)
            if q and cm.unit:
                factors.setdefault(j, []).append(_units.factor_to_si(cm.unit, q))
                unit_of[cm.target] = _units.SI_UNIT[q] if q != "temperature" else "degC"
            else:
                unit_of[cm.target] = cm.unit
            targets.append(cm.target)
        names = targets
    else:
        unit_of = {}
        declared = hdr.meta.get("units", "")
        if isinstance(declared, str) and declared:
            for item in declared.split(","):
                k, _, v = item.partition("=")
                if k.strip():
                    unit_of[k.strip()] = v.strip()

    def columns(idx: list[int]) -> np.ndarray:
        arr = _gather(pieces, idx, rows)
        for i, j in enumerate(idx):
            for f in factors.get(j, ()):
                if arr.ndim == 1:
                    arr *= f
                else:
                    arr[:, i] *= f
        return arr

    if "time" in names:
        rec = Recording(columns([names.index("time")]))
    elif hdr.rate_hz is not None:
        rec = Recording((first_row + np.arange(rows, dtype=np.float64)) / hdr.rate_hz)
    else:
        raise ImutoolError(
            "no time column found (looked for time/timestamp/t headers): give the sample rate with --rate HZ, "
            "or name the time column with --time-column NAME[:UNIT]",
            path=path,
        )
    groups = group_columns([n for n in names if n != "time"])
    idx = {n: j for j, n in enumerate(names)}
    for ch, cols in groups:
        arr = columns([idx[c] for c in cols])
        unit = canonical_unit(ch) if hdr.mapping is None else None
        if unit is None:
            unit = unit_of.get(ch) or unit_of.get(cols[0])
            if unit is None and hdr.mapping is not None:
                unit = canonical_unit(ch) if ch in ("gyro", "accel", "mag", "temp") else None
        rec.add(ch, arr, unit, columns=cols)
    meta = {k: v for k, v in hdr.meta.items() if not k.startswith("_")}
    meta.pop("units", None)
    meta["source"] = os.fspath(path)
    if hdr.mapping is not None:
        meta["column_mapping"] = hdr.mapping.as_meta()
        meta["column_mapping_origin"] = hdr.mapping.origin
        assumed = sorted(
            {
                cm.target.split("_")[0]
                for cm in hdr.mapping.columns
                if cm.unit_assumed and cm.target.split("_")[0] in ("gyro", "accel", "mag")
            }
        )
        if assumed:  # no unit in the header: formats.plausibility checks these against their values
            meta["units_assumed"] = ",".join(assumed)
    if "time" not in names:
        meta["time_source"] = f"time from --rate {hdr.rate_hz:g} Hz (t = n / {hdr.rate_hz:g} s, n the data row from 0)"
        meta["rate_hz"] = hdr.rate_hz
    if rep.bad_rows:
        meta["skipped_rows"] = rep.bad_rows
        meta["skipped_rows_first"] = rep.first_bad
        if "time" not in names:
            meta["time_source"] += "; the malformed rows skipped took no time slot: later rows are early"
    rec.meta.update(meta)
    return rec


def _expected_quantity_of(target: str) -> str | None:
    base = target.split("_")[0]
    if target == "time":
        return "time"
    if base in ("gyro", "accel", "mag") and target[-2:] in ("_x", "_y", "_z"):
        return {"gyro": "angular_rate", "accel": "acceleration", "mag": "magnetic"}[base]
    if target == "temp":
        return "temperature"
    return None


def iter_csv(
    path: str,
    chunk_rows: int = 500_000,
    columns: str | None = None,
    profile: str | None = None,
    strict: bool = False,
    block_bytes: int = 16 << 20,
    prefetch: bool = False,
    *,
    rate_hz: float | None = None,
    time_column: str | None = None,
    header_rows: int | None = None,
) -> Iterator[Recording]:
    """Stream a CSV as successive Recordings of at most ``chunk_rows`` rows (bounded memory).

    The file is read in blocks of ``block_bytes`` cut at line ends; memory is O(block + chunk), not O(file).
    Skipped-row counts in each chunk's meta are running totals. ``prefetch``: the next chunk is parsed in a
    background thread while the caller works on the current one (one chunk more in memory); errors are raised
    in the caller at the chunk where they occur. ``rate_hz``, ``time_column``, ``header_rows``: as
    :func:`read_header`.
    """
    hdr = read_header(path, columns, profile, rate_hz=rate_hz, time_column=time_column, header_rows=header_rows)
    chunks = _iter_csv(path, hdr, chunk_rows, strict, block_bytes)
    return in_background(chunks) if prefetch else chunks


def in_background(items: Iterator[Any], depth: int = 1) -> Iterator[Any]:
    """Run an iterator in a worker thread, ``depth`` items ahead of the consumer (useful when producing an item
    runs GIL-free compiled code). Exceptions are re-raised in the consumer; abandoning the loop stops the worker."""
    q: queue.Queue = queue.Queue(maxsize=depth)
    quit_ = threading.Event()

    def put(item: tuple) -> bool:
        while not quit_.is_set():
            try:
                q.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def work() -> None:
        try:
            for it in items:
                if not put(("item", it)):
                    return
            put(("end", None))
        except BaseException as e:  # handed to the consumer
            put(("error", e))

    threading.Thread(target=work, name="imutool-prefetch", daemon=True).start()
    try:
        while True:
            kind, value = q.get()
            if kind == "end":
                return
            if kind == "error":
                raise value
            yield value
    finally:
        quit_.set()


def _last_newline(buf: np.ndarray, end: int) -> int:
    """The index of the last LF in buf[:end], or -1; searched backwards in growing windows (a line is short)."""
    w = 1 << 16
    hi = end
    while hi > 0:
        lo = max(0, hi - w)
        nl = np.flatnonzero(buf[lo:hi] == 10)
        if nl.size:
            return lo + int(nl[-1])
        hi = lo
        w *= 4
    return -1


def _iter_csv(
    path: str, hdr: CsvHeader, chunk_rows: int, strict: bool, block_bytes: int, rep: ReadReport | None = None
) -> Iterator[Recording]:
    """The chunks of ``chunk_rows`` rows: blocks of ``block_bytes`` read into one reused buffer (the part line at
    a block's end moved to its front), parsed in pieces by threads, and each chunk's channels copied once out of
    the pieces (no joined block or chunk array in between). ``rep``: the report the skipped rows are counted in
    (a new one by default)."""
    done = 0  # rows yielded so far
    rep = ReadReport() if rep is None else rep
    parser = _BlockParser(hdr, path, strict, rep)
    pending: list[np.ndarray] = []
    npending = 0
    carry = 0  # bytes of an unfinished line at the front of buf
    nthreads = _threads()
    pool = ThreadPoolExecutor(nthreads, thread_name_prefix="imutool-parse") if nthreads > 1 else None
    try:
        with open(path, "rb") as f:
            f.seek(hdr.data_offset)
            # one block, or less for a smaller file (+1: the read that finds the end has room)
            buf = np.empty(max(1, min(block_bytes, os.fstat(f.fileno()).st_size - hdr.data_offset + 1)), np.uint8)
            while True:
                if carry >= buf.size:  # a line longer than the buffer: room for it and a block more
                    grown = np.empty(carry + block_bytes, np.uint8)
                    grown[:carry] = buf[:carry]
                    buf = grown
                got = f.readinto(memoryview(buf)[carry:])
                eof = not got
                total = carry + got
                if eof:
                    end = total
                else:
                    cut = _last_newline(buf, total)
                    if cut < 0:
                        carry = total
                        continue
                    end = cut + 1
                if end:
                    for arr in _parse_parallel(parser, buf, end, pool):
                        if arr.shape[0]:
                            pending.append(arr)
                            npending += arr.shape[0]
                carry = total - end
                if carry:
                    buf[:carry] = buf[end:total].copy()
                if eof:  # the text is parsed: let it go before the last chunk's channels are copied
                    buf = np.empty(0, np.uint8)
                while npending >= chunk_rows or (eof and npending):
                    take = min(chunk_rows, npending)
                    yield _to_recording(hdr, pending, path, rep, done, take)
                    done += take
                    left, rest = take, []
                    for a in pending:  # what the chunk did not take stays, as views
                        if left >= a.shape[0]:
                            left -= a.shape[0]
                            continue
                        rest.append(a[left:])
                        left = 0
                    pending = rest
                    npending -= take
                if eof:
                    break
    finally:
        if pool is not None:
            pool.shutdown(wait=False)


def read_csv(
    path: str,
    columns: str | None = None,
    profile: str | None = None,
    strict: bool = False,
    *,
    rate_hz: float | None = None,
    time_column: str | None = None,
    header_rows: int | None = None,
    block_bytes: int = 16 << 20,
) -> Recording:
    """Read a whole CSV (imutool or foreign) into a Recording (SI units for sensor channels).

    ``rate_hz`` (a file without a time column), ``time_column`` (``NAME[:UNIT]``), ``header_rows`` (names, then
    units): as :func:`read_header`.

    The rows are read as :func:`iter_csv` reads them, in blocks of ``block_bytes`` parsed by threads, as one chunk:
    the file's text is never held whole (peak memory: the parsed rows twice, while they are copied into the
    channels, and one block).

    Malformed rows are counted and skipped (``meta['skipped_rows']``, first ones with line numbers in
    ``meta['skipped_rows_first']``); ``strict=True`` raises ImutoolError at the first one instead.
    """
    hdr = read_header(path, columns, profile, rate_hz=rate_hz, time_column=time_column, header_rows=header_rows)
    rep = ReadReport()
    chunks = _iter_csv(path, hdr, sys.maxsize, strict, block_bytes, rep)
    try:
        whole = next(chunks, None)
    except OSError as e:
        raise ImutoolError(f"cannot read: {e.strerror}", path=path) from None
    finally:
        chunks.close()  # the parse threads stop; the parsed pieces are let go
    if whole is None:
        msg = "no data rows"
        if rep.bad_rows:
            msg += f" ({rep.bad_rows} malformed rows skipped; first: {rep.first_bad[0]})"
        raise ImutoolError(msg, path=path)
    return whole


def _fmt_meta(v: Any) -> str:
    if isinstance(v, (dict, list, tuple)):
        return json.dumps(v, separators=(",", ":"), default=str)
    return str(v).replace("\n", " ")


def header_text(rec: Recording) -> str:
    """The metadata and header lines of an imutool CSV for this recording."""
    lines = [MAGIC]
    extra_units = []
    for name in rec.channels:
        u = rec.units.get(name)
        if u is not None and canonical_unit(name) != u:
            extra_units.append(f"{name}={u}")
    for k, v in rec.meta.items():
        if k in ("units",):
            continue
        lines.append(f"# {k}: {_fmt_meta(v)}")
    if extra_units:
        lines.append("# units: " + ", ".join(extra_units))
    lines.append(",".join(rec.column_names()))
    return "\n".join(lines) + "\n"


def _canonicalised(rec: Recording) -> list[np.ndarray]:
    """Column blocks ready to print: canonical channels converted to their canonical unit."""
    blocks = [rec.time[:, None]]
    for name, a in rec.channels.items():
        cu = canonical_unit(name)
        u = rec.units.get(name)
        if cu is not None and u is not None and u != cu:
            a = _units.convert(a, u, cu)
        blocks.append(a.reshape(len(a), -1))
    return blocks


_WRITE_BLOCK_ROWS = 32768


def format_array(data: np.ndarray, sep: str = ",", decimals: np.ndarray | None = None) -> bytes:
    """CSV text (bytes) of a 2-D float array: exact round-trip digits (shortest of 15/16/17), NaN empty.
    ``decimals`` (per column, −1 = exact) rounds chosen columns to a fixed number of decimals."""
    data = np.ascontiguousarray(data, dtype=np.float64)
    if data.ndim == 1:
        data = data[:, None]
    parts = []
    for r0 in range(0, data.shape[0], _WRITE_BLOCK_ROWS):
        parts.append(_format_block(data, r0, min(r0 + _WRITE_BLOCK_ROWS, data.shape[0]), sep, decimals))
    return b"".join(parts)


def _format_block(
    data: np.ndarray, r0: int, r1: int, sep: str, decimals: np.ndarray | None = None
) -> bytes | memoryview:
    """Rows data[r0:r1] as CSV lines: a view of the formatted bytes (written or joined as they are, not copied
    into a ``bytes`` first: 160 bytes a row of an estimate, a copy of the whole output otherwise)."""
    n = r1 - r0
    if decimals is None:
        decimals = np.full(data.shape[1], -1, np.int64)
    out = np.empty(n * (data.shape[1] * _eng.MAX_FIELD_BYTES + 1), np.uint8)
    fails = np.empty((1, 2), np.int64)
    nbytes, nfail = _eng.format_block(data, data.view(np.uint64), r0, r1, ord(sep), out, fails, decimals)
    if nfail:  # never seen; Python's repr is exact too
        return "".join(sep.join("" if v != v else repr(v) for v in row) + "\n" for row in data[r0:r1].tolist()).encode()
    return memoryview(out)[:nbytes]


DECIMALS_KEY = "csv_decimals"


def column_decimals(rec: Recording) -> np.ndarray | None:
    """Per-column decimals from ``rec.meta['csv_decimals']`` ({channel: n}, the printed resolution of estimator
    outputs, written into the header); −1 (exact round trip) for the time and every other channel."""
    spec = rec.meta.get(DECIMALS_KEY)
    if not spec:
        return None
    if not isinstance(spec, dict) or not all(
        isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= _eng.MAX_DECIMALS for v in spec.values()
    ):
        raise ImutoolError(
            f"metadata {DECIMALS_KEY} must map channel names to 0…{_eng.MAX_DECIMALS} decimals, got {spec!r}"
        )
    widths = [1] + [1 if a.ndim == 1 else a.shape[1] for a in rec.channels.values()]
    per = [-1] + [spec.get(name, -1) for name in rec.channels]
    return np.repeat(np.array(per, np.int64), widths)


def _threads() -> int:
    """Worker threads for the compiled kernels (they release the GIL): this process's thread budget
    (:func:`formats.jit.threads.thread_budget`: the usable cores, or a batch worker's share), at most 4."""
    return max(1, min(4, thread_budget()))


def _write_rows(f: Any, rec: Recording, before: Callable[[], Any] | None = None) -> None:
    """Write ``rec``'s rows to ``f``; or, with ``before``, to the file it returns, called once the rows' formatting
    has started on the format threads and before the first row is written (:meth:`CsvWriter._write_chunk`: the
    copy of the earlier rows behind a new header runs while the chunk is formatted)."""
    if not len(rec):
        if before is not None:
            before()
        return
    blocks = _canonicalised(rec)
    decimals = column_decimals(rec)

    def one(r0: int) -> bytes | memoryview:
        r1 = min(r0 + _WRITE_BLOCK_ROWS, len(rec))
        data = np.ascontiguousarray(np.hstack([b[r0:r1] for b in blocks]), dtype=np.float64)
        return _format_block(data, 0, r1 - r0, ",", decimals)

    starts = range(0, len(rec), _WRITE_BLOCK_ROWS)
    nthreads = _threads()
    if nthreads == 1 or len(starts) < 2:
        if before is not None:
            f = before()
        for r0 in starts:
            f.write(one(r0))
        return
    with ThreadPoolExecutor(nthreads) as pool:  # blocks formatted in parallel, written in order
        texts = pool.map(one, starts)  # (every block submitted now)
        if before is not None:
            f = before()
        for text in texts:
            f.write(text)


def format_rows(rec: Recording) -> str:
    """Data rows as text: exact round-trip representation, ``nan`` written as empty field."""
    buf = io.BytesIO()
    _write_rows(buf, rec)
    return buf.getvalue().decode()


def write_csv(rec: Recording, path: str) -> None:
    """Write an imutool CSV atomically (temporary file renamed at the end)."""
    for name in rec.channels:
        cu = canonical_unit(name)
        u = rec.units.get(name)
        if cu is not None and u is not None and u != cu:
            _units.convert(np.zeros(1), u, cu)  # raises a clear error on an incompatible unit
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(header_text(rec).encode("utf-8"))
        _write_rows(f, rec)


COPY_BLOCK = 1 << 24  # bytes per step of the one copy of a streamed file's rows behind its final header


def copy_range(src: Any, dst: Any, offset: int) -> None:
    """Append the bytes of open file ``src`` from ``offset`` to its end at the position of open file ``dst``: in
    the kernel (``os.copy_file_range``) where the system has it, else (or for what it left) in ``COPY_BLOCK``-byte
    reads."""
    dst.flush()
    start = dst.tell()
    total = os.fstat(src.fileno()).st_size - offset
    done = 0
    if hasattr(os, "copy_file_range"):
        try:
            while done < total:
                n = os.copy_file_range(
                    src.fileno(), dst.fileno(), min(total - done, 1 << 30), offset + done, start + done
                )
                if n <= 0:
                    break
                done += n
        except OSError:  # not on this file system, or across devices: the rest by blocks
            pass
    src.seek(offset + done)
    dst.seek(start + done)
    if done < total:
        shutil.copyfileobj(src, dst, COPY_BLOCK)


class CsvWriter(AtomicChunkWriter):
    """Incremental imutool CSV writer for streaming conversion; atomic on :meth:`close`.

    Usage: ``with CsvWriter(path) as w: w.write(chunk) ...`` — the header comes from the first chunk.
    ``background=True``: formatting and writing of a chunk overlap the caller's next chunk (one in flight).
    Metadata handed to :meth:`set_final_meta` (known only at the end: a streamed run's warnings) replace the first
    chunk's keys in the header, so a person opening the file sees one clean header — no line kept blank for them,
    no key twice. The rows written before they were known are copied once behind the final header, in a new file
    (in large blocks, in the kernel where it can: ``os.copy_file_range``; ``benchmarks/stream_header.py`` measures
    the copy); rows written after go straight behind it. So a stream that knows its final metadata before its last
    chunk (:func:`imutool.filtering.stream_ekf` looks one chunk ahead) hands them over before writing that chunk,
    and only the rows before it are copied.
    """

    def __init__(self, path: str, background: bool = False):
        super().__init__(path, background, "imutool-writer")
        self._cur = str(self._tmp)  # the file the rows go to: the temporary file, or its rewrite behind a new header
        self._f = open(self._cur, "wb")
        self._head: Recording | None = None  # the first chunk without rows: its header, rebuilt with final_meta
        self._head_bytes = b""  # the header the current file starts with

    def _header(self, final: dict[str, Any]) -> bytes:
        """The header of the first chunk with the metadata ``final`` merged in (a key of the first chunk keeps its
        place, new keys follow)."""
        assert self._head is not None
        first = self._head.meta
        self._head.meta = {**first, **final}
        try:
            return header_text(self._head).encode("utf-8")
        finally:
            self._head.meta = first

    def _first(self, rec: Recording) -> None:
        self._head = rec.select(slice(0, 0))
        self._head.meta = dict(rec.meta)
        final = self.final_meta
        head = self._header(final) if final else header_text(rec).encode("utf-8")
        self._f.write(head)
        self._head_bytes = head

    def _rewrite(self, head: bytes) -> Any:
        """Start a new file with ``head`` and the current file's rows copied behind it; it becomes the current
        file (open for more rows, returned) and the old one is removed."""
        self._f.close()
        old = self._cur
        self._cur = str(self._tmp) + (".meta" if old == str(self._tmp) else "")
        self._f = open(self._cur, "wb")
        self._f.write(head)
        with open(old, "rb") as src:
            copy_range(src, self._f, len(self._head_bytes))
        self._head_bytes = head
        if old != str(self._tmp):  # the temporary file itself stays: atomic_path renames or removes it
            os.unlink(old)
        return self._f

    def _write_chunk(self, rec: Recording) -> None:
        final = self.final_meta  # one version (set_final_meta replaces the dict)
        if final:
            head = self._header(final)
            if head != self._head_bytes:  # the earlier rows copied behind it while this chunk is formatted
                _write_rows(self._f, rec, before=lambda: self._rewrite(head))
                return
        _write_rows(self._f, rec)

    def _finish(self) -> None:
        if self._started and self._head is not None and self.final_meta:
            head = self._header(self.final_meta)
            if head != self._head_bytes:  # metadata given after the last row: the rows copied behind them
                self._rewrite(head)
        self._f.close()
        if self._cur != str(self._tmp):
            os.replace(self._cur, self._tmp)
            self._cur = str(self._tmp)

    def _discard(self) -> None:
        try:
            self._f.close()
        except OSError:
            pass
        if self._cur != str(self._tmp):  # a rewrite behind the final header (the temporary file: atomic_path)
            try:
                os.unlink(self._cur)
            except OSError:
                pass
