"""Loading a recording the way every imutool command does: read, validate, bridge absurd samples, calibrate,
mount, check plausibility.

:func:`load_recording` is the library route behind every command's input (the routes call it through
:func:`imutool.routes.load_input`; the CLI adds only printing the warnings, :func:`imutool.cli.common.note_input`).
Nothing is printed here: what validation did and every plausibility warning come back in the report (and in
``rec.meta``).
"""

from __future__ import annotations

import os
import re
from typing import Any

import numpy as np

import formats
from formats import Recording
from formats.errors import ImutoolError
from formats.recording import (
    SENSOR_CHANNELS,
    all_nan_sensors,
    join_streams,
    missing_sensor_warnings,
    refuse_without_sensor_data,
    require_samples,
)

READ_OPTIONS = ("columns", "profile", "topic", "stamp", "duplicates", "backwards")
"""How a file's columns, bag topic and rows are read: a report's reference file (``--reference``) is read with
these too (its column mapping, :data:`MAPPING`, unless it is given its own)."""

INPUT_ONLY_OPTIONS = (
    "mounting",
    "calibration_file",
    "input_rate_hz",
    "time_column",
    "header_rows",
    "with_files",
    "with_offsets",
    "with_prefixes",
)
"""The input's own: its mounting and calibration, its clock, header and ``--with`` files (a reference has its
own clock options, :data:`REF_LOAD_OPTIONS`, and neither mounting nor calibration)."""

LOAD_OPTIONS = READ_OPTIONS + INPUT_ONLY_OPTIONS
"""How a path is loaded (:func:`load_recording`): the ``--columns ... --with`` options every command that reads a
recording takes."""

CSV_ONLY = {"rate_hz": "--rate", "time_column": "--time-column", "header_rows": "--header-rows"}

REF_LOAD_OPTIONS = {
    "ref_columns": ("columns", "--ref-columns"),
    "ref_profile": ("profile", "--ref-profile"),
    "ref_rate_hz": ("input_rate_hz", "--ref-rate"),
    "ref_time_column": ("time_column", "--ref-time-column"),
    "ref_header_rows": ("header_rows", "--ref-header-rows"),
    "ref_with_files": ("with_files", "--ref-with"),
    "ref_with_offsets": ("with_offsets", "--ref-with-offset"),
    "ref_with_prefixes": ("with_prefixes", "--ref-with-prefix"),
    "ref_start": ("start", "--ref-start"),
}
"""How a command's second recording (its reference: ``evaluate``, ``report inclinometer|heading``) is loaded: each
option → (the :func:`load_recording` parameter it sets for the reference, its command-line flag). The reference
goes through :func:`load_recording` as the main input does, with these in place of ``--columns ... --with``
(``columns``/``profile``: its own column mapping, given in place of the input's — where a command lets the reference
inherit the input's mapping, :data:`MAPPING`, either one replaces both); ``start`` (``--ref-start``) then puts its
first row at a given time (:func:`starting_at`): a clockless reference on the input's clock."""

MAPPING = ("columns", "profile")
"""The :func:`load_recording` options of a foreign CSV's column mapping (``--columns``, ``--profile``): a reference
given either of its own (``--ref-columns``, ``--ref-profile``) takes neither of the input's."""

FLAGS = {
    "columns": "--columns",
    "profile": "--profile",
    "input_rate_hz": "--rate",
    "time_column": "--time-column",
    "header_rows": "--header-rows",
    "with_files": "--with",
    "with_offsets": "--with-offset",
    "with_prefixes": "--with-prefix",
    "start": "--start",
}
"""The command-line flag of each loading option that says how a file's columns, times and header are read (what
:func:`how_loaded` records)."""


