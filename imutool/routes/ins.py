"""The route behind ``imutool ins`` and ``imutool batch ins``: read the input, dead-reckon it with
:mod:`imutool.ins` (the INS over arrays), write the track, the stride table and the plot.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

import formats
from formats import Recording
from formats.atomic import atomic_path
from formats.csv import format_array
from formats.errors import ImutoolError
from formats.jit.warm import CSV_WRITER, wait_for, warm_in_background
from imutool.ins import (
    GYRO_NOISE_DEG,
    INS_KERNEL,
    STRIDE_COLUMNS,
    ZARU_SIGMA_DEG,
    InsConfig,
    _ins_kernel,
    evaluate_position,
    ins,
    strides,
)
from imutool.loading import one_clock, require_channels
from imutool.routes import OnInput, RouteResult, Stage, read_source


def _loop_entries(ends: dict[str, Any]) -> dict[str, Any]:
    """The summary's loop figures: a closed-loop error for a loop, else why none is claimed."""
    share = ends["start_to_end_percent_of_distance"]
    if ends["loop"]:
        return {
            "closed_loop_error_m": round(ends["final_error_m"], 4),
            "closed_loop_error_percent": round(share, 3) if share is not None else None,
        }
    if ends["loop_decided"] == "given":
        return {"loop_note": "not a loop (--no-loop): the start-to-end distance is no error"}
    pct = f" ({share:.1f} % of the path)" if share is not None else ""
    return {
        "loop_note": f"start and end {ends['start_to_end_m']:.2f} m apart{pct}: not a loop, so no loop-closure "
        "error is claimed (--loop if the walk did end where it started)"
    }


