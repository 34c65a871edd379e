"""`imutool convert IN OUT`: CSV ↔ Parquet ↔ ROS1/ROS2 bags ↔ NMEA 0183 (format from each name's extension).

Bags are converted REP-103 FLU/ENU ↔ FRD/NED at the boundary (formats.bags). CSV/Parquet → CSV/Parquet streams in
chunks (bounded memory). The summary says rows in/out, channels, frame conversions applied and any channel the output
format cannot carry. Options and printing only; the conversion is :func:`imutool.convert.convert`.
"""

from __future__ import annotations

from typing import Any

import click

from imutool.cli.common import (
    emit_summary,
    input_options,
    lazy_bar,
    note_input,
    output_options,
    safe_outputs,
    strict_requested,
)
from imutool.progress import stages


@click.command(
    "convert",
    epilog="Example: imutool convert roll.csv roll.bag   |   "
    "imutool convert test1.bag imu.csv --topic /imu/data --stamp header",
)
@click.argument("input_path", metavar="IN", type=click.Path(exists=True))
@click.argument("output_arg", metavar="OUT", required=False)
@click.option("-o", "--output", default=None, help="Output (alternative to the OUT argument).")
@input_options
@click.option(
    "--sentences",
    default="HDT,XDR",
    show_default=True,
    help="NMEA output: sentence types, comma-separated (HDT, HDG, THS, ROT, XDR, PASHR, HRM...).",
)
@click.option("--nmea-rate", type=float, default=None, help="NMEA output: sentence rate in Hz (default: input).")
@click.option("--talker", default=None, help="NMEA output: talker ID (default per sentence).")
@click.option("--imu-topic", default="/imu/data", show_default=True, help="Bag output: sensor_msgs/Imu topic.")
@click.option(
    "--mag-topic",
    default="/imu/mag",
    show_default=True,
    help="Bag output: sensor_msgs/MagneticField topic (written when the input has mag).",
)
@click.option("--frame-id", default=None, help="Bag output: header frame_id (default: the input bag's, or imu_link).")
@click.option(
    "--storage",
    type=click.Choice(["sqlite3", "mcap"]),
    default=None,
    help="ROS2 folder output storage (default sqlite3; .db3/.mcap names decide by themselves).",
)
@click.option(
    "--compression",
    type=click.Choice(["none", "bz2", "lz4"]),
    default="none",
    show_default=True,
    help="ROS1 output chunk compression.",
)
@click.option(
    "--vector3-mag-unit",
    default="T",
    show_default=True,
    help="Bag input: unit of a geometry_msgs/Vector3Stamped magnetometer topic.",
)
@click.option(
    "--chunk-rows",
    type=int,
    default=500_000,
    show_default=True,
    help="CSV/Parquet → CSV/Parquet: rows per streamed chunk (bounds memory).",
)
@click.option(
    "--no-stream", is_flag=True, help="CSV/Parquet → CSV/Parquet: read the whole file (allows --backwards sort)."
)
@output_options
@safe_outputs("output_arg", "output")
def convert_cmd(
    input_path: str,
    output_arg: str | None,
    output: str | None,
    duplicates: str,
    backwards: str,
    sentences: str,
    nmea_rate: float | None,
    talker: str | None,
    imu_topic: str,
    mag_topic: str,
    frame_id: str | None,
    storage: str | None,
    compression: str,
    vector3_mag_unit: str,
    chunk_rows: int,
    no_stream: bool,
    as_json: bool,
    quiet: bool,
    **io: Any,
) -> None:
    """Convert IN to OUT: .csv, .parquet, .bag (ROS1), .db3/.mcap or a folder (ROS2), .nmea/.log (NMEA 0183)."""
    out = output or output_arg
    if not out:
        raise click.UsageError("give the output as OUT or -o OUTPUT")
    if output and output_arg:
        raise click.UsageError("give the output once (OUT or -o)")
    from imutool.convert import convert, streams

    merging = bool(io.get("with_files"))
    if streams(input_path, out, stream=not no_stream, duplicates=duplicates, backwards=backwards, merging=merging):
        bar = lazy_bar("converting", unit="rows", quiet=quiet)
        stage = None
    else:
        bar = stages("convert", ["reading", "writing"], quiet)
        stage = bar.stage
    with bar:
        summary = convert(
            input_path,
            out,
            stream=not no_stream,
            chunk_rows=chunk_rows,
            sentences=sentences,
            nmea_rate=nmea_rate,
            talker=talker,
            imu_topic=imu_topic,
            mag_topic=mag_topic,
            frame_id=frame_id,
            storage=storage,
            compression=compression,
            vector3_mag_unit=vector3_mag_unit,
            progress=None if stage else bar,
            stage=stage,
            strict=strict_requested(),
            on_input=note_input,
            duplicates=duplicates,
            backwards=backwards,
            **io,
        )
    emit_summary(summary, as_json, quiet, lines=_lines(summary))


def _lines(s: dict[str, Any]) -> list[str]:
    out = [
        f"{s['input']} ({s['from']}) → {s['output']} ({s['to']})",
        f"rows in {s.get('rows_in')}, rows out {s.get('rows_out')}" + (" (streamed)" if s.get("streamed") else ""),
    ]
    if "bag_in" in s:
        b = s["bag_in"]
        out.append(f"bag: {b['format']}, topics {b['topics']}, frame_id {b['frame_id']}, time = {b['stamp']} stamp")
    if "messages_out" in s:
        out.append("messages written: " + ", ".join(f"{k} {v}" for k, v in s["messages_out"].items()))
    if "sentences_out" in s:
        out.append(f"sentences written: {s['sentences_out']}")
    out.append("channels: " + ", ".join(s.get("channels", [])))
    if s.get("channels_not_written"):
        out.append(
            "NOT written (no field in sensor_msgs/Imu or MagneticField): " + ", ".join(s["channels_not_written"])
        )
    out.append("frame conversions: " + "; ".join(s["conversions"]))
    for a in s.get("validation_actions", []):
        out.append(f"time base: {a}")
    for n in s.get("notes", []):
        out.append(f"note: {n}")
    if s.get("warning"):
        out.append(f"WARNING: {s['warning']}")
    return out