def load_recording(
    path: str | os.PathLike,
    *,
    columns: str | None = None,
    profile: str | None = None,
    topic: str | None = None,
    stamp: str = "header",
    duplicates: str = "drop",
    backwards: str = "error",
    mounting: str | None = None,
    calibration_file: str | None = None,
    validate: bool = True,
    strict: bool = False,
    input_rate_hz: float | None = None,
    time_column: str | None = None,
    header_rows: int | None = None,
    with_files: tuple[str, ...] | list[str] = (),
    with_offsets: tuple[float, ...] | list[float] = (),
    with_prefixes: tuple[str, ...] | list[str] = (),
    with_clock: str = "grid",
) -> tuple[Recording, dict[str, Any]]:
    """Read ``path`` (any format imutool reads) → (recording, validation report dict).

    columns/profile: foreign CSV column mapping; input_rate_hz (``--rate``, Hz: a CSV without a time column gets
    t = n / rate), time_column (``NAME[:UNIT]``, unit s/ms/us/ns), header_rows (a CSV's header rows: names, then
    units): how a CSV's time and header are read (:func:`formats.csv.read_header`); with_files: other recordings
    (sensors on other clocks) merged with this one (:func:`merge_with`; with_offsets: seconds added to each one's
    times, in order; with_prefixes: a prefix for each one's channel names, in order — two logs of one kind;
    with_clock: ``grid`` interpolates them onto this one's times, for a command that needs one grid, ``own`` keeps
    each on its own clock as a stream, :data:`WITH_CLOCKS`); topic/stamp: bag topic and time source;
    duplicates/backwards: validation policies (:meth:`formats.Recording.validated`); mounting: sensor→body
    ``'x,-y,-z[;r,p,y]'`` (deg); calibration_file: calibration TOML applied before mounting. The report holds
    rows read/kept/dropped and why, samples bridged, ``warnings`` (implausible units or axes, rows dropped...) and
    ``plausibility_figures``; what validation did and the warnings also go into ``rec.meta``. ``strict``: warnings
    raise an ImutoolError.
    """
    from formats import plausibility

    path = os.fspath(path)
    csv_opts = {"rate_hz": input_rate_hz, "time_column": time_column, "header_rows": header_rows}
    kind = formats.kind_of(path)
    rec = read_input(path, columns=columns, profile=profile, topic=topic, stamp=stamp, **csv_opts)
    report: dict[str, Any] = {}
    checks = plausibility.PlausibilityReport()
    if validate:
        n_in = len(rec)
        rec, rep = rec.validated(duplicates=duplicates, backwards=backwards, source=path)
        report = rep.as_dict()
        drops, warns = plausibility.dropped_rows(n_in, len(rec), report, rec.meta, duplicates)
        report.update(drops)
        checks.warnings += warns + missing_sensor_warnings(all_nan_sensors(rec))
        rec, checks = plausibility.bridge_absurd(rec, rep=checks)
    else:  # what the reader itself could not read is reported all the same
        t = rec.time[np.isfinite(rec.time)]
        distinct = 0 if not len(t) else (1 if np.ptp(t) == 0 else 2)  # rows at different times, up to two
        require_samples(len(rec), distinct, path, len(t) - distinct if distinct == 1 else 0)
        report, warns = plausibility.dropped_rows(len(rec), len(rec), {}, rec.meta)
        checks.warnings += warns
    if (with_offsets or with_prefixes) and not with_files:
        flag = "--with-offset is the clock offset" if with_offsets else "--with-prefix is the channel prefix"
        raise ImutoolError(f"{flag} of a --with FILE: give the file too")
    if with_files:
        rec, merged = merge_with(
            rec,
            path,
            list(with_files),
            list(with_offsets),
            list(with_prefixes),
            duplicates=duplicates,
            backwards=backwards,
            clock=with_clock,
        )
        report["with"] = merged["files"]
        checks.warnings += merged["warnings"]
    if calibration_file:
        from calibration import load_calibration

        rec = load_calibration(calibration_file).apply(rec)
    if mounting:
        remap, mis = formats.parse_mounting(mounting)
        rec = rec.mounted(remap, mis)
    if len(rec):  # also for commands that read without validating (info, plot): they show the warnings
        ok = np.all(np.diff(rec.time) > 0) if len(rec) > 1 else True
        found = plausibility.check_recording(
            rec if ok else rec.select(np.argsort(rec.time, kind="stable")), mounting, kind
        )
        checks.warnings += found.warnings
        checks.figures.update(found.figures)
        report.update({k: v for k, v in checks.as_dict().items() if k != "figures"})
        report["plausibility_figures"] = checks.figures
        if validate:
            rec.meta["validation"] = {k: v for k, v in report.items() if k not in ("plausibility_figures", "warnings")}
        else:
            report["validated"] = False
        if checks.warnings:
            rec.meta["warnings"] = merged_warnings(rec.meta, checks.warnings)
        if strict and checks.warnings:
            raise ImutoolError(strict_message(checks.warnings), path=path)
    return rec, report


