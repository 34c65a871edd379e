"""Parquet in and out: the same columns, units and metadata as the imutool CSV, streamed by row groups.

Layout: one float64 column per CSV column (``time, gyro_x, gyro_y, gyro_z, ...``), canonical channels in their
canonical unit (time s, gyro rad/s, accel m/s², mag µT, angles deg, heave m up) exactly as in the CSV; NaN =
missing. The recording's metadata travel in the Parquet key-value metadata under the key ``imutool`` (JSON)::

    {"format": "imutool-parquet", "version": 1, "meta": {...}, "units": {channel: unit},
     "columns": {channel: [column names]}}

A streamed write may add, in the file footer under ``imutool_final``, a JSON object of metadata known only at
the end (a streamed run's warnings); the reader merges it over ``meta``. Each field carries its unit in the
field metadata (``unit``) for other tools. A Parquet file without the ``imutool`` key (written by another tool)
is read column by column: numeric columns become channels (vector columns grouped like the CSV's ``*_x/_y/_z``),
a timestamp ``time`` column becomes seconds since the Unix epoch, other columns are skipped and listed in
``meta['skipped_columns']``.

Needs ``pyarrow`` (the ``[parquet]`` extra). Reading is streamed row group by row group (:func:`iter_parquet`),
writing appends row groups (:class:`ParquetWriter`), so files larger than memory pass through in bounded memory.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from typing import Any

import numpy as np

from . import units as _units
from .atomic import AtomicChunkWriter
from .errors import ImutoolError
from .jit.threads import ENV as THREADS_ENV
from .jit.threads import thread_budget
from .recording import Recording, canonical_unit, group_columns

META_KEY = b"imutool"
FINAL_META_KEY = b"imutool_final"  # metadata known only at the end of a streamed write (JSON), merged over "meta"
FORMAT_NAME = "imutool-parquet"
VERSION = 1
ROW_GROUP_ROWS = 262_144  # rows per row group written (≈ 21 MB of float64 per 10 columns)


def _pa() -> Any:
    try:
        import pyarrow
        import pyarrow.parquet  # noqa: F401
    except ImportError:
        raise ImutoolError("Parquet needs pyarrow: pip install 'imutool[parquet]' (or pip install pyarrow)") from None
    if os.environ.get(THREADS_ENV):  # a batch worker's share of the cores (formats/jit/threads.py)
        pyarrow.set_cpu_count(thread_budget())
    return pyarrow


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)


# -- writing ----------------------------------------------------------------------------------------------------
def _layout(rec: Recording) -> tuple[list[str], dict[str, str], bytes]:
    """Column names, per-column unit, and the key-value metadata blob for a recording."""
    names = rec.column_names()
    col_units = {"time": "s"}
    units: dict[str, str] = {}
    for name in rec.channels:
        cu = canonical_unit(name)
        u = rec.units.get(name)
        if cu is not None and u is not None and u != cu:
            _units.convert(np.zeros(1), u, cu)  # raises a clear error on an incompatible unit
        unit = cu if cu is not None else u
        if unit is not None:
            units[name] = unit
            for c in rec.columns[name]:
                col_units[c] = unit
    meta = {k: v for k, v in rec.meta.items() if k != "units"}
    blob = {
        "format": FORMAT_NAME,
        "version": VERSION,
        "meta": meta,
        "units": units,
        "columns": {k: list(v) for k, v in rec.columns.items()},
    }
    return names, col_units, json.dumps(blob, default=_jsonable, separators=(",", ":")).encode("utf-8")


def _schema(rec: Recording) -> Any:
    pa = _pa()
    names, col_units, blob = _layout(rec)
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ImutoolError(f"Parquet: duplicate column names {', '.join(dup)}")
    fields = [
        pa.field(n, pa.float64(), metadata={b"unit": col_units[n].encode()} if n in col_units else None) for n in names
    ]
    return pa.schema(fields, metadata={META_KEY: blob})


def _table(rec: Recording, schema: Any) -> Any:
    """The recording's rows as an Arrow table (canonical channels in their canonical unit, like the CSV)."""
    pa = _pa()
    arrays = [pa.array(rec.time, pa.float64())]
    for name, a in rec.channels.items():
        cu = canonical_unit(name)
        u = rec.units.get(name)
        if cu is not None and u is not None and u != cu:
            a = _units.convert(a, u, cu)
        a = np.asarray(a, dtype=np.float64)
        if a.ndim == 1:
            arrays.append(pa.array(a, pa.float64()))
        else:
            arrays.extend(pa.array(np.ascontiguousarray(a[:, j]), pa.float64()) for j in range(a.shape[1]))
    return pa.Table.from_arrays(arrays, schema=schema)


