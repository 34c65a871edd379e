"""The route behind ``imutool zvi`` and ``imutool batch zvi``: read the input, detect the zero-velocity intervals
with :mod:`imutool.zvi` (arrays in, arrays out), write the interval table, the per-sample flags and the plot.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

import formats
from formats import Recording
from formats.atomic import atomic_path
from formats.errors import ImutoolError
from imutool.loading import input_notes, one_clock, require_channels
from imutool.routes import OnInput, RouteResult, Stage, read_source
from imutool.zvi import DEFAULTS, DETECTORS, ZviResult, detect_zvi, flag_scores, interval_indices, pick_threshold


def write_intervals(result: ZviResult, path: str | Path) -> None:
    """Write the interval table (start_s, end_s, duration_s) as CSV, or the summary + table as .json."""
    rows = result.table()
    path = Path(path)
    with atomic_path(path) as tmp:
        if path.suffix.lower() == ".json":
            tmp.write_text(json.dumps({**result.summary(), "table": rows}, indent=2))
        else:
            lines = ["start_s,end_s,duration_s"]
            lines += [f"{r['start_s']:.6f},{r['end_s']:.6f},{r['duration_s']:.6f}" for r in rows]
            tmp.write_text("\n".join(lines) + "\n")


def plot_zvi(
    result: ZviResult, gyro: np.ndarray, accel: np.ndarray, path: str | Path, truth: np.ndarray | None = None
) -> None:
    """Plot |gyro|, |accel|, the statistic against its threshold and the detected intervals (PNG/PDF)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = result.time - result.time[0]
    fig, ax = plt.subplots(3, 1, figsize=(11, 7), sharex=True)
    ax[0].plot(t, np.degrees(np.linalg.norm(gyro, axis=1)), lw=0.6, color="C0")
    ax[0].set_ylabel("|gyro| (deg/s)")
    ax[1].plot(t, np.linalg.norm(accel, axis=1), lw=0.6, color="C1")
    ax[1].set_ylabel("|accel| (m/s²)")
    stat = np.maximum(result.statistic, 1e-12)
    ax[2].semilogy(t, stat, lw=0.6, color="C2", label=f"{result.detector} statistic")
    ax[2].axhline(result.threshold, color="k", ls="--", lw=0.8, label=f"threshold {result.threshold:g}")
    ax[2].set_ylabel("statistic")
    ax[2].set_xlabel(f"time (s) from {result.time[0]:.3f}")
    for a in ax:
        for s, e in interval_indices(result.flags):
            a.axvspan(t[s], t[e - 1], color="0.85", zorder=0, lw=0)
    if truth is not None:
        ax[2].plot(
            t, np.where(np.asarray(truth) > 0.5, result.threshold, np.nan), color="C3", lw=2, label="truth stance"
        )
    ax[2].legend(loc="upper right", fontsize=8)
    ax[0].set_title(
        f"Zero-velocity intervals ({result.detector}): {len(result.intervals)} intervals, "
        f"{100 * np.mean(result.flags):.1f} % of samples (grey)"
    )
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=path.suffix.lstrip(".").lower() or "png", dpi=90)
    plt.close(fig)


