"""`imutool events detect INPUT -o events.json` and `imutool events fleet RESULTS... -o fleet.csv --plot fleet.png`.

Thin click layer over :mod:`imutool.events` (heavy-roll events, hourly MSC.363(92) statistics, parametric roll):
`detect` calls :func:`imutool.events.run_events` and `fleet` :func:`imutool.events.run_fleet`, the routes `imutool
batch` and a Python user take.
"""

from __future__ import annotations

from typing import Any

import click

from imutool import events as _events
from imutool.cli.common import emit_summary, input_options, note_input, route_of, safe_outputs, strict_requested
from imutool.routes import RouteResult

D = _events.DEFAULTS
FLEET_OUTPUTS = ("output", "voyages_path", "plot_path")


@click.group(
    "events",
    epilog="Example: imutool events detect est.csv -o est_events.json   |   "
    "imutool events fleet events/ -o fleet.csv --plot fleet.png",
)
def events_group() -> None:
    """Roll events per recording (detect) and across a fleet (fleet)."""


@events_group.command(
    "detect",
    epilog="Example: imutool events detect pr.csv -o pr_events.json --roll-channel ref_roll --pitch-channel ref_pitch",
)
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True))
@click.option("-o", "--output", default=None, type=click.Path(), help="Result as JSON (events, hourly, summary).")
@click.option("--events-csv", default=None, type=click.Path(), help="Also the event table as CSV.")
@click.option("--hourly-csv", default=None, type=click.Path(), help="Also the hourly statistics as CSV.")
@click.option("--roll-channel", default=None, help="Heel/roll channel, deg + starboard (default heel or roll).")
@click.option("--pitch-channel", default=None, help="Pitch channel, deg (default pitch) for the encounter period.")
@click.option("--heave-channel", default=None, help="Heave channel, m (default heave), used when there is no pitch.")
@click.option(
    "--threshold",
    "threshold_deg",
    type=float,
    default=D["threshold_deg"],
    show_default=True,
    help="Heavy roll: |heel| at or above this (deg).",
)
@click.option(
    "--merge-gap",
    "merge_gap_s",
    type=float,
    default=D["merge_gap_s"],
    show_default=True,
    help="Threshold crossings closer than this (s) are one event.",
)
@click.option(
    "--hysteresis",
    "hysteresis_deg",
    type=float,
    default=D["hysteresis_deg"],
    show_default=True,
    help="Roll-cycle hysteresis (deg), as in `imutool roll`.",
)
@click.option(
    "--hour", "hour_s", type=float, default=D["hour_s"], show_default=True, help="Length of a statistics bin (s)."
)
@click.option(
    "--tuning-tol",
    type=float,
    default=D["tuning_tol"],
    show_default=True,
    help="Parametric roll: accepted |Troll/(2·Te) − 1|.",
)
@click.option(
    "--min-cycles",
    type=int,
    default=D["min_cycles"],
    show_default=True,
    help="Parametric roll: fewest growing half-cycles.",
)
@click.option(
    "--min-growth",
    type=float,
    default=D["min_growth"],
    show_default=True,
    help="Parametric roll: smallest amplitude growth factor.",
)
@click.option(
    "--min-amplitude",
    "min_amplitude_deg",
    type=float,
    default=D["min_amplitude_deg"],
    show_default=True,
    help="Parametric roll: smallest peak amplitude (deg).",
)
@click.option(
    "--min-lock",
    type=float,
    default=D["min_lock"],
    show_default=True,
    help="Parametric roll: smallest roll/pitch phase-locking value (0…1).",
)
@click.option(
    "--window",
    "window_s",
    type=float,
    default=D["window_s"],
    show_default=True,
    help="Window (s) for the encounter period around each roll cycle.",
)
@click.option("--utc-start", default=None, metavar="ISO", help="UTC of time 0 (Unix-epoch times need none).")
@click.option("--ship", default=None, help="Ship name (default: metadata ship/vessel, else the parent folder).")
@click.option("--voyage", default=None, help="Voyage (default: metadata voyage, else the file stem).")
@click.option(
    "--path-regex",
    default=None,
    metavar="REGEX",
    help="Ship/voyage from the path: named groups ship and voyage, e.g. '(?P<ship>[^/]+)/(?P<voyage>[^/]+)/'.",
)
@input_options
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("--quiet", "-q", is_flag=True)
@safe_outputs("output", "events_csv", "hourly_csv")
def detect_cmd(input_path: str, output: str | None, as_json: bool, quiet: bool, **options: Any) -> None:
    """Heavy-roll events, hourly roll statistics (MSC.363(92)) and parametric-roll episodes of INPUT (read with
    the loading options every command takes: --columns, --time-column, --with ...)."""
    r = detect_route(input_path, output, on_input=note_input, **options)
    res, s = r.data, r.summary
    para = [e for e in res["events"] if e["type"] == "parametric_roll"]
    lines = [
        f"{input_path}: ship {res['ship']}, voyage {res['voyage']}, {s['rows']} rows, {s['duration_s']:.0f} s",
        f"max heel {s['max_heel_deg']:.1f}° ; {s['heavy_roll_events']} heavy-roll events "
        f"(|heel| ≥ {res['settings']['threshold_deg']:g}°), {len(res['hourly'])} hourly rows",
    ]
    for e in res["events"]:
        if e["type"] == "heavy_roll":
            lines.append(
                f"  heavy roll  t {e['t_start']:.1f}–{e['t_end']:.1f} s, peak {e['peak_deg']:.1f}°, "
                f"{e['crossings']} crossings, period {e['period_s'] or float('nan'):.1f} s"
            )
    for e in para:
        lines.append(
            f"  PARAMETRIC ROLL onset {e['t_onset']:.1f} s, roll period {e['period_s']:.1f} s = "
            f"{e['period_ratio']:.2f} × encounter {e['encounter_period_s']:.1f} s, growth "
            f"{e['growth_rate_per_s']:.4f} 1/s, peak {e['peak_deg']:.1f}°, phase lock {e['phase_lock']:.2f}"
        )
    for n in res["notes"]:
        lines.append(f"note: {n}")
    emit_summary(r.summary, as_json, quiet, lines=lines)