MAPPED_KINDS = ("csv", "ros1", "ros2")  # inputs whose columns' units --columns/--profile can state


def mapping_options(path: str, columns: str | None, profile: str | None) -> dict[str, Any]:
    """The reader options of a column mapping (``--columns``/``--profile``) for ``path``: a foreign CSV's mapping,
    or a bag's unit and scale overrides; refused (ImutoolError) for an input that states its own units (Parquet,
    NMEA) rather than ignored."""
    if not columns and not profile:
        return {}
    kind = formats.kind_of(path)
    if kind not in MAPPED_KINDS:
        what = "--columns" if columns else "--profile"
        raise ImutoolError(
            f"{what} applies to a CSV or a ROS bag; a {kind.capitalize() if kind == 'parquet' else 'NMEA'} file "
            "states its own columns and units",
            path=path,
        )
    return {"columns": columns, "profile": profile}


def read_input(
    path: str,
    *,
    columns: str | None = None,
    profile: str | None = None,
    topic: str | None = None,
    stamp: str = "header",
    rate_hz: float | None = None,
    time_column: str | None = None,
    header_rows: int | None = None,
) -> Recording:
    """:func:`formats.read` of ``path`` with the options its format takes (CSV: columns, profile and the time
    and header options; bags: topic, stamp and a column mapping, :func:`mapping_options`); a CSV-only option given
    for another format is an ImutoolError."""
    kind = formats.kind_of(path)
    csv_opts = {"rate_hz": rate_hz, "time_column": time_column, "header_rows": header_rows}
    given = [CSV_ONLY[k] for k, v in csv_opts.items() if v is not None]
    if given and kind != "csv":
        raise ImutoolError(f"{', '.join(given)}: only for a CSV file (this is {kind})", path=path)
    opts: dict[str, Any] = mapping_options(path, columns, profile)
    if kind == "csv":
        opts.update(csv_opts)
    elif kind in ("ros1", "ros2"):
        opts.update(topic=topic, stamp=stamp)
    return formats.read(path, **opts)


WITH_CLOCKS = ("grid", "own")
"""How :func:`merge_with` joins a ``--with`` file: ``grid`` — interpolated onto the input's times, over the span
every file covers (a command that needs one grid: the filter, heave, calibration, events, ...); ``own`` — each file
a stream on its own clock (:func:`formats.recording.join_streams`: no resampling, every row of every file kept;
``evaluate``, which takes each channel on its own samples)."""