def run_zvi(
    source: str | os.PathLike | Recording,
    output: str | os.PathLike | None = None,
    *,
    detector: str = "shoe",
    gamma: float | None = None,
    window_s: float | None = None,
    sigma_a: float | None = None,
    sigma_g_deg_s: float | None = None,
    b_g_deg_s: float | None = None,
    b_a: float | None = None,
    window_g_s: float | None = None,
    window_a_s: float | None = None,
    min_duration_s: float | None = None,
    flags_path: str | os.PathLike | None = None,
    plot_path: str | os.PathLike | None = None,
    labels: str | None = None,
    pick: bool = False,
    strict: bool = False,
    on_input: OnInput | None = None,
    stage: Stage | None = None,
    **load_options: Any,
) -> RouteResult:
    """Zero-velocity intervals of ``source`` (gyro + accel; a path or a Recording) written to ``output`` (.csv
    table or .json, :func:`write_intervals`): the route behind ``imutool zvi`` and ``imutool batch zvi``.

    Detector parameters left None take :data:`DEFAULTS` (rates in deg/s here: ``sigma_g_deg_s``, ``b_g_deg_s``;
    a parameter the detector does not take is an error). ``labels``: the column of true flags to score against
    (default ``ref_zvi`` when present); ``pick``: grid-search the threshold maximising F1 against them
    (:func:`pick_threshold`) and use it. Also writes ``flags_path`` (per-sample zvi, zvi_statistic) and
    ``plot_path``. A path is loaded with ``load_options`` (columns, profile, ... calibration_file).
    """
    inputs: list[dict[str, Any]] = []
    if stage is not None:
        stage("reading")
    rec, name, report = read_source(source, inputs, strict=strict, on_input=on_input, **load_options)
    rec = one_clock(rec, ("gyro", "accel"), inputs)  # many clocks: the IMU's own samples
    require_channels(rec, ["gyro", "accel"], name)
    given = {
        "gamma": gamma,
        "window_s": window_s,
        "sigma_a": sigma_a,
        "sigma_g": _rad(sigma_g_deg_s),
        "b_g": _rad(b_g_deg_s),
        "b_a": b_a,
        "window_g_s": window_g_s,
        "window_a_s": window_a_s,
        "min_duration_s": min_duration_s,
    }
    if detector not in DEFAULTS:
        raise ImutoolError(f"unknown ZVI detector {detector!r}; known: {', '.join(DETECTORS)}")
    allowed = DEFAULTS[detector]
    bad = [k for k, v in given.items() if v is not None and k not in allowed]
    if bad:
        opts = ", ".join("--" + b.replace("_s", "").replace("_", "-") for b in bad)
        raise ImutoolError(f"detector {detector!r} does not take {opts}")
    params = {k: v for k, v in given.items() if k in allowed}
    gyro = rec.get("gyro", "rad/s")
    accel = rec.get("accel", "m/s^2")
    label_col = labels or ("ref_zvi" if "ref_zvi" in rec.channels else None)
    if labels and labels not in rec.channels:
        raise ImutoolError(f"label column {labels!r} not found", path=name)
    truth = rec[label_col] if label_col else None
    summary: dict[str, Any] = {"input": name}
    if pick:
        if truth is None:
            raise ImutoolError("--pick-threshold needs labelled flags (--labels COLUMN or a ref_zvi column)")
        best = pick_threshold(rec.time, gyro, accel, truth, detector, **params)
        params[best["param"]] = best["value"]
        summary["picked"] = {"param": best["param"], "value": best["value"], "f1": round(best["f1"], 4)}
    if stage is not None:
        stage(f"detecting ({detector})")
    res = detect_zvi(rec.time, gyro, accel, detector, **params)
    if stage is not None:
        stage("writing")
    if output is not None:
        write_intervals(res, output)
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
    summary["output"] = None if output is None else os.fspath(output)
    if truth is not None:
        summary["score_vs_" + label_col] = {k: round(v, 4) for k, v in flag_scores(res.flags, truth).items()}
    out = Recording(rec.time.copy(), meta={"source": name, "zvi_detector": detector, **input_notes(rec.meta)})
    out.add("zvi", res.flags.astype(float), "1")
    out.add("zvi_statistic", res.statistic, "1")
    if flags_path:
        formats.write(out, flags_path)
        summary["flags"] = os.fspath(flags_path)
    if plot_path:
        plot_zvi(res, gyro, accel, plot_path, truth=truth)
        summary["plot"] = os.fspath(plot_path)
    if report.get("actions"):
        summary["input_fixes"] = report["actions"]
    return RouteResult(summary, inputs, out)


def _rad(v: float | None) -> float | None:
    return None if v is None else float(np.radians(v))