def detect_route(
    input_path: str, output: str | None, quiet: bool = True, on_input: Any = None, **options: Any
) -> RouteResult:
    """Parsed options → :func:`imutool.events.run_events` (the loading options go to its input)."""
    return _events.run_events(input_path, output, strict=strict_requested(), on_input=on_input, **options)


detect_cmd = route_of(detect_route, ("output", "events_csv", "hourly_csv"))(detect_cmd)


@events_group.command(
    "fleet", epilog="Example: imutool events fleet events/ -o fleet.csv --voyages voyages.csv --plot fleet.png"
)
@click.argument("inputs", nargs=-1, required=True)
@click.option("-o", "--output", required=True, type=click.Path(), help="Fleet event table (.csv or .parquet).")
@click.option("--voyages", "voyages_path", default=None, type=click.Path(), help="Per-voyage table (.csv).")
@click.option("--plot", "plot_path", default=None, type=click.Path(), help="Plot (.png/.pdf/.svg).")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("--quiet", "-q", is_flag=True)
@safe_outputs(*FLEET_OUTPUTS)
def fleet_cmd(
    inputs: tuple[str, ...], output: str, voyages_path: str | None, plot_path: str | None, as_json: bool, quiet: bool
) -> None:
    """One table across many `events detect` results (JSON files, folders or globs): events per ship/voyage."""
    res = fleet_route(inputs, output, voyages_path, plot_path)
    summary, voyages = res.summary, res.data["voyages"]
    lines = [
        f"{summary['results']} recordings, {summary['ships']} ships, {len(voyages)} voyages, "
        f"{summary['events']} events "
        f"({summary['parametric_roll_episodes']} parametric roll) → {output}"
    ]
    for v in voyages:
        w = v["worst_roll_deg"]
        lines.append(
            f"  {v['ship']:<16} {v['voyage']:<16} worst roll {'' if w is None else f'{w:6.1f}°'}  heavy "
            f"{v['heavy_roll_events']}  parametric {v['parametric_roll_episodes']}"
        )
    emit_summary(summary, as_json, quiet, lines=lines)


def fleet_route(
    inputs: tuple[str, ...], output: str, voyages_path: str | None, plot_path: str | None, quiet: bool = True
) -> RouteResult:
    """Parsed options → :func:`imutool.events.run_fleet`."""
    return _events.run_fleet(inputs, output, voyages_path=voyages_path, plot_path=plot_path)


fleet_cmd = route_of(fleet_route, FLEET_OUTPUTS)(fleet_cmd)