def merge_with(
    rec: Recording,
    path: str,
    with_files: list[str],
    with_offsets: list[float] | None = None,
    with_prefixes: list[str] | None = None,
    *,
    duplicates: str = "drop",
    backwards: str = "error",
    clock: str = "grid",
) -> tuple[Recording, dict[str, Any]]:
    """``rec`` (read from ``path``) with the channels of ``with_files`` (sensors on other clocks) → (merged
    recording, {"files": per file, "warnings": [...]}).

    Each file is read as it is (a CSV's columns inferred), put in time order with the ``duplicates``/``backwards``
    policies, its times shifted by its offset (``with_offsets``, s, in order; none: 0) and its channels renamed with
    its prefix (``with_prefixes``, in order; ``''`` or none: as they are) — two logs of one kind (two IMUs) need
    one. ``clock`` (:data:`WITH_CLOCKS`): ``grid`` interpolates them onto ``rec``'s times by :func:`formats.merge`,
    keeping only the span every file covers; ``own`` joins them without resampling
    (:func:`formats.recording.join_streams`: one stream per file, named by its file name). Files that do not
    overlap in time are refused (a clock offset is missing); so is a channel name two files share (which one
    would be meant is not clear: give a prefix). The metadata's ``merged`` says which file gave which channels,
    the time base and each offset and prefix.
    """
    if clock not in WITH_CLOCKS:
        raise ImutoolError(f"--with clock {clock!r}: expected one of {', '.join(WITH_CLOCKS)}")
    offsets = [float(v) for v in (with_offsets or [])]
    if offsets and len(offsets) != len(with_files):
        raise ImutoolError(
            f"--with-offset given {len(offsets)} time(s) for {len(with_files)} --with file(s): give one per file, "
            "in order (0 for none)"
        )
    prefixes = [str(p) for p in (with_prefixes or [])]
    if prefixes and len(prefixes) != len(with_files):
        raise ImutoolError(
            f"--with-prefix given {len(prefixes)} prefix(es) for {len(with_files)} --with file(s): give one per "
            "file, in order ('' for none)"
        )
    offsets = offsets or [0.0] * len(with_files)
    prefixes = prefixes or [""] * len(with_files)
    owner = {name: path for name in rec.channels}
    others: list[Recording] = []
    files: list[dict[str, Any]] = [{"input": path, "channels": list(rec.channels), "offset_s": 0.0, "rows": len(rec)}]
    warnings: list[str] = []
    for p, off, pre in zip(with_files, offsets, prefixes, strict=True):
        p = os.fspath(p)
        if not np.isfinite(off):
            raise ImutoolError(f"--with-offset {off}: not a finite number of seconds", path=p)
        if pre and not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", pre):
            raise ImutoolError(f"--with-prefix {pre!r}: letters, digits and _ only, starting with a letter", path=p)
        r = read_input(p)
        n_in = len(r)
        r, rep = r.validated(duplicates=duplicates, backwards=backwards, source=p)
        if not len(r):
            raise ImutoolError("no samples to merge (--with)", path=p)
        if pre:
            r = prefixed(r, pre)
        clash = [n for n in r.channels if n in owner]
        if clash:
            raise ImutoolError(
                f"--with: channel(s) {', '.join(clash)} also in {owner[clash[0]]}; which one to use is not clear "
                "(two logs of one kind: give each a prefix with --with-prefix, e.g. --with-prefix imu2_)",
                path=p,
            )
        owner.update({n: p for n in r.channels})
        if off:
            r = r.copy()
            r.time = r.time + off
        dropped = n_in - len(r)
        if dropped:
            warnings.append(f"--with {p}: {dropped} of {n_in} rows dropped by validation")
        files.append({"input": p, "channels": list(r.channels), "offset_s": off, "rows": len(r)})
        if pre:
            files[-1]["prefix"] = pre
        others.append(r)
    t0 = max(float(r.time[0]) for r in (rec, *others))
    t1 = min(float(r.time[-1]) for r in (rec, *others))
    if t1 <= t0:
        spans = "; ".join(
            f"{f['input']} {r.time[0]:.6g}…{r.time[-1]:.6g} s" for f, r in zip(files, (rec, *others), strict=True)
        )
        raise ImutoolError(
            f"--with: the files do not overlap in time ({spans}); give each one's clock offset with --with-offset",
            path=path,
        )
    meta = dict(rec.meta)
    if clock == "own":
        names = _stream_names([path, *(f["input"] for f in files[1:])])
        merged = join_streams([rec, *others], names)
        for f, n in zip(files, names, strict=True):
            f["stream"] = n
        meta.pop("streams", None)
        meta["streams"] = merged.meta.get("streams", {})
        meta["merged"] = {
            "time_base": f"each file on its own clock, one stream per file ({', '.join(names)}): the rows are the "
            "union of their times, nothing interpolated",
            "files": files,
            "span_s": [t0, t1],
            "rows_outside_common_span_dropped": 0,
        }
        merged.meta = meta
        return merged, {"files": files[1:], "warnings": warnings}
    merged = formats.merge([rec, *others], rec)
    kept = len(merged)
    meta.pop("streams", None)  # a many-clock input: every channel now interpolated onto each of its rows
    meta["merged"] = {
        "time_base": f"{path} (its {len(rec)} sample times; the others interpolated linearly onto them: this command "
        "needs one grid)",
        "files": files,
        "span_s": [t0, t1],
        "rows_outside_common_span_dropped": len(rec) - kept,
    }
    merged.meta = meta
    if len(rec) - kept > 0.01 * len(rec):  # a few rows at the ends are what merging clocks costs
        warnings.append(
            f"--with: {len(rec) - kept} of {len(rec)} rows of {path} outside the span every file covers dropped"
        )
    return merged, {"files": files[1:], "warnings": warnings}


