"""`imutool filter INPUT -o OUTPUT`: roll/pitch/heading by quaternion EKF, compass KF or low-pass baseline."""

from __future__ import annotations

import os
from typing import Any

import click
import numpy as np

import formats
from formats.errors import ImutoolError
from imutool.cli.common import emit_summary, input_options, load_input, output_options


@click.command("filter", epilog="Example: imutool simulate ship-roll -o roll.csv && "
                                "imutool filter roll.csv -o est.csv --smooth")
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True))
@click.option("-o", "--output", required=True, type=click.Path(), help="Output file (.csv, .bag, ...).")
@click.option("--method", type=click.Choice(["ekf", "lpf", "accel", "compass"]), default="ekf", show_default=True,
              help="ekf: quaternion EKF with gyro bias; lpf: Butterworth low-passed accel tilt + magnetic heading "
                   "(paper baseline); accel: unfiltered accelerometer tilt; compass: heading Kalman filter.")
@click.option("--update-every", type=int, default=1, show_default=True,
              help="EKF: covariance propagation + accel/mag update every N samples (paper: 40 at 200 Hz).")
@click.option("--mag-mode", type=click.Choice(["heading", "full", "off"]), default="heading", show_default=True,
              help="EKF magnetometer use: heading only (never touches roll/pitch), full 3-D vector (paper), off.")
@click.option("--smooth", is_flag=True, help="EKF: add the RTS backward pass (zero-lag offline estimates).")
@click.option("--gyro-noise", type=float, default=1e-3, show_default=True, help="EKF: gyro noise density, rad/s/√Hz.")
@click.option("--gyro-scale-noise", type=float, default=0.0, show_default=True,
              help="EKF: rate-proportional gyro noise (scale-factor uncertainty, fraction).")
@click.option("--bias-rw", type=float, default=2e-5, show_default=True, help="EKF: gyro bias random walk, rad/s/√s.")
@click.option("--accel-noise", type=float, default=0.03, show_default=True,
              help="EKF: σ floor of the normalised accelerometer direction per update (≈ rad).")
@click.option("--accel-noise-gain", type=float, default=4.0, show_default=True,
              help="EKF: accel σ² = floor² + (gain × the accelerometer's white-noise σ/g learned online)² "
                   "(0 = fixed σ).")
@click.option("--accel-lp-tau", type=float, default=1.0, show_default=True,
              help="EKF: time constant (s) of the accel low-pass in the gyro-integrated quasi-inertial frame "
                   "(0 = raw accel as in the paper).")
@click.option("--gyro-integration", type=click.Choice(["rectangular", "trapezoid"]), default="rectangular",
              show_default=True, help="EKF: rate over a step: ω_k (rectangular) or ½(ω_{k−1}+ω_k) (trapezoid).")
@click.option("--mag-noise", type=float, default=45.0, show_default=True, help="EKF: σ of magnetic heading, deg.")
@click.option("--accel-gate", type=float, default=15.0, show_default=True,
              help="EKF: skip accel sample (shock) when | |a| − g | exceeds this (m/s², 0 = off).")
@click.option("--accel-nis-gate", type=float, default=0.0, show_default=True,
              help="EKF: skip accel update when its NIS exceeds this (0 = off).")
@click.option("--accel-nis-soft", is_flag=True,
              help="EKF: above --accel-nis-gate inflate R by NIS/gate instead of skipping the update.")
@click.option("--accel-adapt", type=float, default=0.0, show_default=True,
              help="EKF: scale accel σ by √(1 + (| |a| − g | / this)²) (m/s², 0 = off).")
@click.option("--mag-norm-gate", type=float, default=0.15, show_default=True,
              help="EKF: skip mag update when |m|/m_ref departs from 1 by more (fraction, 0 = off).")
@click.option("--mag-dip-gate", type=float, default=10.0, show_default=True,
              help="EKF: skip mag update when the dip departs by more (deg, 0 = off).")
@click.option("--rest-time", type=float, default=1.0, show_default=True,
              help="EKF: rest after this long below --rest-gyro/--rest-accel (s, 0 = no rest detection).")
@click.option("--rest-gyro", type=float, default=0.05, show_default=True, help="EKF: rest rate threshold, rad/s.")
@click.option("--rest-accel", type=float, default=0.3, show_default=True,
              help="EKF: rest | |a| − g | threshold, m/s².")
@click.option("--gap-factor", type=float, default=5.0, show_default=True,
              help="EKF: a time step longer than this × median dt is a gap.")
@click.option("--gnss", "gnss_path", type=click.Path(exists=True, dir_okay=False), default=None,
              help="EKF: NMEA or CSV file with sog (m/s) and cog (deg) for centripetal compensation "
                   "(sog/cog columns of INPUT are used automatically).")
