"""`imutool roll INPUT -o roll_stats.csv`: MSC.363(92) roll statistics (heel, period, amplitudes, peak hold).

Only option parsing and printing here; the work is :func:`imutool.routes.roll.run_roll`, the route
`imutool batch roll` and a Python user take (the detector's defaults live in :data:`imutool.roll.ROLL_DEFAULTS`).
"""

from __future__ import annotations

from datetime import datetime, timezone
from typing import Any

import click

from formats.errors import ImutoolError
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
from imutool.routes import OnInput, RouteResult
from imutool.routes.roll import run_roll

OUTPUTS = ("output", "cycles_path")


def parse_utc(text: str | None) -> datetime | None:
    """ISO 8601 UTC time (e.g. 2026-01-05T10:00:00Z) → aware datetime; None passes through."""
    if not text:
        return None
    try:
        d = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise ImutoolError(f"--utc-start {text!r}: expected ISO 8601, e.g. 2026-01-05T10:00:00Z") from None
    return d if d.tzinfo else d.replace(tzinfo=timezone.utc)


def parse_resets(text: str | None) -> list[float]:
    if not text:
        return []
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ImutoolError(f"--reset {text!r}: expected comma-separated times in s") from None


class Hysteresis(click.ParamType):
    """``auto`` (None: scaled to the roll) or a fixed hysteresis in degrees."""

    name = "auto|DEG"

    def convert(self, value: Any, param: Any, ctx: Any) -> float | None:
        if value is None or (isinstance(value, str) and value.strip().lower() == "auto"):
            return None
        try:
            v = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r}: expected 'auto' or a number of degrees", param, ctx)
        if not 0 <= v <= 90:
            self.fail(f"{value!r}: expected 'auto' or a hysteresis in [0, 90] deg", param, ctx)
        return v


def _frac_option(flag: str, dest: str, text: str):
    return click.option(flag, dest, type=float, default=default_of(run_roll, dest), show_default=True, help=text)


def roll_options(f):
    """Options of the roll-cycle detector shared by `roll` and `nmea` (defaults: imutool.roll.ROLL_DEFAULTS)."""
    opts = [
        click.option(
            "--hysteresis",
            "hysteresis_deg",
            type=Hysteresis(),
            default="auto",
            show_default=True,
            help="Hysteresis (deg) around the centre: oscillations smaller than ± this are ignored; auto = "
            "--hysteresis-frac × the roll's running RMS, at least --hysteresis-min.",
        ),
        _frac_option("--hysteresis-frac", "hysteresis_frac", "Auto hysteresis: this fraction of the roll's RMS."),
        _frac_option("--hysteresis-min", "hysteresis_min_deg", "Auto hysteresis: at least this (deg)."),
        click.option(
            "--centre",
            type=click.Choice(["zero", "running"]),
            default=default_of(run_roll, "centre"),
            show_default=True,
            help="Centre of the port/starboard split and of the amplitudes: the mean heel over --centre-window "
            "(running) or 0 (zero: a level ship, e.g. a motion table).",
        ),
        click.option(
            "--centre-window",
            "centre_window_s",
            type=float,
            default=default_of(run_roll, "centre_window_s"),
            show_default=True,
            help="Running-mean window (s) of --centre running (and of the auto hysteresis's RMS).",
        ),
        _frac_option(
            "--smooth", "smooth_frac", "Detection smoothing: this fraction of the spectral peak period (0 = none)."
        ),
        _frac_option(
            "--disagree",
            "disagree_frac",
            "Warn when the peak-to-peak, zero-up-crossing and spectral periods differ by more than this fraction.",
        ),
        click.option(
            "--refine",
            "refine_frac",
            type=float,
            default=default_of(run_roll, "refine_frac"),
            show_default=True,
            help="Peak refinement: parabola over ± this fraction of the excursion duration.",
        ),
        click.option(
            "--max-period",
            "max_period_s",
            type=float,
            default=default_of(run_roll, "max_period_s"),
            show_default=True,
            help="Longest roll period accepted (s); longer gaps are not periods.",
        ),
        click.option(
            "--reset",
            "resets",
            default=None,
            metavar="T1,T2,...",
            help="Peak-hold reset times (s, recording time); the start is always a reset.",
        ),
        click.option(
            "--utc-start",
            default=None,
            metavar="ISO",
            help="UTC of time 0 (for the reset time/date); Unix-epoch times need none.",
        ),
    ]
    for o in reversed(opts):
        f = o(f)
    return f