def prefixed(rec: Recording, prefix: str) -> Recording:
    """``rec`` with every channel renamed ``prefix + name`` (units kept; CSV columns ``prefix + column``)."""
    out = Recording(rec.time.copy(), meta=dict(rec.meta), stream_rows={k: v.copy() for k, v in rec.stream_rows.items()})
    for name, a in rec.channels.items():
        out.add(prefix + name, a.copy(), rec.units.get(name), columns=[prefix + c for c in rec.columns.get(name, [])])
    if rec.streams:
        out.meta["streams"] = {k: [prefix + c for c in v] for k, v in rec.streams.items()}
    return out


def _stream_names(paths: list[str]) -> list[str]:
    """One stream name per file: its file name, numbered where two share one."""
    out: list[str] = []
    for p in paths:
        base = os.path.basename(p) or p
        name, k = base, 2
        while name in out:
            name, k = f"{base}#{k}", k + 1
        out.append(name)
    return out


def merged_warnings(meta: dict[str, Any], *more: list[str]) -> list[str]:
    """The ``warnings`` of ``meta`` (a list, or one string from another writer), then those of ``more`` that are
    not already there: what an output built from that input says."""
    prev = meta.get("warnings")
    out = list(prev) if isinstance(prev, (list, tuple)) else [str(prev)] if prev else []
    for ws in more:
        out += [w for w in ws if w not in out]
    return out


def strict_message(warnings: list[str]) -> str:
    """The one-line error the input warnings become under ``strict``."""
    return "; ".join(warnings) + " (an error because of --strict)"


def require_channels(rec: Recording, names: list[str] | tuple[str, ...], path: str) -> None:
    """Refuse (ImutoolError naming ``path``) a recording that lacks any of the channels ``names``."""
    missing = [n for n in names if n not in rec.channels]
    if missing:
        raise ImutoolError(f"needs channel(s) {', '.join(missing)}; has {', '.join(rec.channels) or 'none'}", path=path)


