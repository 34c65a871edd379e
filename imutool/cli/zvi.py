"""`imutool zvi IN -o intervals.csv`: zero-velocity interval detection (paper eq. 43, SHOE, ARE, MV, MAG)."""

from __future__ import annotations

import click
import numpy as np

from formats.errors import ImutoolError
from imutool.cli.common import emit_summary, input_options, load_input, output_options, require_channels, safe_outputs


def _rad(v: float | None) -> float | None:
    return None if v is None else float(np.radians(v))


@click.command("zvi", epilog="Example: imutool zvi walk.csv -o intervals.csv --detector shoe --gamma 1e5 --plot z.png")
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True))
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(dir_okay=False),
    help="Interval table: .csv (start_s,end_s,duration_s) or .json (summary + table).",
)
@click.option(
    "--detector",
    type=click.Choice(["paper", "shoe", "are", "mv", "mag"]),
    default="shoe",
    show_default=True,
    help="paper = eq. 43 gyro + accel-difference windows; Skog 2010: shoe (GLRT), are, mv, mag.",
)
@click.option(
    "--gamma",
    type=float,
    default=None,
    help="Skog detectors: threshold γ (stationary when T < γ). Default shoe/are 1e5, mv/mag 1.5e4.",
)
@click.option("--window", "window_s", type=float, default=None, help="Skog detectors: window W in s [0.05].")
@click.option("--sigma-a", type=float, default=None, help="Accelerometer noise std σ_a in m/s² [0.01].")
@click.option("--sigma-g", type=float, default=None, help="Gyro noise std σ_g in deg/s [0.1].")
@click.option("--b-g", type=float, default=None, help="paper: gyro bound B_g in deg/s [34.4 = 0.6 rad/s].")
@click.option("--b-a", type=float, default=None, help="paper: accel first-difference bound B_a in m/s² [2.0].")
@click.option("--window-g", "window_g_s", type=float, default=None, help="paper: gyro window N_g in s [0.05].")
@click.option("--window-a", "window_a_s", type=float, default=None, help="paper: accel window N_a in s [0.05].")
@click.option(
    "--min-duration", "min_duration_s", type=float, default=None, help="Drop intervals shorter than this, s [0.05]."
)
@click.option(
    "--flags",
    "flags_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="Also write the per-sample recording with columns zvi (0/1) and zvi_statistic.",
)
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="Plot signal, statistic, threshold and intervals (.png/.pdf).",
)
@click.option(
    "--labels",
    "labels",
    default=None,
    metavar="COLUMN",
    help="Column with true ZVI flags to score against (default: ref_zvi if present).",
)
@click.option(
    "--pick-threshold",
    is_flag=True,
    help="Grid-search the threshold (γ, or B_g for paper) maximising F1 against the labels; use it.",
)
@input_options
@output_options
@safe_outputs("output", "flags_path", "plot_path")
def zvi_cmd(
    input_path: str,
    output: str,
    detector: str,
    gamma: float | None,
    window_s: float | None,
    sigma_a: float | None,
    sigma_g: float | None,
    b_g: float | None,
    b_a: float | None,
    window_g_s: float | None,
    window_a_s: float | None,
    min_duration_s: float | None,
    flags_path: str | None,
    plot_path: str | None,
    labels: str | None,
    pick_threshold: bool,
    as_json: bool,
    quiet: bool,
    **input_kw,
) -> None:
    """Detect zero-velocity intervals in INPUT (needs gyro and accel) and write the interval table."""
    from imutool import zvi
    from imutool.progress import stages

    steps = stages("zvi", ["reading", "detecting", "writing"], quiet)
    steps.stage("reading")
    rec, report = load_input(input_path, **input_kw)
    require_channels(rec, ["gyro", "accel"], input_path)
    given = {
        "gamma": gamma,
        "window_s": window_s,
        "sigma_a": sigma_a,
        "sigma_g": _rad(sigma_g),
        "b_g": _rad(b_g),
        "b_a": b_a,
        "window_g_s": window_g_s,
        "window_a_s": window_a_s,
        "min_duration_s": min_duration_s,
    }
    allowed = zvi.DEFAULTS[detector]
    bad = [k for k, v in given.items() if v is not None and k not in allowed]
    if bad:
        opts = ", ".join("--" + b.replace("_s", "").replace("_", "-") for b in bad)
        raise ImutoolError(f"detector {detector!r} does not take {opts}")
    params = {k: v for k, v in given.items() if k in allowed}
    gyro = rec.get("gyro", "rad/s")
    accel = rec.get("accel", "m/s^2")
    label_col = labels or ("ref_zvi" if "ref_zvi" in rec.channels else None)
    if labels and labels not in rec.channels:
        raise ImutoolError(f"label column {labels!r} not found", path=input_path)
    truth = rec[label_col] if label_col else None
    summary: dict = {"input": input_path}
    if pick_threshold:
        if truth is None:
            raise ImutoolError("--pick-threshold needs labelled flags (--labels COLUMN or a ref_zvi column)")
        best = zvi.pick_threshold(rec.time, gyro, accel, truth, detector, **params)
        params[best["param"]] = best["value"]
        summary["picked"] = {"param": best["param"], "value": best["value"], "f1": round(best["f1"], 4)}
    steps.stage(f"detecting ({detector})")
    res = zvi.detect_zvi(rec.time, gyro, accel, detector, **params)
    steps.stage("writing")
    zvi.write_intervals(res, output)
    summary.update(res.summary())
    for k in ("b_g", "sigma_g"):  # degrees at the user surface, as the options
        if k in summary["params"]:
            summary["params"][f"{k}_deg_s"] = round(float(np.degrees(summary["params"].pop(k))), 6)
    if summary.get("picked", {}).get("param") == "b_g":
        summary["picked"] = {
            "param": "b_g_deg_s",
            "value": round(float(np.degrees(summary["picked"]["value"])), 6),
            "f1": summary["picked"]["f1"],
        }
    summary["output"] = output
    if truth is not None:
        summary["score_vs_" + label_col] = {k: round(v, 4) for k, v in zvi.flag_scores(res.flags, truth).items()}
    if flags_path:
        import formats
        from formats import Recording
        from imutool.loading import input_notes

        out = Recording(rec.time.copy(), meta={"source": input_path, "zvi_detector": detector, **input_notes(rec.meta)})
        out.add("zvi", res.flags.astype(float), "1")
        out.add("zvi_statistic", res.statistic, "1")
        formats.write(out, flags_path)
        summary["flags"] = flags_path
    if plot_path:
        zvi.plot_zvi(res, gyro, accel, plot_path, truth=truth)
        summary["plot"] = plot_path
    if report.get("actions"):
        summary["input_fixes"] = report["actions"]
    steps.close()
    emit_summary(summary, as_json, quiet)