class ParquetWriter(AtomicChunkWriter):
    """Incremental Parquet writer (row groups appended per chunk); atomic on :meth:`close`.

    Usage: ``with ParquetWriter(path) as w: w.write(chunk) ...`` — schema and metadata come from the first
    chunk; every later chunk must have the same columns. ``row_group_rows`` caps the rows per row group.
    ``background=True``: a chunk is converted and written (pyarrow releases the GIL) while the caller works on
    the next one.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        compression: str = "snappy",
        row_group_rows: int = ROW_GROUP_ROWS,
        background: bool = False,
    ):
        _pa()
        super().__init__(path, background, "imutool-parquet")
        self.compression = compression
        self.row_group_rows = int(row_group_rows)
        self._writer: Any = None
        self._schema: Any = None

    def _first(self, rec: Recording) -> None:
        import pyarrow.parquet as pq

        self._schema = _schema(rec)
        # no dictionary encoding: float sensor data rarely repeats enough to pay for it, and trying it per row
        # group cost 3-5x the write time (benchmarks/parquet.py)
        self._writer = pq.ParquetWriter(
            str(self._tmp), self._schema, compression=self.compression, use_dictionary=False
        )

    def _check(self, rec: Recording) -> None:
        if rec.column_names() != self._schema.names:
            raise ImutoolError(
                f"Parquet: chunk columns {rec.column_names()} differ from the first chunk's {self._schema.names}",
                path=self.path,
            )

    def _write_chunk(self, rec: Recording) -> None:
        self._writer.write_table(_table(rec, self._schema), row_group_size=self.row_group_rows)

    def _finish(self) -> None:
        if self._writer is None:
            raise ImutoolError("Parquet: nothing written (no chunk)", path=self.path)
        if self.final_meta:  # the schema's metadata are fixed at the first chunk: these go into the footer
            blob = json.dumps(self.final_meta, default=_jsonable, separators=(",", ":"))
            if not hasattr(self._writer, "add_key_value_metadata"):
                raise ImutoolError(
                    "Parquet: writing metadata at the end of a stream needs pyarrow >= 17 (pip install -U pyarrow)",
                    path=self.path,
                )
            self._writer.add_key_value_metadata({FINAL_META_KEY.decode(): blob})
        self._writer.close()

    def _discard(self) -> None:
        if self._writer is not None:
            try:
                self._writer.close()
            except Exception:
                pass


def write_parquet(
    rec: Recording, path: str | os.PathLike, compression: str = "snappy", row_group_rows: int = ROW_GROUP_ROWS
) -> None:
    """Write a Recording as imutool Parquet atomically (temporary file renamed at the end)."""
    with ParquetWriter(path, compression=compression, row_group_rows=row_group_rows) as w:
        w.write(rec)


# -- reading ----------------------------------------------------------------------------------------------------
class _Plan:
    """How the file's columns become channels (decided once from the schema)."""

    def __init__(self, schema: Any, path: str, file_meta: dict[bytes, bytes] | None = None):
        pa = _pa()
        self.path = path
        blob = (schema.metadata or {}).get(META_KEY)
        info: dict[str, Any] = {}
        if blob is not None:
            try:
                info = json.loads(blob.decode("utf-8"))
            except ValueError:
                raise ImutoolError("Parquet: the imutool metadata is not valid JSON", path=path) from None
        self.imutool = info.get("format") == FORMAT_NAME
        if self.imutool and int(info.get("version", 0)) > VERSION:
            raise ImutoolError(
                f"Parquet: imutool-parquet version {info.get('version')} is newer than this "
                f"reader ({VERSION}); upgrade imutool",
                path=path,
            )
        self.meta: dict[str, Any] = dict(info.get("meta", {})) if self.imutool else {}
        final = (file_meta or {}).get(FINAL_META_KEY)
        if self.imutool and final is not None:
            try:
                self.meta.update(json.loads(final.decode("utf-8")))
            except ValueError:
                raise ImutoolError("Parquet: the imutool end-of-file metadata is not valid JSON", path=path) from None
        units: dict[str, str] = dict(info.get("units", {})) if self.imutool else {}
        numeric: list[str] = []
        skipped: list[str] = []
        self.time_is_timestamp = False
        for f in schema:
            t = f.type
            if f.name == "time" and pa.types.is_timestamp(t):
                self.time_is_timestamp = True
                numeric.append(f.name)
            elif pa.types.is_floating(t) or pa.types.is_integer(t) or pa.types.is_boolean(t):
                numeric.append(f.name)
                if not self.imutool and f.metadata and b"unit" in f.metadata:
                    units.setdefault(f.name, f.metadata[b"unit"].decode())
            else:
                skipped.append(f.name)
        if "time" not in numeric:
            raise ImutoolError(
                f"Parquet: no numeric 'time' column (seconds); has {', '.join(schema.names) or 'none'}", path=path
            )
        if skipped:
            self.meta["skipped_columns"] = skipped
        self.read_columns = numeric
        stored = info.get("columns") if self.imutool else None
        names = [n for n in numeric if n != "time"]
        if stored and sorted(c for cols in stored.values() for c in cols) == sorted(names):
            order = {n: i for i, n in enumerate(names)}
            self.groups = sorted(((ch, list(cols)) for ch, cols in stored.items()), key=lambda g: order[g[1][0]])
        else:
            self.groups = group_columns(names)
        self.units = {}
        for ch, cols in self.groups:
            u = canonical_unit(ch) or units.get(ch) or units.get(cols[0])
            if u is not None:
                self.units[ch] = u

    def recording(self, batch: Any) -> Recording:
        cols = {}
        for name in self.read_columns:
            arr = batch.column(name)
            if name == "time" and self.time_is_timestamp:
                ns = arr.cast(_pa().timestamp("ns")).cast(_pa().int64()).to_numpy(zero_copy_only=False)
                cols[name] = ns.astype(np.float64) / 1e9
                continue
            if arr.null_count:
                arr = arr.cast(_pa().float64()).fill_null(float("nan"))
            cols[name] = np.asarray(arr.to_numpy(zero_copy_only=False), dtype=np.float64)
        rec = Recording(cols["time"])
        for ch, names in self.groups:
            a = cols[names[0]] if len(names) == 1 else np.column_stack([cols[c] for c in names])
            rec.add(ch, a, self.units.get(ch), columns=names)
        rec.meta.update(json.loads(json.dumps(self.meta)))  # an independent copy per chunk
        rec.meta["source"] = self.path
        return rec


