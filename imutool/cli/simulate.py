"""`imutool simulate SCENARIO -o OUT`: a recording with truth columns from the simulator.

Only option parsing and printing here; the file is written by :func:`imutool.sim.run_simulate` (the route a Python
user takes); ``--serve`` streams live frames through :func:`imutool.capture.serve.serve`.
"""

from __future__ import annotations

from typing import Any

import click

from imutool import sim
from imutool.cli.common import default_of, emit_summary, route_of, safe_outputs
from imutool.progress import stages
from imutool.routes import RouteResult


def _parse_set(items: tuple[str, ...]) -> dict:
    out = {}
    for item in items:
        k, sep, v = item.partition("=")
        if not sep:
            raise click.BadParameter(f"{item!r}: expected NAME=VALUE", param_hint="--set")
        try:
            val: object = float(v) if any(c in v for c in ".eE") else int(v)
        except ValueError:
            val = v
        out[k.strip().replace("-", "_")] = val
    return out


@click.command(
    "simulate",
    epilog="Example: imutool simulate ship-roll -o roll.csv --seed 1   |   "
    "imutool simulate --serve auto --protocol bridge --rate 200",
)
@click.argument("scenario", type=click.Choice(list(sim.SCENARIOS)), metavar="SCENARIO", required=False)
@click.option("-o", "--output", type=click.Path(dir_okay=True), help="Output file (.csv, .bag...).")
@click.option(
    "--serve",
    default=None,
    metavar="auto|LINK",
    help="Stream live frames into a new pseudo-terminal instead of writing a file; 'auto' prints the "
    "port, a path keeps a symlink to it (for demos and capture tests).",
)
@click.option(
    "--protocol",
    type=click.Choice(["nmea", "bridge", "bridge-binary"]),
    default="bridge",
    show_default=True,
    help="With --serve: what to stream.",
)
@click.option(
    "--corrupt",
    type=float,
    default=0.0,
    show_default=True,
    help="With --serve: fraction of frames with one flipped bit.",
)
@click.option("--replug-every", type=float, default=None, help="With --serve: simulate unplugging every N s.")
@click.option("--serve-log", default=None, help="With --serve: write what was sent (JSON) here at the end.")
@click.option(
    "--start-delay",
    type=float,
    default=1.0,
    show_default=True,
    help="With --serve: seconds between announcing the port and the first frame.",
)
@click.option(
    "--start-when",
    default=None,
    metavar="FILE",
    help="With --serve: wait until FILE exists before streaming (e.g. a capture's events log).",
)
@click.option("--duration", type=float, default=None, help="Length in s (scenario default if omitted).")
@click.option("--rate", "rate_hz", type=float, default=None, help="Sample rate in Hz (scenario default).")
@click.option(
    "--seed",
    type=int,
    default=default_of(sim.run_simulate, "seed"),
    show_default=True,
    help="Random seed (deterministic output).",
)
@click.option(
    "--set",
    "settings",
    multiple=True,
    metavar="NAME=VALUE",
    help="Scenario option, repeatable (e.g. --set roll_amplitude_deg=20).",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("--quiet", "-q", is_flag=True)
@safe_outputs("output", "serve_log")
def simulate_cmd(
    scenario: str | None,
    output: str | None,
    serve: str | None,
    protocol: str,
    corrupt: float,
    replug_every: float | None,
    serve_log: str | None,
    start_delay: float,
    start_when: str | None,
    duration: float | None,
    rate_hz: float | None,
    seed: int,
    settings: tuple[str, ...],
    as_json: bool,
    quiet: bool,
) -> None:
    """Simulate SCENARIO (ship-roll, ship-at-sea, sea-state, turn, compass-swing, mag-sphere, static, walk, ...).

    Scenario options (--set NAME=VALUE) are the keyword arguments of the scenario functions in imutool.sim; an
    unknown name is refused with the list of valid ones. A bridge sensor on a ship with its speed sources:
    ship-at-sea --set lever_arm=-12,0,-20 --set sway_m=1 --set speed_source=smoothed (gnss|smoothed|log|none;
    lengths m, periods s, angles deg, lever arms body FRD from the roll centre; docs/attitude.md)."""
    if serve:
        from imutool.capture.serve import serve as serve_pty

        log = serve_pty(
            protocol,
            rate_hz or 200.0,
            duration,
            seed,
            corrupt,
            None if serve == "auto" else serve,
            replug_every,
            serve_log,
            announce=lambda name: click.echo(f"serving on {name}", err=True),
            start_delay=start_delay,
            start_when=start_when,
        )
        emit_summary({"protocol": protocol, **log.as_dict(), "corrupted": len(log.corrupted)}, as_json, quiet)
        return
    res = simulate_route(scenario, output, duration, rate_hz, seed, settings, quiet=quiet)
    emit_summary(res.summary, as_json, quiet)


def simulate_route(
    scenario: str | None,
    output: str | None,
    duration: float | None,
    rate_hz: float | None,
    seed: int,
    settings: tuple[str, ...],
    quiet: bool = True,
    serve: str | None = None,
    **serve_options: Any,
) -> RouteResult:
    """Parsed options → :func:`imutool.sim.run_simulate` (progress on stderr unless ``quiet``); ``--serve`` (a
    live stream, never a file) is not a route."""
    if serve:
        raise click.UsageError("--serve streams live frames: run it as its own command")
    if not scenario or not output:
        raise click.UsageError("give SCENARIO and -o OUTPUT (or --serve)")
    opts = _parse_set(settings)
    with stages("simulate", ["simulating", "writing"], quiet) as steps:
        return sim.run_simulate(
            scenario, output, seed=seed, duration=duration, rate_hz=rate_hz, settings=opts, stage=steps.stage
        )


simulate_cmd = route_of(simulate_route, ("output", "serve_log"))(simulate_cmd)
