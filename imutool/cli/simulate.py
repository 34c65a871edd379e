"""`imutool simulate SCENARIO -o OUT`: a recording with truth columns from the simulator."""

from __future__ import annotations

import click

import formats
from imutool import sim
from imutool.cli.common import emit_summary


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


@click.command("simulate", epilog="Example: imutool simulate ship-roll -o roll.csv --seed 1")
@click.argument("scenario", type=click.Choice(list(sim.SCENARIOS)), metavar="SCENARIO")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=True), help="Output file (.csv, .bag...).")
@click.option("--duration", type=float, default=None, help="Length in s (scenario default if omitted).")
@click.option("--rate", "rate_hz", type=float, default=None, help="Sample rate in Hz (scenario default).")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed (deterministic output).")
@click.option("--set", "settings", multiple=True, metavar="NAME=VALUE",
              help="Scenario option, repeatable (e.g. --set roll_amplitude_deg=20).")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("--quiet", "-q", is_flag=True)
def simulate_cmd(scenario: str, output: str, duration: float | None, rate_hz: float | None, seed: int,
                 settings: tuple[str, ...], as_json: bool, quiet: bool) -> None:
    """Simulate SCENARIO (ship-roll, sea-state, turn, compass-swing, mag-sphere, static, walk, ...)."""
    opts = _parse_set(settings)
    if duration is not None:
        opts["duration"] = duration
    if rate_hz is not None:
        opts["rate_hz"] = rate_hz
    rec = sim.simulate(scenario, seed=seed, **opts)
    rec.meta["scenario"] = scenario
    rec.meta["seed"] = seed
    formats.write(rec, output)
    summary = {"scenario": scenario, "output": output, "rows": len(rec), "duration_s": round(rec.duration, 3),
               "rate_hz": round(rec.rate_hz, 3), "channels": list(rec.channels)}
    emit_summary(summary, as_json, quiet)
