"""`imutool filter INPUT -o OUTPUT`: roll/pitch/heading by quaternion EKF, compass KF or low-pass baseline."""

from __future__ import annotations

import os
from typing import Any

import click
import numpy as np

import formats
from formats.errors import ImutoolError
from imutool.cli.common import emit_summary, input_options, load_input, output_options, parse_vector, safe_outputs
from imutool.progress import bar


@click.command("filter", epilog="Example: imutool simulate ship-roll -o roll.csv && "
                                "imutool filter roll.csv -o est.csv --smooth")
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True))
@click.option("-o", "--output", required=True, type=click.Path(), help="Output file (.csv, .bag, ...).")
@click.option("--method", type=click.Choice(["ekf", "lpf", "accel", "compass"]), default="ekf", show_default=True,
              help="ekf: quaternion EKF with gyro bias; lpf: Butterworth low-passed accel tilt + magnetic heading "
                   "(paper baseline); accel: unfiltered accelerometer tilt; compass: heading Kalman filter.")
@click.option("--params", "params_file", type=click.Path(exists=True, dir_okay=False), default=None,
              help="EKF: TOML file with tuning parameters (every constant, its unit and default: "
                   "`--save-params FILE` writes the full set).")
@click.option("--param", "param_items", multiple=True, metavar="NAME=VALUE",
              help="EKF: override one tuning parameter (repeatable), e.g. --param mag_noise_deg=10.")
@click.option("--save-params", type=click.Path(dir_okay=False), default=None,
              help="EKF: write the parameters used (TOML, with units) to this file.")
@click.option("--update-every", type=int, default=None,
              help="EKF: covariance propagation + accel/mag update every N samples (paper: 40 at 200 Hz; default 1).")
@click.option("--mag-mode", type=click.Choice(["heading", "full", "off"]), default=None,
              help="EKF magnetometer use: heading only (default; never touches roll/pitch), full 3-D vector "
                   "(paper), off.")
@click.option("--smooth", is_flag=True, help="EKF: add the RTS backward pass (zero-lag offline estimates).")
@click.option("--lever-arm", default=None, metavar="X,Y,Z",
              help="EKF: sensor position relative to the vessel's centre of rotation, m, body FRD (x bow, "
                   "y starboard, z down; a bridge 20 m above the roll centre is z = -20): the tangential and "
                   "centripetal accelerations ω̇×r + ω×(ω×r) are removed before the accelerometer update.")
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
              help="EKF on CSV/Parquet: stream the file in chunks of this many rows when larger than --stream-mb.")
@click.option("--stream-mb", type=float, default=300.0, show_default=True,
              help="EKF on CSV/Parquet: stream (bounded memory) when the input is larger than this (MB).")
@input_options
@output_options
@safe_outputs("output", "save_params")
def filter_cmd(input_path: str, output: str, method: str, params_file: str | None, param_items: tuple[str, ...],
               save_params: str | None, update_every: int | None, mag_mode: str | None, smooth: bool,
               lever_arm: str | None, gnss_path: str | None, no_gnss: bool, cutoff: float, order: int,
               compass_model: str, comp_q: float, comp_r: float, variation: float, paper_init: bool,
               chunk_rows: int, stream_mb: float, as_json: bool, quiet: bool, **io: Any) -> None:
    """Estimate roll, pitch and heading (deg) from INPUT (gyro/accel/mag, or an NMEA heading for compass).

    Output columns: roll, pitch, heading (deg), qw..qz (body→NED), gyro_bias_x..z (rad/s), roll_std,
    pitch_std, heading_std (deg, one sigma), accel_rejected, mag_rejected, rest, inconsistent (0/1: the
    filter's self-check); ref_* and label columns of the input are carried over so `imutool evaluate OUTPUT`
    works directly. EKF tuning: --params FILE / --param NAME=VALUE (list and units: --save-params).
    """
    params = ekf_params(params_file, param_items, update_every, mag_mode)
    lever = parse_vector(lever_arm, 3, "--lever-arm") if lever_arm else None
    if lever is not None and not np.all(np.isfinite(lever)):
        raise ImutoolError(f"--lever-arm {lever_arm!r}: expected three finite numbers (m)")
    if save_params:
        from formats.atomic import atomic_path

        with atomic_path(save_params) as tmp:
            tmp.write_text(params.to_toml(), encoding="utf-8")
    if (method == "ekf" and not smooth and gnss_path is None and formats.kind_of(input_path) in ("csv", "parquet")
            and os.path.getsize(input_path) > stream_mb * 1e6):
        summary = _stream_ekf(input_path, output, params, chunk_rows, no_gnss, io, lever, quiet)
        _warn(summary)
        emit_summary(summary, as_json, quiet)
        return
    rec, validation = load_input(input_path, **io)
    summary: dict[str, Any] = {"input": input_path, "output": output, "rows": len(rec)}
    if method == "ekf":
        from imutool.attitude import ekf_recording

        if gnss_path and not no_gnss:
            rec = _attach_gnss(rec, gnss_path)
        with bar("filter", total=len(rec), unit="samples", quiet=quiet) as b:
            out, s = ekf_recording(rec, params, smooth=smooth, use_gnss=not no_gnss, lever_arm=lever, progress=b)
        if smooth and ("ref_q" in rec.channels or "ref_roll" in rec.channels):
            from imutool.metrics import attitude_rmse

            causal, _ = ekf_recording(rec, params, use_gnss=not no_gnss, lever_arm=lever)
            s["smoother_gain"] = {"causal_rmse_deg": attitude_rmse(causal, rec),
                                  "smoothed_rmse_deg": attitude_rmse(out, rec)}
        if params_file:
            out.meta["filter_params_file"] = params_file
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
    _warn(summary)
    formats.write(out, output)
    emit_summary(summary, as_json, quiet)


