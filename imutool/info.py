"""What a recording holds — duration, rate, time-base problems, channels, units, ranges: the route behind
``imutool info`` and ``imutool batch info``.

:func:`run_info` reads a file without validating it (what validation *would* do is part of the answer), and
:func:`summarize` describes it: rows, start/end/duration, rate and step statistics, gaps, duplicate timestamps,
backwards steps, NaN rows, channels with units and min/mean/max per axis (angles and rates in degrees), metadata,
the foreign-CSV column mapping used and, for an NMEA log, every sentence named and counted. Nothing is printed.
"""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

import formats
from formats import Recording
from formats.errors import ImutoolError
from formats.nmea import sentence_summary
from formats.timing import stream_timing
from imutool.routes import OnInput, RouteResult, load_input

# units shown in degrees (DESIGN: degrees at every user-facing surface); the file keeps what its header says
_DEG_UNITS = {"rad/s": "deg/s", "rad": "deg", "rad/s^2": "deg/s^2"}

_HIDDEN_META = {
    "validation",
    "column_mapping",
    "column_mapping_origin",
    "skipped_rows",
    "skipped_rows_first",
    "sentence_timing",  # shown as the summary's own sentence_timing
}


def _num(v: float) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _channel_stats(rec: Recording) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, a in rec.channels.items():
        a2 = a.reshape(len(a), -1).astype(float)
        unit = rec.units.get(name)
        if unit in _DEG_UNITS:
            a2 = np.degrees(a2)
        with np.errstate(all="ignore"):
            ok = ~np.isnan(a2)
            any_ok = ok.any(axis=0)
            mn = np.where(any_ok, np.nanmin(np.where(ok, a2, np.inf), axis=0), np.nan) if len(a2) else []
            mx = np.where(any_ok, np.nanmax(np.where(ok, a2, -np.inf), axis=0), np.nan) if len(a2) else []
            mean = np.where(any_ok, np.nansum(a2, axis=0) / np.maximum(ok.sum(axis=0), 1), np.nan) if len(a2) else []
        out[name] = {
            "unit": _DEG_UNITS.get(unit, unit),
            "columns": list(rec.columns.get(name, [name])),
            "min": [_num(v) for v in mn],
            "max": [_num(v) for v in mx],
            "mean": [_num(v) for v in mean],
        }
        if unit in _DEG_UNITS:
            out[name]["unit_in_file"] = unit
    return out


def summarize(
    path: str | os.PathLike, rec_raw: Recording, duplicates: str = "drop", backwards: str = "error"
) -> dict[str, Any]:
    """The summary dict of ``imutool info`` for a recording read from ``path`` (not yet validated)."""
    t = rec_raw.time
    steps = np.diff(t) if len(t) > 1 else np.empty(0)
    n_back = int(np.count_nonzero(steps < 0))
    notes = []
    policy = backwards
    if n_back and backwards == "error":
        policy = "sort"
        notes.append(
            f"time goes backwards {n_back} times: other commands refuse this file unless given "
            "--backwards sort|drop (summarised here after sorting)"
        )
    rec, rep = rec_raw.validated(duplicates=duplicates, backwards=policy, source=path)
    pos = np.diff(rec.time) if len(rec) > 1 else np.empty(0)
    gaps = rep.gaps
    summary: dict[str, Any] = {
        "file": os.fspath(path),
        "format": formats.kind_of(path),
        "rows": len(rec_raw),
        "rows_after_validation": len(rec),
        "start_s": _num(rec.time[0]) if len(rec) else None,
        "end_s": _num(rec.time[-1]) if len(rec) else None,
        "duration_s": _num(rec.duration),
        "rate_hz": _num(rec.rate_hz),
        "step_s": {
            "median": _num(np.median(pos)) if pos.size else None,
            "min": _num(pos.min()) if pos.size else None,
            "max": _num(pos.max()) if pos.size else None,
        },
        "gaps": {
            "count": len(gaps),
            "missing_s": _num(sum(g[1] for g in gaps) - len(gaps) * rep.median_dt) if gaps else 0.0,
            "first": [{"start_s": a, "length_s": b} for a, b in gaps[:10]],
        },
        "duplicate_timestamps": rep.duplicates,
        "duplicate_timestamps_with_different_data": rep.duplicates_conflicting,
        "backwards_steps": n_back,
        "rows_with_nan": rep.nan_rows,
        "nan_by_channel": dict(rep.nan_by_channel),
        "skipped_rows": int(rec_raw.meta.get("skipped_rows", 0)),
        "skipped_rows_first": list(rec_raw.meta.get("skipped_rows_first", [])),
        "channels": _channel_stats(rec),
        "metadata": {k: v for k, v in rec_raw.meta.items() if k not in _HIDDEN_META},
        "column_mapping": None,
        "validation_actions": list(rep.actions) + notes,
    }
    if rec.multi_clock:
        _per_stream(rec, summary)
    if rec_raw.meta.get("sentences"):  # an NMEA log: every sentence named and counted, read or not
        summary["nmea_sentences"] = sentence_summary(rec_raw.meta)
    bag = rec_raw.meta.get("bag")
    if isinstance(bag, dict) and bag.get("topics_not_read"):  # a bag: every topic not read, named and counted
        summary["bag_topics_not_read"] = list(bag["topics_not_read"])
    _own_timing(rec, rec_raw.meta, summary)
    cm = rec_raw.meta.get("column_mapping")
    if cm:
        summary["column_mapping"] = {
            "origin": rec_raw.meta.get("column_mapping_origin", "inferred"),
            "columns": [s.strip() for s in str(cm).split(";") if s.strip()],
        }
    return summary


