"""`imutool evaluate EST --reference REF`: estimate vs truth — RMSE, max, p95, MAE, lag, SNR, BROAD metrics.

Options and printing only; the comparison is :func:`imutool.evaluation.evaluate`.
"""

from __future__ import annotations

import click

from imutool.cli.common import emit_summary, safe_outputs


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
    type=click.Choice(["angles", "quaternion", "heave", "position"]),
    default=None,
    help="What to compare (default: angles, plus quaternion when both files have one).",
)
@click.option(
    "--max-lag",
    type=float,
    default=0.0,
    show_default=True,
    help="Search a constant lag up to ± this many seconds (response time / phase lag).",
)
@click.option("--plot", "plot_path", type=click.Path(), default=None, help="Error plot (.png/.pdf).")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("--quiet", "-q", is_flag=True)
@safe_outputs("plot_path")
def evaluate_cmd(
    est_path: str,
    ref_path: str | None,
    channel: str | None,
    max_lag: float,
    plot_path: str | None,
    as_json: bool,
    quiet: bool,
) -> None:
    """Compare the estimate EST with a reference: per angle RMSE, max, p95, MAE, lag and SNR_dB (deg; heading
    errors wrapped), quaternion errors with the BROAD metrics (total, heading, inclination), heave, position."""
    from imutool.evaluation import evaluate

    summary = evaluate(est_path, ref_path, channel=channel, max_lag_s=max_lag, plot=plot_path)
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
    emit_summary(summary, as_json, quiet, lines)