def _open(path: str | os.PathLike) -> Any:
    _pa()
    import pyarrow.parquet as pq

    path = os.fspath(path)
    if not os.path.exists(path):
        raise ImutoolError("no such file", path=path)
    try:
        return pq.ParquetFile(path, pre_buffer=False, buffer_size=1 << 20)  # streamed: no whole-file buffer
    except Exception as e:  # pyarrow raises ArrowInvalid/OSError with a long message
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ImutoolError(f"not a readable Parquet file ({msg})", path=path) from None


def parquet_info(path: str | os.PathLike) -> dict[str, Any]:
    """Rows, row groups, columns and the imutool metadata of a Parquet file, without reading the data."""
    pf = _open(path)
    plan = _Plan(pf.schema_arrow, os.fspath(path), pf.metadata.metadata)
    return {
        "rows": pf.metadata.num_rows,
        "row_groups": pf.metadata.num_row_groups,
        "columns": pf.schema_arrow.names,
        "imutool": plan.imutool,
        "meta": plan.meta,
    }


def iter_parquet(path: str | os.PathLike, chunk_rows: int = 500_000) -> Iterator[Recording]:
    """Stream a Parquet file as successive Recordings of at most ``chunk_rows`` rows (bounded memory).

    Same contract as :func:`formats.csv.iter_csv`: each chunk carries the file's metadata, units and column
    names; memory is O(row group + chunk), not O(file).
    """
    pf = _open(path)
    plan = _Plan(pf.schema_arrow, os.fspath(path), pf.metadata.metadata)
    try:
        for batch in pf.iter_batches(batch_size=int(chunk_rows), columns=plan.read_columns):
            if batch.num_rows:
                yield plan.recording(batch)
    except ImutoolError:
        raise
    except Exception as e:
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ImutoolError(f"cannot read Parquet data ({msg})", path=os.fspath(path)) from None


def read_parquet(path: str | os.PathLike) -> Recording:
    """Read a whole Parquet file into a Recording (imutool layout, or any table with a numeric ``time``)."""
    pf = _open(path)
    plan = _Plan(pf.schema_arrow, os.fspath(path), pf.metadata.metadata)
    try:
        table = pf.read(columns=plan.read_columns)
    except Exception as e:
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ImutoolError(f"cannot read Parquet data ({msg})", path=os.fspath(path)) from None
    if table.num_rows == 0:
        raise ImutoolError("no data rows", path=os.fspath(path))
    return plan.recording(table)
