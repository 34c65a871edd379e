"""`imutool evaluate EST --reference REF`: estimate vs truth — RMSE, max, p95, MAE, lag, SNR, BROAD metrics.

Options and printing only; the comparison is :func:`imutool.evaluation.run_evaluate` (the route `imutool batch
evaluate` and a Python user take).
"""

from __future__ import annotations

from typing import Any

import click

from formats.errors import ImutoolError
from imutool.cli.common import (
    ClockTime,
    default_of,
    emit_summary,
    input_options,
    note_input,
    reference_frame_options,
    reference_options,
    route_of,
    safe_outputs,
    strict_requested,
)
from imutool.evaluation import CHANNELS, parse_align_heading, run_evaluate


def _align(value: str | None) -> str | None:
    """``--align-heading`` checked at parsing (a usage error names the option)."""
    try:
        parse_align_heading(value)
    except ImutoolError as e:
        raise click.BadParameter(str(e).split(": ", 1)[-1]) from None
    return value


def evaluate_route(
    est_path: str,
    ref_path: str | None = None,
    channel: str | None = default_of(run_evaluate, "channel"),
    max_lag: float = default_of(run_evaluate, "max_lag_s"),
    plot_path: str | None = default_of(run_evaluate, "plot"),
    align_heading: str | None = default_of(run_evaluate, "align_heading"),
    ref_frame: str | None = default_of(run_evaluate, "ref_frame"),
    ref_mounting: str | None = default_of(run_evaluate, "ref_mounting"),
    t_start: float | str | None = default_of(run_evaluate, "start"),
    t_end: float | str | None = default_of(run_evaluate, "end"),
    quiet: bool = True,
    on_input: Any = None,
    **load_options: Any,
) -> Any:
    """Parsed options → :func:`imutool.evaluation.run_evaluate` (the loading options apply to EST; the ``ref_*``
    ones, :func:`imutool.cli.common.reference_options`, to the reference)."""
    return run_evaluate(
        est_path,
        ref_path,
        channel=channel,
        max_lag_s=max_lag,
        plot=plot_path,
        align_heading=align_heading,
        ref_frame=ref_frame,
        ref_mounting=ref_mounting,
        start=t_start,
        end=t_end,
        strict=strict_requested(),
        on_input=on_input,
        **load_options,
    )


@click.command("evaluate", epilog="Example: imutool evaluate est.csv --reference roll.csv --max-lag 1 --plot err.png")
@click.argument("est_path", metavar="EST", type=click.Path(exists=True))
@click.option(
    "--reference",
    "ref_path",
    type=click.Path(exists=True),
    default=None,
    help="File with the ref_* truth columns (default: EST itself).",
)
@click.option(
    "--channel",
    type=click.Choice(list(CHANNELS)),
    default=None,
    help="What to compare (default: angles, plus quaternion when both files have one).",
)
@click.option(
    "--max-lag",
    type=float,
    default=default_of(run_evaluate, "max_lag_s"),
    show_default=True,
    help="Search a constant lag up to ± this many seconds (response time / phase lag).",
)
@click.option("--plot", "plot_path", type=click.Path(), default=None, help="Error plot (.png/.pdf).")
@click.option(
    "--align-heading",
    default=None,
    metavar="DEG|auto",
    callback=lambda ctx, param, v: _align(v),
    help="Add a constant heading offset (deg) to the reference (a motion-capture frame's x axis is not north); "
    "'auto' estimates it as the circular mean of estimate − reference heading and reports it.",
)
@reference_frame_options
@click.option(
    "--start",
    "t_start",
    type=ClockTime(),
    default=None,
    help="Compare from this time: s on the estimate's clock, or a UTC time (2014-08-01T12:00:00Z) where it has a "
    "date (as a report's --start); e.g. after the filter has settled.",
)
@click.option("--end", "t_end", type=ClockTime(), default=None, help="Compare up to this time (as --start).")
@input_options
@reference_options
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("--quiet", "-q", is_flag=True)
@safe_outputs("plot_path")
def evaluate_cmd(
    est_path: str,
    ref_path: str | None,
    channel: str | None,
    max_lag: float,
    plot_path: str | None,
    align_heading: str | None,
    ref_frame: str | None,
    ref_mounting: str | None,
    t_start: float | str | None,
    t_end: float | str | None,
    as_json: bool,
    quiet: bool,
    **load_options: Any,
) -> None:
    """Compare the estimate EST with a reference: per angle RMSE, max, p95, MAE, lag and SNR_dB (deg; heading
    errors wrapped), quaternion errors with the BROAD metrics (total, heading, inclination), heave, position."""
    summary = evaluate_route(
        est_path,
        ref_path,
        channel,
        max_lag,
        plot_path,
        align_heading,
        ref_frame=ref_frame,
        ref_mounting=ref_mounting,
        t_start=t_start,
        t_end=t_end,
        on_input=note_input,
        **load_options,
    ).summary
    for w in summary.get("warnings") or []:
        click.echo(f"warning: {w}", err=True)
    lines = None
    if "angles" in summary:
        lines = [f"{'angle':8s} {'RMSE':>7s} {'max':>7s} {'p95':>7s} {'MAE':>7s} {'lag s':>7s} {'SNR dB':>7s}"]
        for k, v in summary["angles"].items():
            lines.append(
                f"{k:8s} {v['rmse']:7.3f} {v['max_abs']:7.3f} {v['p95_abs']:7.3f} {v['mae']:7.3f} "
                f"{v.get('lag_s', float('nan')):7.3f} {v.get('snr_db', float('nan')):7.1f}"
            )
        if "quaternion" in summary:
            qv = summary["quaternion"]
            lines.append(
                f"BROAD ({qv['rows']}): total {qv['total']['rmse']:.3f}°, heading "
                f"{qv['heading']['rmse']:.3f}°, inclination {qv['inclination']['rmse']:.3f}° RMSE"
            )
    if lines is not None:
        al = summary.get("align_heading")
        if al:
            lines.append(f"heading alignment: {al['offset_deg']:+.3f}° added to the reference ({al['how']})")
        for note in summary.get("derived", []):
            lines.append(f"note: {note}")
        ld = summary.get("reference_loading")
        if ld:
            from imutool.loading import loading_text

            lines.append(f"reference loaded: {loading_text(ld)}")
        fr = summary.get("reference_frame")
        if fr and (fr.get("world") != "ned" or fr.get("mounting")):
            lines.append(f"reference frame: {fr['how']}")
        lines.append(f"compared: {summary['span']['text']}")
    emit_summary(summary, as_json, quiet, lines)


evaluate_cmd = route_of(evaluate_route, ("plot_path",))(evaluate_cmd)
