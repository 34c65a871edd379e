"""`imutool info FILE`: what a recording holds — duration, rate, time-base problems, channels, units, ranges."""

from __future__ import annotations

import math
import os
from typing import Any

import click
import numpy as np

import formats
from formats import Recording
from formats.errors import ImutoolError
from formats.nmea import sentence_summary
from imutool.cli.common import emit_summary, input_options, load_input

# units shown in degrees (DESIGN: degrees at every user-facing surface); the file keeps what its header says
_DEG_UNITS = {"rad/s": "deg/s", "rad": "deg", "rad/s^2": "deg/s^2"}

_HIDDEN_META = {"validation", "column_mapping", "column_mapping_origin", "skipped_rows", "skipped_rows_first"}


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


def summarize(path: str, rec_raw: Recording, duplicates: str = "drop", backwards: str = "error") -> dict[str, Any]:
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
    if rec_raw.meta.get("sentences"):  # an NMEA log: every sentence named and counted, read or not
        summary["nmea_sentences"] = sentence_summary(rec_raw.meta)
    cm = rec_raw.meta.get("column_mapping")
    if cm:
        summary["column_mapping"] = {
            "origin": rec_raw.meta.get("column_mapping_origin", "inferred"),
            "columns": [s.strip() for s in str(cm).split(";") if s.strip()],
        }
    return summary


def _fmt(v: Any) -> str:
    if v is None:
        return "nan"
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def _fmt_t(v: Any) -> str:
    """Times: epoch stamps in full (ms resolution), short times as %g."""
    if isinstance(v, float) and abs(v) >= 1e5:
        return f"{v:.3f}"
    return _fmt(v)


def _lines(s: dict[str, Any]) -> list[str]:
    st = s["step_s"]
    out = [
        f"file:      {s['file']} ({s['format']})",
        f"rows:      {s['rows']}"
        + (f" ({s['rows_after_validation']} after validation)" if s["rows_after_validation"] != s["rows"] else ""),
        f"time:      {_fmt_t(s['start_s'])} … {_fmt_t(s['end_s'])} s, duration {_fmt(s['duration_s'])} s",
        f"rate:      {_fmt(s['rate_hz'])} Hz (step median {_fmt(st['median'])} s, min {_fmt(st['min'])} s, "
        f"max {_fmt(st['max'])} s)",
        f"gaps:      {s['gaps']['count']}"
        + (
            f" (≈{_fmt(s['gaps']['missing_s'])} s missing; first at "
            f"{_fmt_t(s['gaps']['first'][0]['start_s'])} s, "
            f"{_fmt(s['gaps']['first'][0]['length_s'])} s long)"
            if s["gaps"]["count"]
            else ""
        ),
        f"duplicate timestamps: {s['duplicate_timestamps']} "
        f"({s['duplicate_timestamps_with_different_data']} with different data)",
        f"time going backwards: {s['backwards_steps']}",
        f"rows with NaN: {s['rows_with_nan']}"
        + (" (" + ", ".join(f"{k} {v}" for k, v in s["nan_by_channel"].items()) + ")" if s["nan_by_channel"] else ""),
    ]
    if s["skipped_rows"]:
        out.append(f"malformed rows skipped: {s['skipped_rows']} (" + "; ".join(s["skipped_rows_first"]) + ")")
    out.append("channels (unit; min / mean / max per axis; angles and rates in degrees):")
    for name, c in s["channels"].items():
        cols = c["columns"]
        axes = " | ".join(
            f"{col} {_fmt(a)} / {_fmt(m)} / {_fmt(b)}"
            for col, a, m, b in zip(cols, c["min"], c["mean"], c["max"], strict=False)
        )
        out.append(f"  {name:<12} [{c['unit'] or '-'}]  {axes}")
    ns = s.get("nmea_sentences")
    if ns:
        for group, what in (
            ("read", "read"),
            ("not_read", "not read (imutool does not decode them)"),
            ("no_data", "empty (no value in any field)"),
            ("bad", "bad (checksum or format)"),
        ):
            if ns.get(group):
                out.append(f"NMEA sentences {what}: " + ", ".join(f"{k} {n}" for k, n in ns[group].items()))
    if s["column_mapping"]:
        out.append(f"column mapping ({s['column_mapping']['origin']}):")
        out += [f"  {m}" for m in s["column_mapping"]["columns"]]
    if s["metadata"]:
        out.append("metadata:")
        for k, v in s["metadata"].items():
            text = str(v)
            out.append(f"  {k}: {text if len(text) <= 100 else text[:97] + '...'}")
    if s["validation_actions"]:
        out.append("time-base actions:")
        out += [f"  {a}" for a in s["validation_actions"]]
    return out


@click.command("info", epilog="Example: imutool info ../shared/data/fusion/sensor_data.csv --json")
@click.argument("path", metavar="FILE", type=click.Path(exists=True, dir_okay=True))
@input_options
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def info_cmd(path: str, duplicates: str, backwards: str, as_json: bool, **io: Any) -> None:
    """Summarise FILE (CSV, ROS1/ROS2 bag, NMEA log): duration, rows, rate (median, min/max step), gaps,
    duplicate timestamps, NaN rows, channels with units and min/mean/max per axis, metadata, the foreign-CSV
    column mapping used, and what the time-base validation would do. Units are SI except angles and angular
    rates, shown in degrees (deg, deg/s) whatever the file holds (the JSON names the unit in the file)."""
    rec, _ = load_input(path, duplicates=duplicates, backwards=backwards, validate=False, **io)
    if len(rec) == 0:
        raise ImutoolError("no samples", path=path)
    summary = summarize(path, rec, duplicates=duplicates, backwards=backwards)
    emit_summary(summary, as_json, False, None if as_json else _lines(summary))
