"""`imutool convert IN OUT`: CSV ↔ Parquet ↔ ROS1/ROS2 bags ↔ NMEA 0183 (format from each name's extension).

Bags are converted REP-103 FLU/ENU ↔ FRD/NED at the boundary (formats.rosbag). CSV/Parquet → CSV/Parquet streams in
chunks (bounded memory). The summary says rows in/out, channels, frame conversions applied and any channel the output
format cannot carry.
"""

from __future__ import annotations

from typing import Any

import click
import numpy as np

import formats
from imutool.cli.common import emit_summary, input_options, load_input, output_options, progress, safe_outputs


def _stream_csv(src: str, dst: str, chunk_rows: int, columns: str | None, profile: str | None, duplicates: str,
                backwards: str, mounting: str | None, calibration_file: str | None,
                quiet: bool) -> dict[str, Any]:
    """CSV/Parquet → CSV/Parquet chunk by chunk (the library route: imutool.convert.stream_convert)."""
    from imutool.convert import stream_convert

    return stream_convert(src, dst, chunk_rows=chunk_rows, columns=columns, profile=profile, duplicates=duplicates,
                          backwards=backwards, mounting=mounting, calibration_file=calibration_file,
                          progress=lambda chunks: progress(chunks, _rows_hint(src), "converting", quiet, unit="rows",
                                                           weight=len))


def _rows_hint(src: str) -> int | None:
    """Rows expected from a CSV (estimated from its size) for the progress total; None for other formats."""
    from imutool.progress import estimate_rows

    return estimate_rows(src) if formats.kind_of(src) == "csv" else None


@click.command("convert", epilog="Example: imutool convert roll.csv roll.bag   |   "
               "imutool convert test1.bag imu.csv --topic /imu/data --stamp header")
@click.argument("input_path", metavar="IN", type=click.Path(exists=True))
@click.argument("output_arg", metavar="OUT", required=False)
@click.option("-o", "--output", default=None, help="Output (alternative to the OUT argument).")
@input_options
@click.option("--sentences", default="HDT,XDR", show_default=True,
              help="NMEA output: sentence types, comma-separated (HDT, HDG, THS, ROT, XDR, PASHR, HRM...).")
@click.option("--nmea-rate", type=float, default=None, help="NMEA output: sentence rate in Hz (default: input).")
@click.option("--talker", default=None, help="NMEA output: talker ID (default per sentence).")
@click.option("--imu-topic", default="/imu/data", show_default=True, help="Bag output: sensor_msgs/Imu topic.")
@click.option("--mag-topic", default="/imu/mag", show_default=True,
              help="Bag output: sensor_msgs/MagneticField topic (written when the input has mag).")
@click.option("--frame-id", default=None, help="Bag output: header frame_id (default: the input bag's, or imu_link).")
@click.option("--storage", type=click.Choice(["sqlite3", "mcap"]), default=None,
              help="ROS2 folder output storage (default sqlite3; .db3/.mcap names decide by themselves).")
@click.option("--compression", type=click.Choice(["none", "bz2", "lz4"]), default="none", show_default=True,
              help="ROS1 output chunk compression.")
@click.option("--vector3-mag-unit", default="T", show_default=True,
              help="Bag input: unit of a geometry_msgs/Vector3Stamped magnetometer topic.")
@click.option("--chunk-rows", type=int, default=500_000, show_default=True,
              help="CSV/Parquet → CSV/Parquet: rows per streamed chunk (bounds memory).")
@click.option("--no-stream", is_flag=True,
              help="CSV/Parquet → CSV/Parquet: read the whole file (allows --backwards sort).")
