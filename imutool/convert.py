"""Conversion between every format imutool reads and writes: the one route behind ``imutool convert``,
``imutool batch convert`` and a Python user.

:func:`run_convert` picks the way. CSV/Parquet → CSV/Parquet streams (:func:`stream_convert`): the input is read
chunk by chunk (:func:`formats.iter_chunks`, Parquet by row groups), each chunk validated (plus a check across chunk
boundaries), calibrated and mounted if asked, and appended to an atomic writer — bounded memory. Anything else
(bags, NMEA, or a policy that needs the whole file: ``backwards='sort'``, ``duplicates='mean'``) is read whole,
validated, calibrated, mounted and written; bags convert REP-103 FLU/ENU ↔ FRD/NED at the boundary
(:mod:`formats.bags`). Returns a :class:`imutool.routes.RouteResult` whose summary says rows in/out, channels,
conversions applied and what the output format could not carry.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import numpy as np

import formats
from formats.errors import ImutoolError
from formats.frames import quat_to_euler
from imutool.loading import (
    LOAD_OPTIONS,
    ChunkChecks,
    load_recording,
    mapping_options,
    merge_with,
    merged_warnings,
    read_input,
)
from imutool.progress import Progress, estimate_rows, report
from imutool.routes import RouteResult

STREAMABLE = ("csv", "parquet")


def chunk_writer(path: str | os.PathLike, background: bool = False) -> Any:
    """An atomic incremental writer (``with w: w.write(chunk)``; ``w.rows``) for a .csv or .parquet output;
    ``background``: each chunk is written by a worker thread while the caller prepares the next. Metadata given
    to ``set_final_meta`` go into the CSV's header (the rows copied once behind it) or the Parquet footer."""
    kind = formats.kind_of(path, for_output=True)
    if kind == "csv":
        from formats.csv import CsvWriter

        return CsvWriter(os.fspath(path), background=background)
    if kind == "parquet":
        from formats.parquet import ParquetWriter

        return ParquetWriter(os.fspath(path), background=background)
    raise ImutoolError(
        f"streamed output must be .csv or .parquet (got {formats.kind_of(path, True)})", path=os.fspath(path)
    )


