"""`imutool info FILE`: what a recording holds — duration, rate, time-base problems, channels, units, ranges.

Only option parsing and printing here; the work is :func:`imutool.info.run_info`, the route `imutool batch info` and
a Python user take.
"""

from __future__ import annotations

from typing import Any

import click

from formats.timing import describe
from imutool.cli.common import emit_summary, input_options, note_input, route_of, strict_requested
from imutool.info import run_info
from imutool.routes import OnInput, RouteResult


def info_route(path: str, quiet: bool = True, on_input: OnInput | None = None, **options: Any) -> RouteResult:
    """Parsed options → :func:`imutool.info.run_info`."""
    return run_info(path, strict=strict_requested(), on_input=on_input, **options)


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
    sentence_timing = s.get("sentence_timing") or {}
    multi = len(sentence_timing) > 1
    rate = f"rate:      {_fmt(s['rate_hz'])} Hz"
    if s.get("bursts"):
        b = s["bursts"]
        rate += f" in bursts of {_fmt(b['samples'])} every {_fmt(b['period_s'])} s"
    rate += f" (step median {_fmt(st['median'])} s, min {_fmt(st['min'])} s, max {_fmt(st['max'])} s)"
    gaps = f"gaps:      {s['gaps']['count']}" + (
        f" (≈{_fmt(s['gaps']['missing_s'])} s missing; first at "
        f"{_fmt_t(s['gaps']['first'][0]['start_s'])} s, "
        f"{_fmt(s['gaps']['first'][0]['length_s'])} s long)"
        if s["gaps"]["count"]
        else ""
    )
    streams = s.get("streams") or {}
    if streams and not multi:  # many clocks: the rows' rate and gaps mean nothing; each stream's do
        rate = f"rate:      per stream ({len(streams)} streams, rows merged; each on its own samples):"
        gaps = ""
    elif multi:  # rows of several sentence types: the rows' rate and gaps mean nothing; each type's do
        rate = f"rate:      per sentence type ({len(sentence_timing)} types, rows merged; each on its own times):"
        gaps = ""
    out = [
        f"file:      {s['file']} ({s['format']})",
        f"rows:      {s['rows']}"
        + (f" ({s['rows_after_validation']} after validation)" if s["rows_after_validation"] != s["rows"] else ""),
        f"time:      {_fmt_t(s['start_s'])} … {_fmt_t(s['end_s'])} s, duration {_fmt(s['duration_s'])} s",
        rate,
    ]
    if multi:
        out += [f"  {k:<14} {describe(v)}" for k, v in sentence_timing.items()]
    if streams:
        if multi:
            out.append(
                f"streams:   {len(streams)} (channels and the sentence types carrying them, on their own samples):"
            )
        out += [f"  {k:<14} {describe(v['timing'])} ({', '.join(v['channels'])})" for k, v in streams.items()]
    if not (multi or streams):
        out.append(gaps)
        if sentence_timing:
            k, v = next(iter(sentence_timing.items()))
            out.append(f"sentence:  {k} {describe(v)}")
    if s.get("channel_timing"):
        out.append("channels on rows of their own (rate and gaps on their own samples):")
        out += [f"  {k:<14} {describe(v)}" for k, v in s["channel_timing"].items()]
    out += [
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
    for t in s.get("bag_topics_not_read") or []:
        out.append(f"bag topic not read: {t['topic']} ({t['type']}, {t['messages']} msgs)")
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
def info_cmd(path: str, as_json: bool, **options: Any) -> None:
    """Summarise FILE (CSV, ROS1/ROS2 bag, NMEA log): duration, rows, rate (median, min/max step), gaps,
    duplicate timestamps, NaN rows, channels with units and min/mean/max per axis, metadata, the foreign-CSV
    column mapping used, and what the time-base validation would do. Units are SI except angles and angular
    rates, shown in degrees (deg, deg/s) whatever the file holds (the JSON names the unit in the file)."""
    summary = info_route(path, on_input=note_input, **options).summary
    emit_summary(summary, as_json, False, None if as_json else _lines(summary))


info_cmd = route_of(info_route, ())(info_cmd)