class ChunkChecks:
    """What :func:`load_recording` does to a whole file, done to a file read chunk by chunk (the streamed
    ``filter`` and ``convert``), so a large file is checked as a small one is.

    :meth:`prepare` bridges each chunk's absurd samples (counted over the run; more than 1 % of the rows seen so
    far is a unit error, and stays one; a run of them at a chunk's edge has no neighbour there and is set to NaN
    instead of interpolated), applies the calibration and the mounting, and runs the plausibility checks (units,
    axes, gravity direction). With ``rows_expected`` (the file's rows; for a CSV an estimate from its first MiB)
    they look at the six stretches of the whole file an in-memory load looks at
    (:func:`formats.plausibility.sample_stretches`), collected as the chunks pass and checked once the last one
    is in (or at :meth:`finish`): a voyage that starts in harbour is judged on its motion, whatever the chunk
    size. Without it, they look at the first chunk. :meth:`finish` accounts for every row the run dropped with
    the same > 1 % warning and returns the warnings, for stderr and the summary; :meth:`meta_warnings` adds the
    input's own for the output's metadata. ``strict``: a warning raises an ImutoolError (inside a streamed
    writer: no output).
    """

    def __init__(
        self,
        path: str,
        *,
        mounting: str | None = None,
        calibration_file: str | None = None,
        strict: bool = False,
        rows_expected: int | None = None,
    ):
        from formats import plausibility

        self.path = path
        self.kind = formats.kind_of(path)
        self.mounting = mounting
        self.strict = strict
        self.cal = None
        if calibration_file:
            from calibration import load_calibration

            self.cal = load_calibration(calibration_file)
        self.mount = formats.parse_mounting(mounting) if mounting else None
        self.warnings: list[str] = []  # the plausibility checks' warnings
        self.earlier: list[str] = []  # warnings the input file itself carries (an estimate's, ...)
        self._absurd = plausibility.PlausibilityReport()
        self._checked = False
        # the rows [start, stop) the plausibility checks look at (None: the first chunk), and those collected
        self._stretches = plausibility.sample_stretches(rows_expected) if rows_expected else None
        self._sampled: list[Recording] = []
        self._rows = 0
        self._sensors: dict[str, bool] = {}  # sensor channel → some value seen (not NaN)

    def prepare(self, chunk: Recording) -> Recording:
        """The chunk to use: absurd samples bridged, calibrated, mounted (its times must already increase)."""
        from formats import plausibility

        self._rows += len(chunk)
        for k in SENSOR_CHANNELS:
            if k in chunk.channels and not self._sensors.get(k):
                self._sensors[k] = k not in all_nan_sensors(chunk)
        chunk, _ = plausibility.bridge_absurd(chunk, rep=self._absurd, out_of=self._rows)
        if self.cal is not None:
            chunk = self.cal.apply(chunk)
        if self.mount is not None:
            chunk = chunk.mounted(*self.mount)
        if len(chunk) and self._rows == len(chunk):  # the first rows
            self.earlier = merged_warnings(chunk.meta)
        if self._stretches is None:
            if not self._checked and len(chunk):
                self._check_plausibility([chunk])
        elif not self._checked:
            first = self._rows - len(chunk)  # the chunk's first row in the file
            for a, b in self._stretches:
                lo, hi = max(a, first) - first, min(b, self._rows) - first
                if hi > lo:
                    self._sampled.append(chunk.select(slice(lo, hi)))
            if self._rows >= self._stretches[-1][1]:
                self._check_plausibility(self._sampled)
        return chunk

    def _check_plausibility(self, pieces: list[Recording]) -> None:
        """Run the plausibility checks on ``pieces`` (once), keep their warnings and refuse under ``strict``."""
        from formats import plausibility

        self._checked = True
        self._sampled = []
        rec = pieces[0] if len(pieces) == 1 else plausibility.joined_rows(pieces)
        found = plausibility.check_recording(rec, self.mounting, self.kind)
        self.warnings += found.warnings
        self._refuse(found.warnings)

    def finish(
        self,
        rows_read: int,
        rows_kept: int,
        *,
        duplicates: int = 0,
        skipped: int = 0,
        reader_meta: dict[str, Any] | None = None,
    ) -> tuple[dict[str, Any], list[str]]:
        """(validation report, every warning of the run). rows_read: rows the reader returned; rows_kept: rows
        used; duplicates: of the rows dropped, those whose time repeated the row before; skipped: malformed
        rows the reader skipped (or ``reader_meta``: the reader's metadata, e.g. a bag's, which hold them)."""
        from formats import plausibility

        if not self._checked and self._sampled:  # fewer rows than expected: the stretches read so far
            self._check_plausibility(self._sampled)
        require_samples(rows_read, rows_kept, self.path, duplicates)
        empty = [k for k, seen in self._sensors.items() if not seen]
        refuse_without_sensor_data(empty, list(self._sensors), self.path)
        missing = missing_sensor_warnings(empty)
        report, dropped = plausibility.dropped_rows(
            rows_read,
            rows_kept,
            {"duplicate_timestamps": duplicates},
            reader_meta if reader_meta is not None else {"skipped_rows": skipped},
        )
        for counts in self._absurd.absurd.values():
            counts[1] = rows_read  # the share of a unit error is over the whole run
        absurd = self._absurd.absurd_warnings()
        report.update({k: v for k, v in self._absurd.as_dict().items() if k.startswith("absurd_")})
        self._refuse(missing + absurd + dropped)
        return report, self.warnings + missing + absurd + dropped

    def meta_warnings(self, *more: list[str]) -> list[str]:
        """The output's ``warnings``: the input's own, then these (each once)."""
        return merged_warnings({"warnings": self.earlier}, *more)

    def _refuse(self, warnings: list[str]) -> None:
        if self.strict and warnings:
            raise ImutoolError(strict_message(warnings), path=self.path)


