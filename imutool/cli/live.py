"""`imutool live [PORT] [--replay FILE --speed X] --out URL ... --sentences HRM,XDR --rate XDR=20 [--record DIR]
[--config FILE] [--duration S]`: a live IMU turned into an electronic inclinometer's outputs. Only option parsing
here; the work is :func:`imutool.live.route.run_live`."""

from __future__ import annotations

from typing import Any

import click

from formats.errors import ImutoolError
from imutool.cli.common import default_of, emit_summary
from imutool.live.config import read_config
from imutool.live.route import log_line, run_live
from imutool.live.sentences import SENTENCES
from imutool.live.sources import DECODERS


@click.command(
    "live",
    epilog="Example: imutool live --replay sample_data/ship_imu.csv --speed 10 --out udp://127.0.0.1:10110 "
    "--sentences HRM,XDR,PASHR --duration 300",
)
@click.argument("port", required=False)
@click.option("--replay", type=click.Path(exists=True), default=None, help="Replay a recording imutool reads.")
@click.option("--speed", type=float, default=None, help="Replay speed (× real time; 0: as fast as it goes). [1]")
@click.option("--protocol", default=None, help=f"Serial IMU protocol: {', '.join(sorted(DECODERS))}. [bridge]")
@click.option(
    "--clock",
    type=click.Choice(["host", "sensor"]),
    default=None,
    help="Sample times: the sensor's clock fitted to the host's (host) or the sensor's alone (sensor). [host]",
)
@click.option("--baud", type=int, default=None, help="Serial IMU baud rate. [115200]")
@click.option("--i2c", default=None, help="Linux I2C bus of an MPU6050 (+HMC5883L), e.g. 1.")
@click.option("--modbus-profile", default=None, help="Modbus register profile (TOML) for PORT.")
@click.option("--poll-rate", "rate_hz", type=float, default=None, help="Polling rate of I2C/Modbus (Hz). [100]")
@click.option("--aux", default=None, help="Second serial port: NMEA RMC/VTG (GNSS) and HDT/THS (gyrocompass).")
@click.option("--aux-baud", type=int, default=None, help="Baud rate of --aux. [4800]")
@click.option(
    "--out", "outputs", multiple=True, help="udp://HOST:PORT, tcp://[HOST]:PORT or serial:///dev/ttyX?baud=N."
)
@click.option("--sentences", default=None, help=f"Comma list of {', '.join(SENTENCES)}. [HRM]")
@click.option("--rate", "rates", multiple=True, metavar="SENTENCE=HZ", help="Rate of one sentence, e.g. XDR=20.")
@click.option("--talker", default=None, help="Talker ID of the sentences. [II]")
@click.option("--record", type=click.Path(), default=None, help="Record raw samples and estimates in this folder.")
@click.option("--rotate", "rotate_s", type=float, default=None, help="Start new recording files every S s. [3600]")
@click.option("--duration", type=float, default=None, help="Stop after S seconds of input time.")
@click.option("--params", "params_file", default=None, help="EKF parameters file (as filter --params).")
@click.option("--motion", type=click.Choice(["auto", "ship", "handheld"]), default=None, help="Motion model.")
@click.option("--settle", "settle_s", type=float, default=None, help="Settling time (s): status V until then. [60]")
@click.option("--lever-arm", default=None, help="Sensor from the roll centre, m body FRD: 'x,y,z'.")
@click.option("--antenna-arm", default=None, help="GNSS antenna from the roll centre, m body FRD: 'x,y,z'.")
@click.option("--mounting", default=None, help="Sensor → body axes, e.g. 'x,-y,-z[;r,p,y]'.")
@click.option("--calibration", "calibration_file", default=None, help="Calibration file (TOML).")
@click.option("--peak-state", default=None, help="File keeping the peak-hold and its reset UTC across restarts.")
@click.option(
    "--http",
    default=None,
    metavar="[HOST:]PORT",
    help="Serve the bridge display and a Signal K stream (loopback unless HOST is given; needs imutool[live]).",
)
@click.option("--signalk-push", default=None, metavar="URL", help="Push Signal K deltas to a server (ws://HOST:PORT).")
@click.option("--config", "config_file", type=click.Path(exists=True), default=None, help="TOML configuration.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("-q", "--quiet", is_flag=True)
def live_cmd(
    config_file: str | None, as_json: bool, quiet: bool, http: str | None, signalk_push: str | None, **given: Any
) -> None:
    """Read a live IMU (or replay a recording) and keep writing the inclinometer's sentences (HRM, XDR, PASHR,
    TSS1, HDT/THS, ROT) to serial ports, UDP and TCP until stopped. Status V while settling, when samples stop,
    on saturation or an inconsistent self-check; SIGUSR1 resets the peak-hold."""
    options = read_config(config_file) if config_file else {}
    for k, v in given.items():
        if v is not None and v != ():
            options[k] = v
    if isinstance(options.get("sentences"), str):
        options["sentences"] = options["sentences"].split(",")
    if "rates" in options and isinstance(options["rates"], tuple):
        options["rates"] = list(options["rates"])
    if "outputs" in options:
        options["outputs"] = list(options["outputs"])
    options["consumers"] = display_consumers(http, signalk_push)
    res = run_live(**options, log=(lambda m: None) if quiet else None)
    if as_json:  # (the one summary line is in the log, stderr)
        emit_summary(res.full_summary(), True, quiet)


def display_consumers(http: str | None, signalk_push: str | None) -> list:
    """The hub's consumers of ``--http`` and ``--signalk-push`` (aiohttp, the extra ``imutool[live]``)."""
    if http is None and signalk_push is None:
        return []
    try:
        import aiohttp  # noqa: F401
    except ImportError:
        raise ImutoolError("--http and --signalk-push need aiohttp: pip install 'imutool[live]'") from None
    from imutool.live.http import http_consumer
    from imutool.live.signalk import SignalKPush

    out: list = []
    if http is not None:
        out.append(http_consumer(http, log=log_line))
    if signalk_push is not None:
        url = signalk_push
        out.append(lambda hub: SignalKPush(url, hub, log=log_line))
    return out


_ = default_of  # (defaults live in run_live: LIVE_DEFAULTS)
