"""`imutool convert IN OUT`: CSV ↔ Parquet ↔ ROS1/ROS2 bags ↔ NMEA 0183 (format from each name's extension).

Bags are converted REP-103 FLU/ENU ↔ FRD/NED at the boundary (formats.bags). CSV/Parquet → CSV/Parquet streams in
chunks (bounded memory). The summary says rows in/out, channels, frame conversions applied and any channel the output
format cannot carry. Options and printing only; the conversion is :func:`imutool.convert.run_convert`, the route
`imutool batch convert` and a Python user take.
"""

from __future__ import annotations

from typing import Any

import click

from imutool.cli.common import (
    default_of,
    emit_summary,
    input_options,
    lazy_bar,
    note_input,
    output_options,
    route_of,
    safe_outputs,
    strict_requested,
)
from imutool.convert import run_convert, streams
from imutool.progress import stages
from imutool.routes import OnInput, RouteResult

OUTPUTS = ("output_arg", "output")


def convert_route(
    input_path: str,
    output_arg: str | None,
    output: str | None,
    no_stream: bool = False,
    quiet: bool = True,
    on_input: OnInput | None = None,
    **options: Any,
) -> RouteResult:
    """Parsed options → :func:`imutool.convert.run_convert` (a progress bar on stderr unless ``quiet``)."""
    out = output or output_arg
    if not out:
        raise click.UsageError("give the output as OUT or -o OUTPUT")
    if output and output_arg:
        raise click.UsageError("give the output once (OUT or -o)")
    dup, back = options.get("duplicates", "drop"), options.get("backwards", "error")
    merging = bool(options.get("with_files"))
    if streams(input_path, out, stream=not no_stream, duplicates=dup, backwards=back, merging=merging):
        bar: Any = lazy_bar("converting", unit="rows", quiet=quiet)
        stage = None
    else:
        bar = stages("convert", ["reading", "writing"], quiet)
        stage = bar.stage
    with bar:
        return run_convert(
            input_path,
            out,
            stream=not no_stream,
            progress=None if stage else bar,
            stage=stage,
            strict=strict_requested(),
            on_input=on_input,
            **options,
        )


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
    default=default_of(run_convert, "sentences"),
    show_default=True,
    help="NMEA output: sentence types, comma-separated (HDT, HDG, THS, ROT, XDR, PASHR, HRM...).",
)
@click.option("--nmea-rate", type=float, default=None, help="NMEA output: sentence rate in Hz (default: input).")
@click.option("--talker", default=None, help="NMEA output: talker ID (default per sentence).")
@click.option(
    "--imu-topic",
    default=default_of(run_convert, "imu_topic"),
    show_default=True,
    help="Bag output: sensor_msgs/Imu topic.",
)
@click.option(
    "--mag-topic",
    default=default_of(run_convert, "mag_topic"),
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
    default=default_of(run_convert, "compression"),
    show_default=True,
    help="ROS1 output chunk compression.",
)
@click.option(
    "--vector3-mag-unit",
    default=default_of(run_convert, "vector3_mag_unit"),
    show_default=True,
    help="Bag input: unit of a geometry_msgs/Vector3Stamped magnetometer topic.",
)
@click.option(
    "--chunk-rows",
    type=int,
    default=default_of(run_convert, "chunk_rows"),
    show_default=True,
    help="CSV/Parquet → CSV/Parquet: rows per streamed chunk (bounds memory).",
)
@click.option(
    "--no-stream", is_flag=True, help="CSV/Parquet → CSV/Parquet: read the whole file (allows --backwards sort)."
)
@output_options
@safe_outputs(*OUTPUTS)
def convert_cmd(
    input_path: str, output_arg: str | None, output: str | None, as_json: bool, quiet: bool, **options: Any
) -> None:
    """Convert IN to OUT: .csv, .parquet, .bag (ROS1), .db3/.mcap or a folder (ROS2), .nmea/.log (NMEA 0183)."""
    res = convert_route(input_path, output_arg, output, quiet=quiet, on_input=note_input, **options)
    emit_summary(res.summary, as_json, quiet, lines=_lines(res.summary))


convert_cmd = route_of(convert_route, OUTPUTS)(convert_cmd)


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