INPUT_NOTES = ("warnings", "validation", "clock")


def one_clock(
    rec: Recording, drivers: tuple[str, ...] | list[str], inputs: list[dict[str, Any]] | None = None
) -> Recording:
    """A many-clock input (formats.Recording: several streams) on the clock of the first of ``drivers`` it holds:
    that stream's own samples, every other channel held at its latest own sample at or before each of them
    (:meth:`formats.Recording.on_clock`) — what a command whose estimator needs one time base computes on, never
    another stream's row as a missing sample. Says so in ``meta['clock']`` (carried into outputs by
    :func:`input_notes`) and in the last report of ``inputs``. A single-clock recording, or none of ``drivers``
    present (the command's own check names what is missing), is returned as it is."""
    if not rec.multi_clock:
        return rec
    by_column = {col: name for name, cols in rec.columns.items() for col in cols}
    drv = next((c if c in rec.channels else by_column[c] for c in drivers if c in rec.channels or c in by_column), None)
    if drv is None:
        return rec
    out = rec.on_clock(drv)
    key = rec.stream_of(drv) or drv
    note: dict[str, Any] = {
        "stream": key,
        "samples": len(out),
        "rows_in_table": len(rec),
        "note": f"computed on the {key} stream's own {len(out)} samples (of {len(rec)} rows of {len(rec.streams)} "
        "streams)",
    }
    if out.meta.get("resampled"):
        note["resampled"] = out.meta["resampled"]
    out.meta["clock"] = note
    if inputs:
        inputs[-1]["clock"] = note
    return out


def input_notes(meta: dict[str, Any]) -> dict[str, Any]:
    """What loading found about an input (``warnings`` and ``validation`` in its metadata, from
    :func:`load_recording`), for the metadata of an output built from it: an estimate says what was wrong with
    the data it came from."""
    return {k: meta[k] for k in INPUT_NOTES if meta.get(k)}


def reference_load_options(options: dict[str, Any]) -> dict[str, Any]:
    """The :func:`load_recording` options of a reference from ``options`` (keys of :data:`REF_LOAD_OPTIONS`; the
    ones not given — None or empty — left out, so a reference without them loads as before). An unknown key is a
    TypeError (a caller's mistake)."""
    unknown = set(options) - set(REF_LOAD_OPTIONS)
    if unknown:
        raise TypeError(f"unexpected reference option(s) {', '.join(sorted(unknown))}")
    out: dict[str, Any] = {}
    for k, v in options.items():
        if v is None or (isinstance(v, (tuple, list)) and not v):
            continue
        out[REF_LOAD_OPTIONS[k][0]] = tuple(v) if isinstance(v, (tuple, list)) else v
    return out