@click.option("--no-gnss", is_flag=True, help="EKF: ignore sog/cog even when present.")
@click.option("--cutoff", type=float, default=0.5, show_default=True, help="lpf: cutoff frequency, Hz.")
@click.option("--order", type=int, default=2, show_default=True, help="lpf: Butterworth order.")
@click.option("--compass-model", type=click.Choice(["auto", "scalar", "gyro"]), default="auto", show_default=True,
              help="compass: scalar KF (paper) or two-state with the gyro rate of turn (auto: gyro if present).")
@click.option("--q", "comp_q", type=float, default=0.003, show_default=True, help="compass: Q, deg² per sample.")
@click.option("--r", "comp_r", type=float, default=2.0, show_default=True, help="compass: R, deg².")
@click.option("--variation", type=float, default=0.0, show_default=True,
              help="compass: magnetic variation, deg east positive (true = magnetic + variation).")
@click.option("--paper-init", is_flag=True, help="compass: x0 = 0, P0 = 0 as in the paper.")
@click.option("--chunk-rows", type=int, default=1_000_000, show_default=True,
              help="EKF on CSV: stream the file in chunks of this many rows when it is larger than --stream-mb.")
@click.option("--stream-mb", type=float, default=300.0, show_default=True,
              help="EKF on CSV: stream (bounded memory) when the input is larger than this (MB).")
@input_options
@output_options
def filter_cmd(input_path: str, output: str, method: str, update_every: int, mag_mode: str, smooth: bool,
               gyro_noise: float, gyro_scale_noise: float, bias_rw: float, accel_noise: float,
               accel_noise_gain: float, accel_lp_tau: float, gyro_integration: str, mag_noise: float,
               accel_gate: float, accel_nis_gate: float, accel_nis_soft: bool, accel_adapt: float,
               mag_norm_gate: float, mag_dip_gate: float,
               rest_time: float, rest_gyro: float, rest_accel: float, gap_factor: float, gnss_path: str | None,
               no_gnss: bool, cutoff: float, order: int, compass_model: str, comp_q: float, comp_r: float,
               variation: float, paper_init: bool, chunk_rows: int, stream_mb: float, as_json: bool, quiet: bool,
               **io: Any) -> None:
    """Estimate roll, pitch and heading (deg) from INPUT (gyro/accel/mag, or an NMEA heading for compass).

    Output columns: roll, pitch, heading (deg), qw..qz (body→NED), gyro_bias_x..z (rad/s), roll_std,
    pitch_std, heading_std (deg, one sigma), accel_rejected, mag_rejected, rest (0/1); ref_* and label
    columns of the input are carried over so `imutool evaluate OUTPUT` works directly.
    """
    from imutool.attitude import EkfParams

    if update_every < 1:
        raise ImutoolError("--update-every must be ≥ 1")
    params = EkfParams(gyro_noise=gyro_noise, gyro_scale_noise=gyro_scale_noise, bias_rw=bias_rw,
                       accel_noise=accel_noise, accel_noise_gain=accel_noise_gain, accel_lp_tau=accel_lp_tau,
                       gyro_integration=gyro_integration, mag_noise_deg=mag_noise, accel_gate=accel_gate,
                       accel_nis_gate=accel_nis_gate, accel_nis_soft=accel_nis_soft, accel_adapt=accel_adapt,
                       mag_norm_gate=mag_norm_gate, mag_dip_gate_deg=mag_dip_gate,
                       rest_time=rest_time, rest_gyro=rest_gyro, rest_accel=rest_accel, gap_factor=gap_factor,
                       update_every=update_every, mag_mode=mag_mode)
    if (method == "ekf" and not smooth and gnss_path is None and formats.kind_of(input_path) == "csv"
            and os.path.getsize(input_path) > stream_mb * 1e6):
        summary = _stream_ekf(input_path, output, params, chunk_rows, no_gnss, io)
        emit_summary(summary, as_json, quiet)
        return
    rec, validation = load_input(input_path, **io)
    summary: dict[str, Any] = {"input": input_path, "output": output, "rows": len(rec)}
    if method == "ekf":
        from imutool.attitude import ekf_recording

        if gnss_path and not no_gnss:
            rec = _attach_gnss(rec, gnss_path)
        out, s = ekf_recording(rec, params, smooth=smooth, use_gnss=not no_gnss)
        if smooth:
            s["smoother_gain"] = _smoother_gain(rec, params)
    elif method in ("lpf", "accel"):
        from imutool.baseline import lpf_attitude

        out, s = lpf_attitude(rec, cutoff if method == "lpf" else None, order)
    else:
        from imutool.compass import CompassParams, compass_recording

        dev = None
        if io.get("calibration_file"):
            from calibration import load_calibration

            dev = load_calibration(io["calibration_file"]).deviation
        out, s = compass_recording(rec, CompassParams(q=comp_q, r=comp_r, model=compass_model,
                                                      variation_deg=variation, paper_init=paper_init), dev)
    summary.update(s)
    if validation.get("rows_with_nan"):
        summary["input_rows_with_nan"] = validation["rows_with_nan"]
    formats.write(out, output)
    emit_summary(summary, as_json, quiet)


