"""``imutool allan``: overlapping Allan deviation → ARW/VRW, bias instability, RRW; noise.yaml and kalibr imu.yaml.

Options and printing only; the analysis and the files are :func:`imutool.noise.allan_noise`, the route
`imutool batch allan` and a Python user take (its defaults are the options').
"""

from __future__ import annotations

from typing import Any

import click
import numpy as np

from imutool.cli.common import (
    default_of,
    emit_summary,
    input_options,
    note_input,
    output_options,
    route_of,
    safe_outputs,
    strict_requested,
)
from imutool.noise import SI as _SI
from imutool.noise import NoiseRun, allan_noise
from imutool.progress import stages
from imutool.routes import OnInput

OUTPUTS = ("output", "plot", "kalibr")


def allan_route(
    inputs: tuple[str, ...],
    output: str,
    channels: str = default_of(allan_noise, "channels"),
    quiet: bool = True,
    on_input: OnInput | None = None,
    **options: Any,
) -> NoiseRun:
    """Parsed options → :func:`imutool.noise.allan_noise` (progress on stderr unless ``quiet``)."""
    wanted = [c.strip() for c in channels.split(",") if c.strip()]
    with stages("allan", [*inputs, *wanted, "writing"], quiet) as steps:
        return allan_noise(
            inputs,
            output,
            channels=channels,
            strict=strict_requested(),
            stage=steps.stage,
            on_input=on_input,
            **options,
        )


_LABEL = {"gyro": ("ARW", "rad/s/√Hz"), "accel": ("VRW", "m/s²/√Hz"), "mag": ("white", "µT/√Hz")}


@click.command("allan", epilog="Example: imutool allan static.csv -o noise.yaml --plot allan.png --kalibr imu.yaml")
@click.argument("inputs", nargs=-1, required=True, metavar="INPUT...")
@click.option(
    "-o",
    "--output",
    required=True,
    help="Noise file (.yaml, SI: rad/s/√Hz, m/s²/√Hz, µT/√Hz): white noise, bias instability and random "
    "walk per sensor, to fill in the noise options of filter/ins or a kalibr config.",
)
@click.option("--plot", default=None, help="Log-log Allan deviation plot with the fitted lines (.png/.pdf).")
@click.option("--kalibr", default=None, help="Also write a kalibr-style imu.yaml here.")
@click.option(
    "--topic-name",
    default=default_of(allan_noise, "topic_name"),
    show_default=True,
    help="rostopic written into the kalibr file.",
)
@click.option(
    "--kalibr-fallback",
    type=click.Choice(["refuse", "upper-bound"]),
    default=default_of(allan_noise, "kalibr_fallback"),
    show_default=True,
    help="A random walk the recording does not resolve: refuse the kalibr file, or write its upper bound "
    "(labelled in the file, with a warning). Never a silent 0.",
)
@click.option(
    "--channels",
    default=default_of(allan_noise, "channels"),
    show_default=True,
    help="Channels to analyse (those present in the inputs).",
)
@click.option(
    "--per-decade",
    type=int,
    default=default_of(allan_noise, "per_decade"),
    show_default=True,
    help="Cluster times per decade of τ.",
)
@click.option("--start", type=float, default=None, help="Use data from this time (s) on.")
@click.option("--end", type=float, default=None, help="Use data before this time (s).")
@input_options
@output_options
@safe_outputs(*OUTPUTS)
def allan_cmd(output: str, plot: str | None, kalibr: str | None, as_json: bool, quiet: bool, **options: Any) -> None:
    """Allan deviation of a static recording (several INPUT files: one per sensor, each on its own clock).

    For each axis: N (ARW/VRW) read at τ = 1 s on the slope −½ line, bias instability B = min σ / 0.664 when a
    flicker floor is seen (else the minimum is labelled the white/random-walk crossover, an upper bound), K
    (rate/acceleration random walk) read at τ = 3 s on the slope +½ line (or "not resolved" with its bound).
    The summary gives the gyro in
    degrees (ARW °/√h, B °/h, K °/h/√h), accelerometer and magnetometer in SI; the noise file is SI throughout.
    """
    run = allan_route(output=output, plot=plot, kalibr=kalibr, quiet=quiet, on_input=note_input, **options)
    results, info, warnings = run.results, run.info, run.summary["warnings"]
    lines = [f"Allan deviation → {output}" + (f", {kalibr}" if kalibr else "") + (f", {plot}" if plot else "")]
    for r in results:
        lab, unit = _LABEL[r.name]
        s = r.summary()
        lines.append(f"  {r.name} ({info[r.name]['rate_hz']} Hz, {info[r.name]['duration_s']} s):")
        if info[r.name]["timing"] != "regular":
            lines.append(f"    note: {info[r.name]['timing']}")
        taus = "   at τ = " + ", ".join(f"{v:.3g}" for v in s["tau_min_s"]) + " s"
        lab_b = {
            "bias instability": "flicker floor",
            "crossover": "white/random-walk crossover, NOT a bias instability",
            "upper bound": "σ still falling: upper bound",
        }
        taus += " (" + "; ".join(lab_b[k] for k in s["B_kind"]) + ")"
        is_b = all(k == "bias instability" for k in s["B_kind"])
        blab = "bias inst. B" if is_b else "Allan min/0.664"

        def kfmt(scale: float, s=s) -> str:
            return "  ".join(
                f"{v * scale:.4g}" if ok else f"not resolved (<= {ub * scale:.3g})"
                for v, ok, ub in zip(s["K"], s["K_resolved"], s["K_upper"], strict=True)
            )

        if r.name == "gyro":  # degrees at the user surface (the noise file stays SI)
            lines.append("    ARW N          (°/√h) = " + "  ".join(f"{np.degrees(v) * 60:.4g}" for v in s["N"]))
            lines.append(f"    {blab:15s} (°/h) = " + "  ".join(f"{np.degrees(v) * 3600:.4g}" for v in s["B"]) + taus)
            lines.append("    rate RW K    (°/h/√h) = " + kfmt(np.degrees(1.0) * 216000))
        else:
            lines.append(f"    {lab} N  ({unit:>11s}) = " + "  ".join(f"{v:.4g}" for v in s["N"]))
            lines.append(f"    {blab} ({_SI[r.name]:>9s}) = " + "  ".join(f"{v:.4g}" for v in s["B"]) + taus)
            lines.append(f"    random walk K ({_SI[r.name]}/√s) = " + kfmt(1.0))
        if any(k == "upper bound" for k in s["B_kind"]):
            lines.append(
                "    note: σ(τ) still falls at the longest τ on some axes: B there is an upper bound and K is "
                "not resolved (record longer)"
            )
    for w in warnings:
        click.echo(f"warning: {w}", err=True)
    emit_summary(run.summary, as_json, quiet, lines)


allan_cmd = route_of(allan_route, OUTPUTS)(allan_cmd)
