"""`imutool capture serial|i2c|modbus`: record instruments on deck, for hours, losing nothing."""

from __future__ import annotations

import re

import click

from formats.errors import ImutoolError
from imutool.cli.common import emit_summary

_UNITS = {"s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0}


def parse_duration(text: str | None) -> float | None:
    """'90', '90s', '10m', '2h', '1h30m' → seconds (None passes through)."""
    if text is None:
        return None
    t = text.strip().lower()
    if re.fullmatch(r"\d+(\.\d+)?", t):
        return float(t)
    parts = re.findall(r"(\d+(?:\.\d+)?)([smhd])", t)
    if not parts or "".join(a + b for a, b in parts) != t:
        raise ImutoolError(f"duration {text!r}: use forms like 90, 90s, 10m, 2h, 1h30m")
    return sum(float(v) * _UNITS[u] for v, u in parts)


def common_capture_options(f):
    opts = [
        click.option("-o", "--output", required=True, help="Output .csv file, or a folder (files named by UTC time)."),
        click.option(
            "--duration", default=None, help="Stop after this long (e.g. 2h, 30m, 90s). Default: until Ctrl-C."
        ),
        click.option("--rotate", default=None, help="Start a new file this often (e.g. 1h)."),
        click.option(
            "--status",
            "status_every",
            default="10s",
            show_default=True,
            help="Live status line on stderr this often ('0' = off).",
        ),
        click.option("--append", is_flag=True, help="Continue an existing output file (after a restart)."),
        click.option("--force", is_flag=True, help="Replace an existing output file."),
        click.option("--json", "as_json", is_flag=True, help="Print the final summary as JSON."),
        click.option("--quiet", "-q", is_flag=True, help="No status line or summary."),
    ]
    for o in reversed(opts):
        f = o(f)
    return f


def _run(summary_fn, as_json: bool, quiet: bool) -> None:
    summary = summary_fn()
    lines = [f"{k}: {v}" for k, v in summary.items() if k not in ("port_gaps", "sequence_gaps", "error_kinds")]
    if summary.get("port_gaps"):
        lines.append(f"port outages: {len(summary['port_gaps'])} (listed with --json)")
    emit_summary(summary, as_json, quiet, lines)


@click.group("capture", epilog="Example: imutool capture serial /dev/ttyUSB0 --baud 4800 --protocol nmea -o voyage/")
def capture_group() -> None:
    """Record a serial NMEA instrument, an MCU bridge, I2C sensors or a Modbus RTU device."""


@capture_group.command(
    "serial",
    epilog="Example: imutool capture serial /dev/ttyACM0 --baud 115200 "
    "--protocol bridge -o deck.csv --duration 2h --rotate 1h",
)
@click.argument("port")
@click.option("--baud", type=int, default=4800, show_default=True, help="Baud rate (NMEA 0183: 4800; -2: 38400).")
@click.option(
    "--protocol",
    type=click.Choice(["nmea", "bridge", "bridge-binary", "vectornav", "witmotion"]),
    default="nmea",
    show_default=True,
    help="vectornav: $VNYMR/$VNIMU ASCII; witmotion: WT901/JY901 0x55 packets (docs/capture.md).",
)
@click.option(
    "--checksum",
    type=click.Choice(["require", "accept-missing", "ignore"]),
    default="require",
    show_default=True,
    help="NMEA checksum policy (failures are counted either way).",
)
@click.option(
    "--accel-range",
    type=click.Choice(["2", "4", "8", "16"]),
    default="2",
    show_default=True,
    help="Bridge: MPU6050 accel full scale ±g (overridden by the bridge's $IMBCFG line).",
)
@click.option(
    "--gyro-range",
    type=click.Choice(["250", "500", "1000", "2000"]),
    default="250",
    show_default=True,
    help="Bridge: MPU6050 gyro full scale ±°/s.",
)
@click.option("--mag", type=click.Choice(["hmc5883l", "qmc5883l"]), default="hmc5883l", show_default=True)
@click.option("--mag-gain", type=int, default=None, help="HMC5883L gain code 0..7 (default 1) or QMC5883L range 2|8.")
@common_capture_options
def serial_cmd(
    port,
    baud,
    protocol,
    checksum,
    accel_range,
    gyro_range,
    mag,
    mag_gain,
    output,
    duration,
    rotate,
    status_every,
    append,
    force,
    as_json,
    quiet,
) -> None:
    """Record from a serial/RS-485 PORT (NMEA 0183, the imutool bridge protocol, a VectorNav or WitMotion IMU)."""
    from imutool.capture.bridge import Scales
    from imutool.capture.serial_capture import capture_bridge, capture_nmea

    kw = dict(
        duration=parse_duration(duration),
        rotate_s=parse_duration(rotate),
        status_s=parse_duration(status_every) or None,
        quiet=quiet or as_json,
        append=append,
        force=force,
    )
    if protocol == "nmea":
        _run(lambda: capture_nmea(port, baud, output, checksum_policy=checksum, **kw), as_json, quiet)
    elif protocol in ("vectornav", "witmotion"):
        from imutool.capture.vendor import capture_vendor

        _run(lambda: capture_vendor(port, baud, output, protocol, **kw), as_json, quiet)
    else:
        gain = mag_gain if mag_gain is not None else (1 if mag == "hmc5883l" else 8)
        scales = Scales("mpu6050", int(accel_range), int(gyro_range), mag, gain)
        _run(
            lambda: capture_bridge(port, baud, output, binary=protocol == "bridge-binary", scales=scales, **kw),
            as_json,
            quiet,
        )


@capture_group.command(
    "i2c", epilog="Example: imutool capture i2c 1 --imu mpu6050 --mag hmc5883l --rate 200 -o deck.csv"
)
@click.argument("bus")
@click.option("--imu", type=click.Choice(["mpu6050", "none"]), default="mpu6050", show_default=True)
@click.option("--imu-address", type=click.Choice(["0x68", "0x69"]), default="0x68", show_default=True)
@click.option("--mag", type=click.Choice(["hmc5883l", "qmc5883l", "none"]), default="hmc5883l", show_default=True)
@click.option("--bypass", is_flag=True, help="Reach the magnetometer through the MPU6050 aux bus (GY-86/GY-87).")
@click.option("--rate", "rate_hz", type=float, default=200.0, show_default=True, help="Sample rate, Hz.")
@click.option("--accel-range", type=click.Choice(["2", "4", "8", "16"]), default="2", show_default=True)
@click.option("--gyro-range", type=click.Choice(["250", "500", "1000", "2000"]), default="250", show_default=True)
@click.option("--mag-gain", type=int, default=None, help="HMC5883L gain code 0..7 (default 1) or QMC5883L range 2|8.")
@common_capture_options
def i2c_cmd(
    bus,
    imu,
    imu_address,
    mag,
    bypass,
    rate_hz,
    accel_range,
    gyro_range,
    mag_gain,
    output,
    duration,
    rotate,
    status_every,
    append,
    force,
    as_json,
    quiet,
) -> None:
    """Read sensors on Linux I2C BUS (number or /dev/i2c-N) at a steady rate (needs smbus2)."""
    from imutool.capture.i2c import capture_i2c

    _run(
        lambda: capture_i2c(
            bus,
            output,
            None if imu == "none" else imu,
            None if mag == "none" else mag,
            rate_hz,
            int(imu_address, 16),
            int(accel_range),
            int(gyro_range),
            mag_gain,
            bypass,
            parse_duration(duration),
            parse_duration(rotate),
            parse_duration(status_every) or None,
            quiet or as_json,
            append,
            force,
        ),
        as_json,
        quiet,
    )


@capture_group.command(
    "modbus", epilog="Example: imutool capture modbus /dev/ttyUSB1 --unit 1 --profile inclinometer.toml -o incl.csv"
)
@click.argument("port")
@click.option("--profile", required=True, type=click.Path(exists=True, dir_okay=False), help="Register profile TOML.")
@click.option("--unit", type=int, default=None, help="Modbus device id (default: the profile's).")
@click.option("--baud", type=int, default=None, help="Baud rate (default: the profile's).")
@click.option("--rate", "rate_hz", type=float, default=None, help="Poll rate, Hz (default: the profile's).")
@common_capture_options
def modbus_cmd(
    port, profile, unit, baud, rate_hz, output, duration, rotate, status_every, append, force, as_json, quiet
) -> None:
    """Poll a Modbus RTU device on PORT described by a register profile (needs pymodbus)."""
    from imutool.capture.modbus import capture_modbus

    _run(
        lambda: capture_modbus(
            port,
            profile,
            output,
            unit,
            baud,
            rate_hz,
            parse_duration(duration),
            parse_duration(rotate),
            parse_duration(status_every) or None,
            quiet or as_json,
            append,
            force,
        ),
        as_json,
        quiet,
    )