def stream_convert(
    src: str,
    dst: str,
    *,
    chunk_rows: int = 500_000,
    columns: str | None = None,
    profile: str | None = None,
    duplicates: str = "drop",
    backwards: str = "error",
    mounting: str | None = None,
    calibration_file: str | None = None,
    strict: bool = False,
    progress: Progress | None = None,
    input_rate_hz: float | None = None,
    time_column: str | None = None,
    header_rows: int | None = None,
) -> dict[str, Any]:
    """Convert ``src`` to ``dst`` (CSV or Parquet each) chunk by chunk; returns the summary dict.

    Validation is per chunk plus a check across chunk boundaries (a time not after the previous chunk's last
    one is dropped, or refused with ``backwards='error'``/``duplicates='error'``); streaming cannot sort. The
    input checks of a whole-file load are made chunk by chunk (:class:`imutool.loading.ChunkChecks`); their
    report is the summary's ``validation``, and it and the warnings go into the output's metadata at the end.
    ``progress(rows_read, rows_expected)`` after each chunk (expected: Parquet footer count, CSV estimate).
    """
    if os.path.abspath(src) == os.path.abspath(dst):
        raise ImutoolError("output would overwrite the input", path=dst)
    opts: dict[str, Any] = mapping_options(src, columns, profile)
    total = expected_rows(src)
    checks = ChunkChecks(src, mounting=mounting, calibration_file=calibration_file, strict=strict, rows_expected=total)
    time_opts = {"rate_hz": input_rate_hz, "time_column": time_column, "header_rows": header_rows}
    if formats.kind_of(src) == "csv":
        opts.update(time_opts)
    elif any(v is not None for v in time_opts.values()):
        read_input(src, **time_opts)  # the one-line refusal of a CSV-only option
    chunks = formats.iter_chunks(src, chunk_rows=chunk_rows, **opts)
    rows_in = 0
    dropped_boundary = duplicates_dropped = 0
    actions: list[str] = []
    channels: list[str] = []
    last_t = -np.inf
    skipped = 0
    with chunk_writer(dst) as w:
        for chunk in chunks:
            rows_in += len(chunk)
            report(progress, rows_in, total)
            if len(chunk) and chunk.time[0] <= last_t:
                early = chunk.time <= last_t
                back = chunk.time < last_t
                if back.any() and backwards != "drop":
                    raise ImutoolError(
                        f"time goes backwards across a chunk boundary (row ≈ {rows_in - len(chunk) + 1}"
                        f"); streaming cannot sort: use --backwards drop or --no-stream",
                        path=src,
                    )
                if (early & ~back).any() and duplicates == "error":
                    raise ImutoolError("duplicate timestamp across a chunk boundary", path=src)
                dropped_boundary += int(early.sum())
                duplicates_dropped += int((early & ~back).sum())
                chunk = chunk.select(~early)
            skipped = int(chunk.meta.get("skipped_rows", skipped) or 0)  # the reader's running total
            if len(chunk) == 0:
                continue
            chunk, rep = chunk.validated(
                duplicates=duplicates,
                backwards="error" if backwards == "sort" else backwards,
                source=src,
                min_rows=0,  # the stream as a whole is checked at its end (ChunkChecks.finish)
            )
            actions += rep.actions
            duplicates_dropped += int(rep.duplicates)
            chunk = checks.prepare(chunk)
            last_t = float(chunk.time[-1])
            channels = list(chunk.channels)
            w.write(chunk)
        if rows_in == 0:
            raise ImutoolError("no data rows", path=src)
        rows_out = w.rows
        validation, warnings = checks.finish(rows_in, rows_out, duplicates=duplicates_dropped, skipped=skipped)
        everything = checks.meta_warnings(warnings)
        w.set_final_meta({"validation": validation, **({"warnings": everything} if everything else {})})
    if dropped_boundary:
        actions.append(f"dropped {dropped_boundary} rows at chunk boundaries (time not after the previous chunk)")
    validation["warnings"] = warnings
    return {
        "rows_in": rows_in,
        "rows_out": rows_out,
        "channels": channels,
        "streamed": True,
        "validation_actions": actions,
        "validation": validation,
    }


def expected_rows(path: str | os.PathLike) -> int | None:
    """Rows to expect (for progress totals): a Parquet file's footer count, a CSV's estimate from its first MiB;
    None for other formats or when unreadable."""
    kind = formats.kind_of(path)
    if kind == "parquet":
        from formats.parquet import parquet_info

        try:
            return int(parquet_info(path)["rows"])
        except ImutoolError:
            return None
    if kind == "csv":
        return estimate_rows(path)
    return None


def streams(
    src: str | os.PathLike,
    dst: str | os.PathLike,
    *,
    stream: bool = True,
    duplicates: str = "drop",
    backwards: str = "error",
    merging: bool = False,
) -> bool:
    """Whether :func:`run_convert` streams: CSV/Parquet → CSV/Parquet, streaming allowed, and no policy that needs the
    whole file (``backwards='sort'``, ``duplicates='mean'``, ``merging``
    other files with ``--with``)."""
    return (
        stream
        and not merging
        and formats.kind_of(src) in STREAMABLE
        and formats.kind_of(dst, for_output=True) in STREAMABLE
        and backwards != "sort"
        and duplicates != "mean"
    )