def split_reference_options(options: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(``options`` without the reference's, the reference's :func:`load_recording` options given): what a route
    that reads a reference does with its keyword arguments (:func:`reference_load_options`)."""
    ref = {k: options[k] for k in REF_LOAD_OPTIONS if k in options}
    rest = {k: v for k, v in options.items() if k not in REF_LOAD_OPTIONS}
    return rest, reference_load_options(ref)


def reference_text(text: str, inherited: tuple[str, ...] | list[str] = ()) -> str:
    """``text`` (an error or a note about loading) with the main input's loading flags named as the reference's
    (``--columns`` → ``--ref-columns``, ``--rate`` → ``--ref-rate``, ``--with`` → ``--ref-with`` ...): what a user
    of the reference typed. ``inherited``: the :func:`load_recording` options the reference took from the input
    (its ``columns``/``profile`` where a command lets it inherit them): their flags stay the input's."""
    keep = {FLAGS[k] for k in inherited if k in FLAGS}
    names = [re.escape(f[2:]) for f in FLAGS.values() if f not in keep]
    return re.sub(rf"(?<![\w-])--({'|'.join(names)})(?![\w-])", r"--ref-\1", text)


def how_loaded(rec: Recording, given: dict[str, Any], reference: bool = False) -> dict[str, Any]:
    """How a recording was loaded, for a report's JSON/PDF and a summary: ``options`` (the column mapping, time and
    header options given — :func:`load_recording` names — by flag; ``reference``: the reference's flags,
    ``--ref-columns``, ``--ref-rate`` ...),
    ``time`` (where its times came from: its reader's ``time_source``), ``dated`` (whether its times give a UTC
    clock time, :class:`imutool.clock.Clock`) and ``merged`` (each ``--with`` file, its channels and clock
    offset, s)."""
    from imutool.clock import Clock

    name = reference_text if reference else str
    opts = {
        name(f): (list(given[k]) if isinstance(given[k], tuple) else given[k]) for k, f in FLAGS.items() if k in given
    }
    src = rec.meta.get("time_source")
    out: dict[str, Any] = {
        "options": opts,
        "time": name(str(src)) if src else "the file's own times (time column or stamps)",
        "dated": Clock.of(rec).dated,
    }
    merged = rec.meta.get("merged")
    if isinstance(merged, dict) and merged.get("files"):
        out["merged"] = [
            {"input": f["input"], "channels": f["channels"], "offset_s": f["offset_s"]}
            | ({"prefix": f["prefix"]} if f.get("prefix") else {})
            for f in merged["files"][1:]
        ]
        if "own clock" in str(merged.get("time_base", "")):
            out["merged_clocks"] = "own (one stream per file, nothing interpolated)"
    return out


def starting_at(rec: Recording, start: float | str, path: str) -> Recording:
    """``rec`` with its times shifted so that its first row is at ``start``: seconds on the other recording's
    clock, or an ISO 8601 UTC time (its times become Unix seconds: a date). The shift (s) is in the metadata
    (``time_shift_s``, and said in ``time_source``)."""
    from imutool.clock import parse_utc

    try:
        t0 = float(start)
    except (TypeError, ValueError):
        t0 = parse_utc(str(start))
        if t0 is None:
            raise ImutoolError(
                f"--start {start!r}: expected seconds or a UTC date and time (e.g. 2014-08-01T12:00:00Z)", path=path
            ) from None
    if not np.isfinite(t0):
        raise ImutoolError(f"--start {start!r}: not a finite time", path=path)
    if not len(rec):
        return rec
    shift = t0 - float(rec.time[0])
    out = rec.copy()
    out.time = rec.time + shift
    was = rec.meta.get("time_source")
    out.meta["time_shift_s"] = shift
    out.meta["time_source"] = (f"{was}; " if was else "") + f"shifted {shift:+.3f} s: first row at --start {start}"
    return out


def loading_text(ld: dict[str, Any]) -> str:
    """How an input was loaded (``inputs.*.loading``, :func:`imutool.loading.how_loaded`) in one line: options
    given, where its times came from, its date, the files merged onto it."""
    opts = ", ".join(
        f"{k} {' '.join(str(x) for x in v) if isinstance(v, list) else v}" for k, v in (ld.get("options") or {}).items()
    )
    parts = [
        opts or "no time or header option",
        f"times: {ld.get('time')}",
        "dated (UTC)" if ld.get("dated") else "no date",
    ]
    for m in ld.get("merged") or []:
        parts.append(f"merged {m['input']} ({', '.join(m.get('channels') or [])}; {m['offset_s']:+g} s)")
    return "; ".join(parts)