def _per_stream(rec: Recording, summary: dict[str, Any]) -> None:
    """A many-clock recording (formats.Recording): rate, samples, duration and gaps of each stream on its own
    samples; the table's rows (the union of every stream's times) have no rate or gaps of their own, so the
    top-level ``rate_hz`` and ``step_s`` are null and ``gaps`` sums the streams' gaps."""
    streams = rec.stream_summary()
    first: list[dict[str, Any]] = []
    for k, v in streams.items():
        tm = rec.stream_timing(k, max_gaps=10)
        v["timing"] = tm
        first += [{"stream": k, "start_s": a, "length_s": b} for a, b in tm.get("first_gaps", [])]
    summary["streams"] = streams
    summary["rate_hz"] = None
    summary["step_s"] = {"median": None, "min": None, "max": None, "note": "per stream: see streams"}
    summary["gaps"] = {
        "count": int(sum(v["gaps"] for v in streams.values())),
        "missing_s": float(sum(v["missing_s"] for v in streams.values())),
        "first": sorted(first, key=lambda g: g["start_s"])[:10],
        "rule": "per stream, on its own samples (see streams)",
    }
    for name, c in summary["channels"].items():
        c["samples"] = int(np.count_nonzero(rec.own_rows(name)))
        c["stream"] = rec.stream_of(name)


def _own_timing(rec: Recording, meta: dict[str, Any], summary: dict[str, Any]) -> None:
    """Rates and gaps on each stream's own times: per NMEA sentence type (the reader's ``sentence_timing``), per
    channel whose samples sit on rows of their own (fewer than 90 % of the rows), and the rows themselves when
    they come in bursts (then ``rate_hz`` and ``gaps`` are the burst-aware ones; formats/timing.py)."""
    st = meta.get("sentence_timing")
    if isinstance(st, dict) and st:
        summary["sentence_timing"] = st
    if len(rec) < 2:
        return
    per_channel: dict[str, Any] = {}
    for name, a in rec.channels.items():
        if (
            st or a.dtype.kind != "f" or rec.multi_clock
        ):  # an NMEA log or streams: they say it  # an NMEA log: its sentence types say it
            continue
        ok = np.isfinite(a.reshape(len(a), -1)).any(axis=1)
        if 2 <= ok.sum() < 0.9 * len(rec):
            per_channel[name] = stream_timing(rec.time[ok])
    if per_channel:
        summary["channel_timing"] = per_channel
    rows = stream_timing(rec.time)
    if rows["bursty"] and not st and not rec.multi_clock:
        summary["rate_hz"] = rows["rate_hz"]
        summary["bursts"] = rows["burst"]
        summary["gaps"] = {
            "count": rows["gaps"],
            "missing_s": rows["missing_s"],
            "first": [{"start_s": a, "length_s": b} for a, b in rows["first_gaps"]],
            "rule": "time between burst starts longer than 3 burst periods",
        }


def run_info(
    source: str | os.PathLike,
    *,
    duplicates: str = "drop",
    backwards: str = "error",
    strict: bool = False,
    on_input: OnInput | None = None,
    **load_options: Any,
) -> RouteResult:
    """Read ``source`` unvalidated (``load_options``: columns, profile, topic, stamp, mounting,
    calibration_file; ``strict``: its warnings are an error) and describe it (:func:`summarize`, with the
    ``duplicates`` and ``backwards`` policies the other commands would apply). ``recording``: what was read."""
    path = os.fspath(source)
    inputs: list[dict[str, Any]] = []
    rec, _ = load_input(
        path,
        inputs,
        strict=strict,
        on_input=on_input,
        duplicates=duplicates,
        backwards=backwards,
        validate=False,
        **load_options,
    )
    if len(rec) == 0:
        raise ImutoolError("no samples", path=path)
    return RouteResult(summarize(path, rec, duplicates=duplicates, backwards=backwards), inputs, rec)