def ekf_params(params_file: str | None, items: tuple[str, ...], update_every: int | None,
               mag_mode: str | None) -> Any:
    """EkfParams from the defaults, then --params FILE, then --param NAME=VALUE, then the everyday flags."""
    from imutool.attitude import PARAM_DOC, EkfParams

    values: dict[str, Any] = {}
    if params_file:
        values.update(vars(EkfParams.from_toml(params_file)))
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip().replace("-", "_")
        if not sep or name not in PARAM_DOC:
            raise ImutoolError(f"--param {item!r}: expected NAME=VALUE with NAME one of {', '.join(PARAM_DOC)}")
        values[name] = _param_value(name, text.strip(), getattr(EkfParams(), name))
    if update_every is not None:
        values["update_every"] = update_every
    if mag_mode is not None:
        values["mag_mode"] = mag_mode
    return EkfParams.from_dict(values, source="--params/--param")


def _param_value(name: str, text: str, default: Any) -> Any:
    try:
        if isinstance(default, bool):
            if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError
            return text.lower() in ("true", "1", "yes")
        if isinstance(default, tuple):
            return tuple(float(x) for x in text.split(","))
        if isinstance(default, int):
            return int(text)
        if isinstance(default, float):
            return float(text)
        return text
    except ValueError:
        raise ImutoolError(f"--param {name}={text!r}: expected a value like {default!r}") from None


def _warn(summary: dict[str, Any]) -> None:
    for w in summary.get("warnings") or []:
        click.echo(f"warning: {w}", err=True)


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


def _stream_ekf(path: str, output: str, params, chunk_rows: int, no_gnss: bool, io: dict, lever=None,
                quiet: bool = True) -> dict[str, Any]:
    """Bounded-memory EKF over a large CSV/Parquet: chunks streamed, state carried, rows appended to the output."""
    from formats.csv import CsvWriter
    from imutool.attitude import F_INCONSISTENT, nominal_dt, result_recording, run_ekf, self_check
    from imutool.convert import chunk_writer
    from imutool.progress import estimate_rows

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
    opts = ({"columns": io.get("columns"), "profile": io.get("profile"), "prefetch": True}
            if formats.kind_of(path) == "csv" else {})
    flagged_t: list[np.ndarray] = []  # times of samples the self-check flagged (to report spans)
    total = estimate_rows(path) if formats.kind_of(path) == "csv" else None
    # a .csv output is written by a background writer thread; a .parquet output row group by row group
    writer = (CsvWriter(output, background=True) if formats.kind_of(output, for_output=True) == "csv"
              else chunk_writer(output))
    with writer as w, bar("filter", total=total, unit="rows", quiet=quiet) as b:
        for chunk in formats.iter_chunks(path, chunk_rows=chunk_rows, **opts):
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
                                 sog, cog, state=state, dt_nominal=dt_nom, lever_arm=lever)
            bad = (res.flags & F_INCONSISTENT) > 0
            if bad.any():
                flagged_t.append(res.time[bad])
            for k, v in res.summary.items():
                if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
                    totals[k] = int(v)  # the state carries cumulative counters
            est = result_recording(chunk, res, params)
            if lever is not None:
                est.meta["lever_arm_m"] = [float(x) for x in lever]
            w.write(est)
            t_last = float(chunk.time[-1])
            summary["rows"] += len(chunk)
            b(summary["rows"], total)
            if chunk.meta.get("skipped_rows"):  # running total of malformed rows skipped by the reader
                summary["skipped_rows"] = chunk.meta["skipped_rows"]
                summary["skipped_rows_first"] = chunk.meta.get("skipped_rows_first")
    summary.update(totals)
    summary["samples"] = summary["rows"]
    if flagged_t:  # spans from the flagged times: a gap longer than 1 s between flagged samples splits a span
        tf = np.concatenate(flagged_t)
        flags = np.full(len(tf), F_INCONSISTENT, np.uint8)
        split = np.flatnonzero(np.diff(tf) > 1.0)
        times = np.insert(tf, split + 1, np.nan)
        flags = np.insert(flags, split + 1, 0)
        check, warnings = self_check(times, flags, n_total=summary["rows"])
        summary.update(check)
        summary["warnings"] = warnings
    if lever is not None:
        summary["lever_arm_m"] = [float(x) for x in lever]
    return summary