def _smoother_gain(rec, params) -> dict[str, Any] | None:
    """When the input carries truth (ref_roll...), RMSE of the causal filter vs the smoother."""
    if "ref_q" not in rec.channels and "ref_roll" not in rec.channels:
        return None
    from imutool.attitude import ekf_recording
    from imutool.metrics import attitude_rmse

    causal, _ = ekf_recording(rec, params, smooth=False)
    smooth, _ = ekf_recording(rec, params, smooth=True)
    return {"causal_rmse_deg": attitude_rmse(causal, rec), "smoothed_rmse_deg": attitude_rmse(smooth, rec)}


def _attach_gnss(rec, path: str):
    g = formats.read(path)
    if "sog" not in g.channels or "cog" not in g.channels:
        raise ImutoolError(f"no sog/cog channels (have {', '.join(g.channels)}); need RMC/VTG or CSV columns "
                           "sog (m/s), cog (deg)", path=path)
    sog = g.get("sog", "m/s") if "sog" in g.units else g["sog"]
    cog = np.unwrap(np.radians(np.asarray(g.get("cog", "deg") if "cog" in g.units else g["cog"], float)))
    ok = np.isfinite(sog) & np.isfinite(cog)
    if ok.sum() < 2:
        raise ImutoolError("fewer than two valid sog/cog fixes", path=path)
    out = rec.copy()
    out.add("sog", np.interp(rec.time, g.time[ok], sog[ok], left=np.nan, right=np.nan), "m/s")
    out.add("cog", np.degrees(np.interp(rec.time, g.time[ok], cog[ok], left=np.nan, right=np.nan)) % 360, "deg")
    return out


def _stream_ekf(path: str, output: str, params, chunk_rows: int, no_gnss: bool, io: dict) -> dict[str, Any]:
    """Bounded-memory EKF over a large CSV: chunks from iter_csv, state carried, rows appended to the output."""
    from formats.csv import CsvWriter, iter_csv
    from imutool.attitude import nominal_dt, result_recording, run_ekf

    cal = mounting = None  # read once, applied to every chunk
    if io.get("calibration_file"):
        from calibration import load_calibration

        cal = load_calibration(io["calibration_file"])
    if io.get("mounting"):
        mounting = formats.parse_mounting(io["mounting"])
    state = None
    dt_nom = None
    t_last = -np.inf
    summary: dict[str, Any] = {"input": path, "output": output, "rows": 0, "method": "ekf (streamed)",
                               "dropped_non_increasing_rows": 0}
    totals: dict[str, int] = {}
    # three stages overlap: the next chunk is parsed and the previous one formatted/written in background threads
    # while the EKF runs on this one (the compiled kernels release the GIL)
    with CsvWriter(output, background=True) as w:
        for chunk in iter_csv(path, chunk_rows=chunk_rows, columns=io.get("columns"), profile=io.get("profile"),
                              prefetch=True):
            keep = chunk.time > np.maximum.accumulate(np.concatenate([[t_last], chunk.time[:-1]]))
            if not keep.all():
                summary["dropped_non_increasing_rows"] += int((~keep).sum())
                chunk = chunk.select(keep)
            if len(chunk) == 0:
                continue
            if cal is not None:
                chunk = cal.apply(chunk)
            if mounting is not None:
                chunk = chunk.mounted(*mounting)
            for ch in ("gyro", "accel"):
                if ch not in chunk.channels:
                    raise ImutoolError(f"the EKF needs channel {ch!r}", path=path)
            if dt_nom is None:
                dt_nom = nominal_dt(chunk.time)
            sog = cog = None
            if not no_gnss and "sog" in chunk.channels and "cog" in chunk.channels:
                sog, cog = chunk["sog"], chunk["cog"]
            res, state = run_ekf(chunk.time, chunk["gyro"], chunk["accel"], chunk.channels.get("mag"), params,
                                 sog, cog, state=state, dt_nominal=dt_nom)
            for k, v in res.summary.items():
                if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
                    totals[k] = int(v)  # the state carries cumulative counters
            w.write(result_recording(chunk, res, params))
            t_last = float(chunk.time[-1])
            summary["rows"] += len(chunk)
            if chunk.meta.get("skipped_rows"):  # running total of malformed rows skipped by the reader
                summary["skipped_rows"] = chunk.meta["skipped_rows"]
                summary["skipped_rows_first"] = chunk.meta.get("skipped_rows_first")
    summary.update(totals)
    summary["samples"] = summary["rows"]
    return summary
