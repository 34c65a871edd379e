"""`imutool gyrofree IN --layout L -o OUT`: angular rate, angular acceleration and attitude from accelerometers.

Only option parsing and printing here; the work is :func:`imutool.routes.gyrofree.run_gyrofree` (and
:func:`imutool.gyrofree.check_layout` for --check-layout), the route `imutool batch gyrofree` and a Python user take.
"""

from __future__ import annotations

from typing import Any

import click
import numpy as np

from formats.errors import ImutoolError
from imutool.cli.common import (
    default_of,
    emit_summary,
    input_options,
    note_input,
    output_options,
    parse_vector,
    route_of,
    safe_outputs,
    strict_requested,
)
from imutool.gyrofree import RATE_RW, load_layout
from imutool.routes import LOAD_OPTIONS, OnInput, RouteResult
from imutool.routes.gyrofree import layout_report, run_gyrofree


def gyrofree_route(
    input_path: str | None,
    output: str | None,
    layout_path: str,
    initial_rate: str | None,
    planar: str | None,
    rate_rw: float | None,
    on_input: OnInput | None = None,
    **options: Any,
) -> Any:
    """Parsed options → :func:`imutool.routes.gyrofree.run_gyrofree`."""
    layout = load_layout(layout_path)
    if not input_path or not output:
        raise ImutoolError("give INPUT and -o OUTPUT (or --check-layout)")
    return run_gyrofree(
        input_path,
        output,
        layout=layout,
        initial_rate_deg_s=parse_vector(initial_rate, 3, "--initial-rate") if initial_rate else None,
        rate_rw_deg_s=rate_rw,
        planar=[c.strip() for c in planar.split(",")] if planar else None,
        strict=strict_requested(),
        on_input=on_input,
        **options,
    )


@click.command(
    "gyrofree",
    epilog="Example: imutool simulate accel-array -o array.csv && "
    "imutool gyrofree array.csv --layout paper -o rates.csv",
)
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True), required=False)
@click.option("-o", "--output", default=None, type=click.Path(), help="Output file (.csv, ...).")
@click.option(
    "--layout",
    "layout_path",
    required=True,
    help="Layout TOML (positions m body FRD, axes, columns, units) or 'paper' (r = 0.1 m).",
)
@click.option(
    "--check-layout", "check_layout_only", is_flag=True, help="Only check observability/conditioning of the layout."
)
@click.option(
    "--noise",
    type=float,
    default=None,
    help="Accelerometer noise σ per sample (m/s²) [default: layout noise_density·√fs, else estimated].",
)
@click.option(
    "--initial-rate", "initial_rate", default=None, metavar="WX,WY,WZ", help="Initial ω (deg/s) [default from data]."
)
@click.option(
    "--initial-sign",
    type=click.Choice(["+", "-"]),
    default=default_of(run_gyrofree, "initial_sign"),
    show_default=True,
    help="Sign of the largest initial ω component (h(ω) = h(−ω)).",
)
@click.option(
    "--tilt-gain",
    type=float,
    default=default_of(run_gyrofree, "tilt_gain"),
    show_default=True,
    help="Gravity tilt correction gain (1/s) from the centre specific force (0 = pure integration).",
)
@click.option(
    "--rate-rw",
    type=float,
    default=None,
    help=f"ω random walk in Q, deg/s/√s [default {np.degrees(RATE_RW):.3g} = {RATE_RW:g} rad/s/√s].",
)
@click.option(
    "--planar",
    default=None,
    metavar="COL1,COL2",
    help="Reduced mode: two parallel single-axis accelerometers (layout sensors' columns) → roll.",
)
@click.option("--causal", is_flag=True, help="Planar mode only: causal band-pass integration (default zero-phase).")
@click.option("--cutoff", type=float, default=None, help="Planar mode only: band-pass cut-off Hz [0.3 × dominant].")
@input_options
@output_options
@safe_outputs("output")
def gyrofree_cmd(check_layout_only: bool, as_json: bool, quiet: bool, **options: Any) -> None:
    """ω (rad/s), ω̇ (rad/s²), f_O and attitude from N accelerometers (no gyro); --check-layout for geometry."""
    if check_layout_only:
        emit_summary(_layout_check(**options), as_json, quiet)
        return
    res = gyrofree_route(on_input=note_input, **options)
    emit_summary(res.summary, as_json, quiet)


def _batch_route(check_layout_only: bool = False, quiet: bool = True, **options: Any) -> Any:
    """What ``imutool batch gyrofree`` runs per input: the route, or the layout check (an error if degenerate)."""
    if check_layout_only:
        return RouteResult(_layout_check(**options))
    return gyrofree_route(**options)


def _layout_check(input_path: str | None, layout_path: str, **options: Any) -> dict[str, Any]:
    """--check-layout: :func:`imutool.routes.gyrofree.layout_report` with every loading option of a given INPUT
    (:data:`imutool.loading.LOAD_OPTIONS`: ``--columns ... --rate --time-column --header-rows --with``)."""
    load = {k: options[k] for k in LOAD_OPTIONS if options.get(k) is not None}
    return layout_report(layout_path, input_path, strict=strict_requested(), **load)


gyrofree_cmd = route_of(_batch_route)(gyrofree_cmd)