def run_convert(
    src: str | os.PathLike,
    dst: str | os.PathLike,
    *,
    stream: bool = True,
    chunk_rows: int = 500_000,
    sentences: str | tuple[str, ...] = "HDT,XDR",
    nmea_rate: float | None = None,
    talker: str | None = None,
    imu_topic: str = "/imu/data",
    mag_topic: str = "/imu/mag",
    frame_id: str | None = None,
    storage: str | None = None,
    compression: str = "none",
    vector3_mag_unit: str = "T",
    strict: bool = False,
    progress: Progress | None = None,
    stage: Callable[[str], None] | None = None,
    on_input: Callable[[str, dict[str, Any]], None] | None = None,
    **load_options: Any,
) -> RouteResult:
    """Convert ``src`` to ``dst`` (format from each name's extension: .csv, .parquet, .bag, .db3/.mcap or a folder,
    .nmea/.log): the route behind ``imutool convert`` and ``imutool batch convert``. Returns its summary and what
    loading the input did (``inputs``); nothing is printed.

    load_options: columns, profile, topic, stamp, duplicates, backwards, mounting, calibration_file (as
    :func:`imutool.loading.load_recording`; a bag input is read with topic/stamp/``vector3_mag_unit`` and gets
    the same checks through :class:`imutool.loading.ChunkChecks`). NMEA output: ``sentences`` (e.g. 'HDT,XDR'),
    ``nmea_rate`` Hz, ``talker``; roll/pitch/heading (deg) are derived from ``q`` when only a quaternion is there.
    Bag output: ``imu_topic``, ``mag_topic``, ``frame_id``, ``storage`` (ROS2 sqlite3/mcap), ``compression``
    (ROS1 none/bz2/lz4). ``stream=False`` reads CSV/Parquet whole. ``progress(rows, total)`` while streaming;
    ``stage(name)`` ('reading', 'writing') otherwise; ``on_input(path, report)`` after a whole-file load.
    """
    unknown = set(load_options) - set(LOAD_OPTIONS)
    if unknown:
        raise TypeError(f"run_convert() got unexpected keyword argument(s) {', '.join(sorted(unknown))}")
    src, dst = os.fspath(src), os.fspath(dst)
    inputs: list[dict[str, Any]] = []

    def noted(path: str, rep: dict[str, Any]) -> None:
        inputs.append({"input": path, **rep})
        if on_input is not None:
            on_input(path, rep)

    opt = {k: load_options.get(k) for k in LOAD_OPTIONS}
    duplicates = opt["duplicates"] or "drop"
    backwards = opt["backwards"] or "error"
    mounting, calibration_file = opt["mounting"], opt["calibration_file"]
    kin = formats.kind_of(src)
    kout = formats.kind_of(dst, for_output=True)
    summary: dict[str, Any] = {"input": src, "output": dst, "from": kin, "to": kout}
    conversions: list[str] = []
    if streams(src, dst, stream=stream, duplicates=duplicates, backwards=backwards, merging=bool(opt["with_files"])):
        summary.update(
            stream_convert(
                src,
                dst,
                chunk_rows=chunk_rows,
                columns=opt["columns"],
                profile=opt["profile"],
                duplicates=duplicates,
                backwards=backwards,
                mounting=mounting,
                calibration_file=calibration_file,
                strict=strict,
                progress=progress,
                input_rate_hz=opt["input_rate_hz"],
                time_column=opt["time_column"],
                header_rows=opt["header_rows"],
            )
        )
        summary["conversions"] = ["none (same frames and units)"]
        noted(src, summary.pop("validation"))
        return RouteResult(summary, inputs)
    if stage is not None:
        stage("reading")
    if kin in ("ros1", "ros2"):
        if any(opt[k] is not None for k in ("input_rate_hz", "time_column", "header_rows")):  # refused: CSV only
            read_input(
                src, rate_hz=opt["input_rate_hz"], time_column=opt["time_column"], header_rows=opt["header_rows"]
            )
        rec = formats.read(
            src,
            topic=opt["topic"],
            stamp=opt["stamp"] or "header",
            vector3_mag_unit=vector3_mag_unit,
            **mapping_options(src, opt["columns"], opt["profile"]),
        )
        rows_in = len(rec)
        bag = rec.meta.get("bag", {})
        conversions += [f"in: {c}" for c in bag.get("conversions", [])]
        summary["bag_in"] = {
            "format": bag.get("format"),
            "stamp": bag.get("stamp"),
            "topics": {k: v.get("topic") for k, v in bag.get("topics", {}).items()},
            "frame_id": bag.get("frame_id"),
        }
        if bag.get("partial_read"):
            summary["warning"] = bag["partial_read"]
        if bag.get("notes"):
            summary["notes"] = bag["notes"]
        rec, rep = rec.validated(duplicates=duplicates, backwards=backwards, source=src)
        summary["validation_actions"] = rep.actions
        merged_notes: list[str] = []
        if opt["with_files"]:
            rec, merged = merge_with(
                rec,
                src,
                list(opt["with_files"]),
                list(opt["with_offsets"] or ()),
                list(opt["with_prefixes"] or ()),
                duplicates=duplicates,
                backwards=backwards,
            )
            merged_notes = merged["warnings"]
        checks = ChunkChecks(src, mounting=mounting, calibration_file=calibration_file, strict=strict)
        rec = checks.prepare(rec)  # the bag whole, as one chunk: the checks of any other input
        report, warns = checks.finish(rows_in, len(rec), duplicates=rep.duplicates, reader_meta=rec.meta)
        warns = warns + merged_notes
        rec.meta["validation"] = report
        if warns:
            rec.meta["warnings"] = merged_warnings(rec.meta, warns)
        if len(rec):
            noted(src, {**report, "warnings": warns})
    else:
        rec, rep2 = load_recording(src, strict=strict, **{k: v for k, v in opt.items() if v is not None})
        if len(rec):
            noted(src, rep2)
        rows_in = int(rep2.get("rows", len(rec)))
        summary["validation_actions"] = rep2.get("actions", [])
    if mounting:
        conversions.append(f"mounting {mounting} applied (sensor → body)")
    opts: dict[str, Any] = {}
    if kout in ("ros1", "ros2"):
        opts = {"topic": imu_topic, "mag_topic": mag_topic, "frame_id": frame_id}
        if kout == "ros2" and storage:
            opts["storage"] = storage
        if kout == "ros1" and compression != "none":
            opts["compression"] = compression
    elif kout == "nmea":
        if "q" in rec and not any(k in rec for k in ("roll", "pitch", "heading")):
            r, p, h = quat_to_euler(rec["q"])
            rec = rec.copy()
            for name, v in (("roll", r), ("pitch", p), ("heading", h)):
                rec.add(name, np.degrees(v), "deg")
            conversions.append("roll/pitch/heading (deg, ZYX) derived from q (body FRD → NED) for NMEA")
        names = sentences.split(",") if isinstance(sentences, str) else sentences
        opts = {
            "sentences": tuple(s.strip().upper() for s in names if s.strip()),
            "rate_hz": nmea_rate,
            "talker": talker,
        }
    if stage is not None:
        stage("writing")
    res = formats.write(rec, dst, **opts)
    summary["rows_in"] = rows_in
    summary["channels"] = list(rec.channels)
    if kout in ("ros1", "ros2") and isinstance(res, dict):
        summary["rows_out"] = max(res["messages"].values()) if res["messages"] else 0
        summary["messages_out"] = res["messages"]
        summary["channels_written"] = res["channels_written"]
        summary["channels_not_written"] = res["channels_not_written"]
        conversions += [f"out: {c}" for c in res["conversions"]]
    elif kout == "nmea" and isinstance(res, dict):
        summary["rows_out"] = len(rec)
        summary["sentences_out"] = res.get("sentences")
    else:
        summary["rows_out"] = len(rec)
    summary["conversions"] = conversions or ["none (same frames and units)"]
    return RouteResult(summary, inputs, rec)