@output_options
@safe_outputs("output_arg", "output")
def convert_cmd(input_path: str, output_arg: str | None, output: str | None, columns: str | None,
                profile: str | None, topic: str | None, stamp: str, duplicates: str, backwards: str,
                mounting: str | None, calibration_file: str | None, sentences: str, nmea_rate: float | None,
                talker: str | None, imu_topic: str, mag_topic: str, frame_id: str | None, storage: str | None,
                compression: str, vector3_mag_unit: str, chunk_rows: int, no_stream: bool, as_json: bool,
                quiet: bool) -> None:
    """Convert IN to OUT: .csv, .parquet, .bag (ROS1), .db3/.mcap or a folder (ROS2), .nmea/.log (NMEA 0183)."""
    out = output or output_arg
    if not out:
        raise click.UsageError("give the output as OUT or -o OUTPUT")
    if output and output_arg:
        raise click.UsageError("give the output once (OUT or -o)")
    kin = formats.kind_of(input_path)
    kout = formats.kind_of(out, for_output=True)
    summary: dict[str, Any] = {"input": input_path, "output": out, "from": kin, "to": kout}
    conversions: list[str] = []
    if (kin in ("csv", "parquet") and kout in ("csv", "parquet") and not no_stream and backwards != "sort"
            and duplicates != "mean"):
        summary.update(_stream_csv(input_path, out, chunk_rows, columns, profile, duplicates, backwards, mounting,
                                   calibration_file, quiet))
    else:
        from imutool.progress import stages

        steps = stages("convert", ["reading", "writing"], quiet)
        steps.stage("reading")
        if kin in ("ros1", "ros2"):
            rec = formats.read(input_path, topic=topic, stamp=stamp, vector3_mag_unit=vector3_mag_unit)
            rows_in = len(rec)
            bag = rec.meta.get("bag", {})
            conversions += [f"in: {c}" for c in bag.get("conversions", [])]
            summary["bag_in"] = {"format": bag.get("format"), "stamp": bag.get("stamp"),
                                 "topics": {k: v.get("topic") for k, v in bag.get("topics", {}).items()},
                                 "frame_id": bag.get("frame_id")}
            for k in ("partial_read",):
                if bag.get(k):
                    summary["warning"] = bag[k]
            if bag.get("notes"):
                summary["notes"] = bag["notes"]
            rec, rep = rec.validated(duplicates=duplicates, backwards=backwards, source=input_path)
            summary["validation_actions"] = rep.actions
            if calibration_file:
                from calibration import load_calibration

                rec = load_calibration(calibration_file).apply(rec)
            if mounting:
                rec = rec.mounted(*formats.parse_mounting(mounting))
        else:
            rec, rep = load_input(input_path, columns=columns, profile=profile, topic=topic, stamp=stamp,
                                  duplicates=duplicates, backwards=backwards, mounting=mounting,
                                  calibration_file=calibration_file)
            rows_in = int(rep.get("rows", len(rec)))
            summary["validation_actions"] = rep.get("actions", [])
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
                from formats.frames import quat_to_euler

                r, p, h = quat_to_euler(rec["q"])
                rec = rec.copy()
                for name, v in (("roll", r), ("pitch", p), ("heading", h)):
                    rec.add(name, np.degrees(v), "deg")
                conversions.append("roll/pitch/heading (deg, ZYX) derived from q (body FRD → NED) for NMEA")
            opts = {"sentences": tuple(s.strip().upper() for s in sentences.split(",") if s.strip()),
                    "rate_hz": nmea_rate, "talker": talker}
        steps.stage("writing")
        res = formats.write(rec, out, **opts)
        steps.close()
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
    emit_summary(summary, as_json, quiet, lines=_lines(summary))


def _lines(s: dict[str, Any]) -> list[str]:
    out = [f"{s['input']} ({s['from']}) → {s['output']} ({s['to']})",
           f"rows in {s.get('rows_in')}, rows out {s.get('rows_out')}"
           + (" (streamed)" if s.get("streamed") else "")]
    if "bag_in" in s:
        b = s["bag_in"]
        out.append(f"bag: {b['format']}, topics {b['topics']}, frame_id {b['frame_id']}, time = {b['stamp']} stamp")
    if "messages_out" in s:
        out.append("messages written: " + ", ".join(f"{k} {v}" for k, v in s["messages_out"].items()))
    if "sentences_out" in s:
        out.append(f"sentences written: {s['sentences_out']}")
    out.append("channels: " + ", ".join(s.get("channels", [])))
    if s.get("channels_not_written"):
        out.append("NOT written (no field in sensor_msgs/Imu or MagneticField): "
                   + ", ".join(s["channels_not_written"]))
    out.append("frame conversions: " + "; ".join(s["conversions"]))
    for a in s.get("validation_actions", []):
        out.append(f"time base: {a}")
    for n in s.get("notes", []):
        out.append(f"note: {n}")
    if s.get("warning"):
        out.append(f"WARNING: {s['warning']}")
    return out