def roll_route(
    input_path: str,
    output: str,
    resets: str | None = None,
    utc_start: str | None = None,
    quiet: bool = True,
    on_input: OnInput | None = None,
    **options: Any,
) -> RouteResult:
    """Parsed options → :func:`imutool.routes.roll.run_roll` (``--reset`` and ``--utc-start`` parsed here)."""
    return run_roll(
        input_path,
        output,
        resets_s=parse_resets(resets),
        utc_start=parse_utc(utc_start),
        strict=strict_requested(),
        on_input=on_input,
        **options,
    )


@click.command("roll", epilog="Example: imutool roll est.csv -o roll_stats.csv --cycles cycles.csv")
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True))
@click.option("-o", "--output", required=True, type=click.Path(), help="Per-sample statistics (.csv).")
@click.option(
    "--cycles",
    "cycles_path",
    default=None,
    type=click.Path(),
    help="Also write the per-cycle table (one row per port/starboard maximum) to this CSV.",
)
@roll_options
@input_options
@output_options
@safe_outputs(*OUTPUTS)
def roll_cmd(input_path: str, output: str, as_json: bool, quiet: bool, **options: Any) -> None:
    """Roll statistics per IMO MSC.363(92) §3 from the `roll` (or HRM `heel`) channel of INPUT.

    Heel is in degrees, + starboard down. Roll period = time between successive maxima on the same side
    (port and starboard tracked separately), cycles counted about the mean heel with a hysteresis scaled to the
    roll, cross-checked against the zero-up-crossing and spectral peak periods (a warning when they disagree);
    amplitudes per side from the mean heel (port reported positive, as HRM; --centre zero: from level); peak hold
    since the last reset. Per-sample values are causal: a cycle's values appear when it completes.
    """
    res = roll_route(input_path, output, quiet=quiet, on_input=note_input, **options)
    rs = res.data["stats"]
    for w in rs.warnings:
        click.echo(f"warning: {input_path}: {w}", err=True)
    lines = [f"{input_path}: {len(res.recording)} samples, {len(rs.cycles)} half-cycles → {output}"]
    s = rs.summary()
    est = s["period_estimates"]

    def sec(v: float | None) -> str:
        return "-" if v is None else f"{v:.2f} s"

    lines.append(
        f"  period: peak-to-peak (same-side maxima) {sec(est['peak_to_peak_s'])}, zero-up-crossing "
        f"{sec(est['zero_up_crossing_s'])}, spectral peak {sec(est['spectral_peak_s'])}"
        + ("" if est["spread"] is None else f" (spread {100 * est['spread']:.0f} %)")
    )
    mh = s["mean_heel_deg"]
    lines.append(f"  amplitudes from the {s['amplitude_from']}" + ("" if mh is None else f" (mean heel {mh:+.2f}°)"))
    for side in ("starboard", "port"):
        d = s[side]
        per = f"{d['period_mean_s']:.2f} s" if d["period_mean_s"] is not None else "-"
        amp = f"{d['amplitude_mean_deg']:.2f}° (max {d['amplitude_max_deg']:.2f}°)" if d["excursions"] else "-"
        lines.append(f"  {side:9s}: {d['excursions']} maxima, mean period {per}, mean amplitude {amp}")
    pp, ps = s["peak_hold_port_deg"], s["peak_hold_stbd_deg"]
    lines.append(
        f"  peak hold since reset: port {pp if pp is None else round(pp, 2)}°, "
        f"starboard {ps if ps is None else round(ps, 2)}° (reset {s['last_reset_utc'] or 'at start'})"
    )
    emit_summary(res.summary, as_json, quiet, lines)


roll_cmd = route_of(roll_route, OUTPUTS)(roll_cmd)
