"""imutool CSV and foreign CSV: read (whole or streamed in chunks) and write (atomic).

imutool CSV (DESIGN.md)::

    # imutool-csv: 1
    # key: value                   (metadata: sensor, rate_hz, frame, mounting, source, units, ...)
    time,gyro_x,gyro_y,gyro_z,...

Canonical columns carry canonical units (time s, gyro rad/s, accel m/s², mag µT, angles deg, heave m up).
Other channels' units are listed in the ``# units:`` line (``name=unit, ...``). Empty field or ``nan`` =
missing. A foreign CSV (any header) is read through a :class:`formats.columns.Mapping`.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import units as _units
from .atomic import atomic_path
from .columns import Mapping, infer_mapping, load_profile, mapping_from_profile, parse_mapping_option
from .errors import ImutoolError
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


def read_header(path: str, columns: str | None = None, profile: str | None = None) -> CsvHeader:
    """Read metadata and column names; infer or apply the column mapping for a foreign CSV."""
    try:
        f = open(path, encoding="utf-8-sig", errors="replace", newline="")
    except OSError as e:
        raise ImutoolError(f"cannot open: {e.strerror}", path=path) from None
    with f:
        meta: dict[str, Any] = {}
        is_imutool = False
        lineno = 0
        comments = 0
        header_line = None
        for raw in f:
            lineno += 1
            line = raw.strip()
            if not line:
                continue
            if line.startswith("#"):
                comments += 1
                if line.startswith("# imutool-csv:"):
                    is_imutool = True
                    continue
                body = line[1:].strip()
                if ":" in body:
                    k, _, v = body.partition(":")
                    meta[k.strip()] = _parse_meta_value(v)
                continue
            header_line = line
            break
    if header_line is None:
        raise ImutoolError("no header row (the file is empty or has only comments)", path=path)
    sep = "," if "," in header_line or ";" not in header_line else ";"
    names = [h.strip().strip('"') for h in header_line.split(sep)]
    if any(not n for n in names):
        raise ImutoolError("the header row has an empty column name", path=path, line=lineno)
    if _looks_numeric(names):
        raise ImutoolError("the first row is numbers, not column names; add a header row", path=path,
                           line=lineno)
    mapping = None
    if not is_imutool or columns or profile:
        if profile:
            mapping = mapping_from_profile(load_profile(profile), names, profile)
        elif columns:
            mapping = parse_mapping_option(columns, names)
        else:
            mapping = infer_mapping(names)
    elif "time" not in names:
        raise ImutoolError("imutool CSV without a 'time' column", path=path, line=lineno)
    hdr = CsvHeader(is_imutool, meta, names, lineno + 1, mapping, comments)
    hdr.meta["_sep"] = sep
    return hdr


def _looks_numeric(names: list[str]) -> bool:
    try:
        [float(n) for n in names]
        return True
    except ValueError:
        return False


def _parse_block(lines: list[str], ncol: int, sep: str, first_line: int, rep: ReadReport,
                 strict: bool, path: str) -> np.ndarray:
    """Parse data lines into an (n, ncol) float64 array; malformed rows counted and skipped (or raised)."""
    out = np.empty((len(lines), ncol))
    k = 0
    for i, line in enumerate(lines):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split(sep)
        try:
            if len(parts) != ncol:
                raise ValueError(f"{len(parts)} fields, expected {ncol}")
            out[k] = [float(p) if p.strip() else np.nan for p in parts]
        except ValueError as e:
            msg = str(e) if "fields" in str(e) else f"not a number in {s[:60]!r}"
            if strict:
                raise ImutoolError(msg, path=path, line=first_line + i) from None
            rep.bad_rows += 1
            if len(rep.first_bad) < 5:
                rep.first_bad.append(f"line {first_line + i}: {msg}")
            continue
        k += 1
    return out[:k]


def _to_recording(hdr: CsvHeader, data: np.ndarray, path: str, rep: ReadReport) -> Recording:
    names = hdr.names
    if hdr.mapping is not None:
        targets = []
        unit_of: dict[str, str | None] = {}
        for j, cm in enumerate(hdr.mapping.columns):
            col = data[:, j]
            if cm.scale != 1.0:
                col *= cm.scale
            q = _expected_quantity_of(cm.target)
            if q and cm.unit:
                col *= _units.factor_to_si(cm.unit, q)
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
    if "time" not in names:
        raise ImutoolError(
            "no time column found (looked for time/timestamp/t headers); name it with --columns "
            "'YourTime=time:s'",
            path=path,
        )
    ti = names.index("time")
    rec = Recording(data[:, ti].copy())
    groups = group_columns([n for n in names if n != "time"])
    idx = {n: j for j, n in enumerate(names)}
    for ch, cols in groups:
        arr = data[:, [idx[c] for c in cols]]
        if len(cols) == 1:
            arr = arr[:, 0]
        unit = canonical_unit(ch) if hdr.mapping is None else None
        if unit is None:
            unit = unit_of.get(ch) or unit_of.get(cols[0])
            if unit is None and hdr.mapping is not None:
                unit = canonical_unit(ch) if ch in ("gyro", "accel", "mag", "temp") else None
        rec.add(ch, np.ascontiguousarray(arr), unit, columns=cols)
    meta = {k: v for k, v in hdr.meta.items() if not k.startswith("_")}
    meta.pop("units", None)
    meta["source"] = os.fspath(path)
    if hdr.mapping is not None:
        meta["column_mapping"] = hdr.mapping.as_meta()
        meta["column_mapping_origin"] = hdr.mapping.origin
    if rep.bad_rows:
        meta["skipped_rows"] = rep.bad_rows
        meta["skipped_rows_first"] = rep.first_bad
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


def iter_csv(path: str, chunk_rows: int = 500_000, columns: str | None = None, profile: str | None = None,
             strict: bool = False) -> Iterator[Recording]:
    """Stream a CSV as successive Recordings of at most ``chunk_rows`` rows (bounded memory)."""
    hdr = read_header(path, columns, profile)
    rep = ReadReport()
    ncol = len(hdr.names)
    sep = hdr.meta.get("_sep", ",")
    with open(path, encoding="utf-8-sig", errors="replace", newline="") as f:
        for _ in range(hdr.data_line - 1):
            f.readline()
        line_no = hdr.data_line
        while True:
            lines = []
            for line in f:
                lines.append(line)
                if len(lines) >= chunk_rows:
                    break
            if not lines:
                break
            data = _parse_block(lines, ncol, sep, line_no, rep, strict, path)
            line_no += len(lines)
            yield _to_recording(hdr, data, path, rep)


def read_csv(path: str, columns: str | None = None, profile: str | None = None,
             strict: bool = False) -> Recording:
    """Read a whole CSV (imutool or foreign) into a Recording (SI units for sensor channels)."""
    hdr = read_header(path, columns, profile)
    rep = ReadReport()
    sep = hdr.meta.get("_sep", ",")
    with open(path, encoding="utf-8-sig", errors="replace", newline="") as f:
        lines = f.readlines()[hdr.data_line - 1:]
    data = _parse_block(lines, len(hdr.names), sep, hdr.data_line, rep, strict, path)
    if data.shape[0] == 0:
        raise ImutoolError("no data rows", path=path)
    return _to_recording(hdr, data, path, rep)


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


def format_rows(rec: Recording) -> str:
    """Data rows as text: shortest round-trip representation, ``nan`` written as empty field."""
    data = np.hstack(_canonicalised(rec)) if len(rec) else np.empty((0, 1))
    buf = io.StringIO()
    for row in data.tolist():
        buf.write(",".join("" if v != v else repr(v) for v in row))
        buf.write("\n")
    return buf.getvalue()


def write_csv(rec: Recording, path: str) -> None:
    """Write an imutool CSV atomically (temporary file renamed at the end)."""
    for name in rec.channels:
        cu = canonical_unit(name)
        u = rec.units.get(name)
        if cu is not None and u is not None and u != cu:
            _units.convert(np.zeros(1), u, cu)  # raises a clear error on an incompatible unit
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8", newline="\n") as f:
        f.write(header_text(rec))
        f.write(format_rows(rec))


class CsvWriter:
    """Incremental imutool CSV writer for streaming conversion; atomic on :meth:`close`.

    Usage: ``with CsvWriter(path) as w: w.write(chunk) ...`` — the header comes from the first chunk.
    """

    def __init__(self, path: str):
        self.path = path
        self._ctx = atomic_path(path)
        self._tmp = self._ctx.__enter__()
        self._f = open(self._tmp, "w", encoding="utf-8", newline="\n")
        self._header_written = False
        self.rows = 0

    def write(self, rec: Recording) -> None:
        if not self._header_written:
            self._f.write(header_text(rec))
            self._header_written = True
        self._f.write(format_rows(rec))
        self.rows += len(rec)

    def close(self) -> None:
        self._f.close()
        self._ctx.__exit__(None, None, None)

    def abort(self, exc: BaseException) -> None:
        self._f.close()
        try:
            self._ctx.__exit__(type(exc), exc, exc.__traceback__)
        except BaseException:
            pass

    def __enter__(self) -> CsvWriter:
        return self

    def __exit__(self, et, ev, tb) -> None:
        if et is None:
            self.close()
        else:
            self.abort(ev)