def plot_track(out: Recording, path: str, title: str = "", ref: np.ndarray | None = None) -> None:
    """Top view (east vs north) of the track with ZVI positions, and height against time (PNG/PDF)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p = out["pos"]
    t = out.time - out.time[0]
    z = out["zvi"] > 0.5 if "zvi" in out.channels else np.zeros(len(t), bool)
    fig = plt.figure(figsize=(10, 5.2))
    ax = fig.add_axes([0.06, 0.1, 0.5, 0.8])
    ax.plot(p[:, 1], p[:, 0], lw=0.8, color="C0", label="INS track")
    ax.plot(p[z, 1], p[z, 0], ".", ms=1.5, color="C2", label="ZVI (stance)")
    if ref is not None:
        ax.plot(ref[:, 1], ref[:, 0], "--", lw=0.8, color="C3", label="reference")
    ok = np.flatnonzero(np.all(np.isfinite(p), axis=1))
    if len(ok):
        ax.plot(p[ok[0], 1], p[ok[0], 0], "ko", ms=5, label="start")
        ax.plot(p[ok[-1], 1], p[ok[-1], 0], "rs", ms=5, label="end")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    ax.set_title(title or "INS track (top view)", fontsize=9)
    ax2 = fig.add_axes([0.65, 0.1, 0.33, 0.8])
    ax2.plot(t, -p[:, 2], lw=0.7, color="C0", label="height (−pos_d)")
    if ref is not None:
        ax2.plot(t, -ref[:, 2], "--", lw=0.7, color="C3", label="reference")
    ax2.set_xlabel("time (s)")
    ax2.set_ylabel("height (m, up)")
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=7)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=str(path).rsplit(".", 1)[-1].lower(), dpi=90)
    plt.close(fig)


def write_strides(table: list[dict[str, Any]], path: str | os.PathLike) -> None:
    """The stride table of :func:`strides` as CSV (atomic): a header ``start_s,...,duration_s`` (s, m) and one
    row a stride, 4 decimals (0.1 ms, 0.1 mm) through the imutool CSV number formatter; NaN is an empty field."""
    data = np.array([[r[c] for c in STRIDE_COLUMNS] for r in table], dtype=float).reshape(-1, len(STRIDE_COLUMNS))
    text = format_array(data, decimals=np.full(len(STRIDE_COLUMNS), 4, np.int64)) if len(data) else b""
    with atomic_path(path) as tmp:
        tmp.write_bytes((",".join(STRIDE_COLUMNS) + "\n").encode("ascii") + text)


def run_ins_track(
    source: str | os.PathLike | Recording,
    output: str | os.PathLike | None = None,
    *,
    zupt: bool = InsConfig.zupt,
    height_update: bool = InsConfig.height_update,
    zaru: bool = InsConfig.zaru,
    detector: str = "shoe",
    gamma: float | None = None,
    zvi_column: str | None = None,
    order: int = InsConfig.order,
    gyro_noise_deg: float = GYRO_NOISE_DEG,
    accel_noise: float = InsConfig.accel_noise,
    zupt_sigma: float = InsConfig.zupt_sigma,
    height_sigma: float = InsConfig.height_sigma,
    zaru_sigma_deg: float = ZARU_SIGMA_DEG,
    bias_states: bool = InsConfig.accel_bias_states,
    heading_deg: float = InsConfig.heading_deg,
    align_window_s: float = InsConfig.align_window_s,
    align_guard_s: float = InsConfig.align_guard_s,
    plot_path: str | os.PathLike | None = None,
    strides_path: str | os.PathLike | None = None,
    strict: bool = False,
    loop: bool | None = None,
    on_input: OnInput | None = None,
    stage: Stage | None = None,
    **load_options: Any,
) -> RouteResult:
    """Dead-reckon ``source`` (gyro + accel, e.g. a foot-mounted IMU; a path or a Recording) into a track written
    to ``output``: the route behind ``imutool ins`` and ``imutool batch ins``. (:func:`run_ins` is the INS itself
    over arrays.)

    Options as :class:`InsConfig` in user units: ``gyro_noise_deg`` deg/s/√Hz, ``accel_noise`` m/s²/√Hz,
    ``zupt_sigma`` m/s, ``height_sigma`` m, ``zaru_sigma_deg`` deg/s, ``heading_deg`` deg, ``align_*_s`` s;
    ``bias_states`` both bias triples. ZVIs: the 0/1 channel ``zvi_column``, else detected with ``detector``
    (``gamma`` for the Skog detectors). Also writes ``plot_path`` (top view + height, .png/.pdf) and ``strides_path``
    (:func:`write_strides`). A path is loaded with ``load_options`` (columns, profile, ... calibration_file).
    Returns the track and the summary: start-to-end distance (a closed-loop error only for a loop: ``loop`` True,
    False, or None to decide from the track, :func:`looks_like_loop`), strides, final sigmas, ``vs_reference``
    with ref_pos.
    """
    inputs: list[dict[str, Any]] = []
    csv_out = output is not None and Path(output).suffix.lower() == ".csv"
    warm = None
    if isinstance(source, Recording) or os.path.isfile(source):
        # a cold cache: a second process compiles the INS kernel while this one compiles the CSV reader (and then
        # the writer); formats.jit.warm
        warm = warm_in_background(_ins_kernel, (INS_KERNEL,))
    if stage is not None:
        stage("reading")
    rec, name, report = read_source(source, inputs, strict=strict, on_input=on_input, **load_options)
    rec = one_clock(rec, ("gyro", "accel"), inputs)  # many clocks: the IMU's own samples
    require_channels(rec, ["gyro", "accel"], name)
    for opt, v in (
        ("--gyro-noise", gyro_noise_deg),
        ("--accel-noise", accel_noise),
        ("--zupt-sigma", zupt_sigma),
        ("--height-sigma", height_sigma),
        ("--zaru-sigma", zaru_sigma_deg),
    ):
        if not np.isfinite(v) or v <= 0:
            raise ImutoolError(f"{opt} must be > 0; got {v}")
    cfg = InsConfig(
        gyro_noise=float(np.radians(gyro_noise_deg)),
        accel_noise=accel_noise,
        zupt_sigma=zupt_sigma,
        height_sigma=height_sigma,
        zaru=zaru,
        zaru_sigma=float(np.radians(zaru_sigma_deg)),
        order=int(order),
        zupt=zupt,
        height_update=height_update,
        accel_bias_states=bias_states,
        gyro_bias_states=bias_states,
        heading_deg=heading_deg,
        align_window_s=align_window_s,
        align_guard_s=align_guard_s,
    )
    flags = None
    if zvi_column:
        if zvi_column not in rec.channels:
            raise ImutoolError(f"ZVI column {zvi_column!r} not found", path=name)
        flags = rec[zvi_column] > 0.5
    params = {"gamma": gamma} if gamma is not None and detector != "paper" else {}
    if gamma is not None and detector == "paper":
        raise ImutoolError("--gamma does not apply to the paper detector (use `imutool zvi` to tune B_g, B_a)")
    if stage is not None:
        stage("INS + zero-velocity updates")
    wait_for(_ins_kernel, warm, (CSV_WRITER,) if csv_out else ())
    try:
        out, res = ins(rec, zvi=flags, detector=detector, detector_params=params, config=cfg)
    except ImutoolError as e:
        raise ImutoolError(str(e), path=name) from None
    out.meta["source"] = name
    out.meta["ins_config"] = (
        f"zupt={zupt} height_update={height_update} zaru={zaru} detector="
        f"{zvi_column or detector} order={order} gyro_noise={gyro_noise_deg}deg/s/rtHz "
        f"accel_noise={accel_noise}m/s2/rtHz zupt_sigma={zupt_sigma}m/s"
    )
    if stage is not None:
        stage("writing")
    if output is not None:
        formats.write(out, output)
    ends = evaluate_position(out, loop=loop)
    st = strides(out.time, out["pos"], out["zvi"])
    ok = np.flatnonzero(np.all(np.isfinite(out["pos"]), axis=1))
    summary: dict[str, Any] = {
        "input": name,
        "output": None if output is None else os.fspath(output),
        "samples": len(out),
        "duration_s": round(out.duration, 3),
        "aligned_from_s": round(res.info["alignment_start_s"], 3),
        "gravity_m_s2": round(res.gravity, 4),
        "distance_m": round(ends["distance_m"], 3),
        "final_position_ned_m": np.round(out["pos"][ok[-1]], 3).tolist() if len(ok) else None,
        "start_to_end_m": round(ends["start_to_end_m"], 4),
        "loop": ends["loop"],
        **_loop_entries(ends),
        "strides": {
            "count": st["count"],
            "mean_length_m": st["mean_length_m"] and round(st["mean_length_m"], 3),
            "mean_duration_s": st["mean_duration_s"] and round(st["mean_duration_s"], 3),
        },
        "final_sigma_pos_m": np.round(np.sqrt(np.maximum(res.p_diag[-1, 3:6], 0)), 4).tolist(),
        "final_sigma_heading_deg": round(float(np.degrees(np.sqrt(max(res.heading_var[-1], 0)))), 3),
    }
    if "ref_pos" in rec.channels:
        ev = evaluate_position(out, rec)
        summary["vs_reference"] = {
            k: (round(v, 4) if isinstance(v, float) else v)
            for k, v in ev.items()
            if k in ("final_error_m", "rmse_m", "rmse_sum_axes_m", "distance_error_percent")
        }
    if strides_path:
        write_strides(st["table"], strides_path)
        summary["strides_file"] = os.fspath(strides_path)
    if plot_path:
        title = f"{name.rsplit('/', 1)[-1]}: {ends['distance_m']:.1f} m walked, " + (
            f"closed-loop error {1000 * ends['final_error_m']:.0f} mm"
            if ends["loop"]
            else f"end {ends['start_to_end_m']:.2f} m from the start"
        )
        ref = rec.get("ref_pos") if "ref_pos" in rec.channels else None
        plot_track(out, os.fspath(plot_path), title=title, ref=ref)
        summary["plot"] = os.fspath(plot_path)
    if report.get("actions"):
        summary["input_fixes"] = report["actions"]
    return RouteResult(summary, inputs, out)
