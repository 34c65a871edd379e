"""The EKF over a Recording: :func:`ekf_recording` and the output channels (degrees at the surface)."""

from __future__ import annotations

import numpy as np

from formats import Recording
from formats.csv import DECIMALS_KEY
from formats.errors import ImutoolError
from formats.frames import quat_conjugate, quat_multiply
from formats.saturation import clipped
from imutool.attitude.aided import aided_result, velocity_is_fixes
from imutool.attitude.layout import F_ACC_REJ
from imutool.attitude.lever_estimate import LeverArmEstimate, analysis_span, estimate_lever_arm
from imutool.attitude.motion import MotionChoice, choose_motion, params_for_motion
from imutool.attitude.params import EkfParams
from imutool.attitude.run import AttitudeResult, nominal_dt, run_ekf
from imutool.attitude.selfcheck import SampleFlag, SelfCheck, has_flag
from imutool.attitude.smoother import zero_lag_smooth
from imutool.loading import merged_warnings
from imutool.progress import Progress

LOG_SPEED = "log_speed"  # the channel of a speed through the water without a course (m/s): filter --speed
SMOOTHER_BYTES_PER_SAMPLE = 1500  # measured: 1.42 kB/sample at peak (1 M samples, three N×6×6 arrays + outputs)


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux MemAvailable; None where unknown)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def check_smoother_memory(n: int) -> None:
    """Refuse (ImutoolError) a smoother run that cannot fit in the memory available, before allocating any of it."""
    need, have = n * SMOOTHER_BYTES_PER_SAMPLE, available_memory()
    if have is not None and need > have:

        def size(b: float) -> str:
            return f"{b / 1e9:.1f} GB" if b >= 1e9 else f"{b / 1e6:.1f} MB"

        raise ImutoolError(
            f"the smoother keeps every sample's covariance: {n} samples need about {size(need)} "
            f"and {size(have)} is available; smooth a shorter span or filter without --smooth"
        )


def heading_channel(rec: Recording) -> np.ndarray | None:
    """The external true heading (deg) of a recording, ``heading_true`` (gyrocompass HDT/THS), or None."""
    if "heading_true" not in rec.channels:
        return None
    return np.asarray(rec.in_unit("heading_true", "deg"), float)


def _read_later(t: np.ndarray, h: np.ndarray, latency_s: float) -> np.ndarray:
    """A heading column ``h`` (deg at times ``t`` s) read ``latency_s`` (s) later: the value at t is the column's
    at t + latency (the fix describes the heading latency_s before its stamp), unwrapped and linear between
    samples, NaN where either neighbour is NaN or past the end; ``h`` itself when the latency is 0."""
    if latency_s <= 0:
        return h
    ok = np.isfinite(h) & np.isfinite(t)
    if ok.sum() < 2:
        return np.full_like(h, np.nan)
    later = t + latency_s
    val = np.degrees(np.interp(later, t[ok], np.unwrap(np.radians(h[ok])), left=np.nan, right=np.nan)) % 360
    both = np.interp(later, t, ok.astype(float), left=0.0, right=0.0) >= 1.0 - 1e-12  # both neighbours valid
    return np.where(both, val, np.nan)


def gnss_inputs(rec: Recording, use_gnss: bool = True) -> tuple[np.ndarray | None, ...]:
    """(sog m/s, cog deg, velocity (N,2) m/s north/east) of a recording, each None where it has none.

    The velocity is ``vel_n``/``vel_e`` when present, else sog·(cos cog, sin cog); the EKF's velocity aiding
    uses it (:func:`imutool.attitude.run.run_ekf`), the turn's compensation sog/cog. Without either, a
    ``log_speed`` channel (the ship's log, ``filter --speed``) is the sog, with no course and no velocity."""
    if not use_gnss:
        return None, None, None
    sog = rec.in_unit("sog", "m/s") if "sog" in rec.channels and "cog" in rec.channels else None
    cog = rec.in_unit("cog", "deg") if sog is not None else None
    if "vel_n" in rec.channels and "vel_e" in rec.channels:
        vel = np.stack([rec.in_unit("vel_n", "m/s"), rec.in_unit("vel_e", "m/s")], axis=1)
        if sog is None:  # the speed and course of the same velocity (the turn's term where no heading is held)
            sog = np.hypot(vel[:, 0], vel[:, 1])
            cog = np.degrees(np.arctan2(vel[:, 1], vel[:, 0])) % 360.0
    elif sog is not None:
        c = np.radians(np.asarray(cog, dtype=np.float64))
        vel = np.stack([sog * np.cos(c), sog * np.sin(c)], axis=1)
    elif LOG_SPEED in rec.channels:  # a speed without a course: along the bow, the turn's term only
        return rec.in_unit(LOG_SPEED, "m/s"), None, None
    else:
        vel = None
    return sog, cog, vel


def drop_clipped(
    gyro: np.ndarray, accel: np.ndarray, checks: SelfCheck, time: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(accel with its clipped samples NaN, the clipped rows): a sample at the accelerometer's range limit is not
    gravity plus the motion, so the filter does not use it; both channels' clipping goes to ``checks``
    (:mod:`formats.saturation`)."""
    clip_a, clip_g = clipped(accel, "accel"), clipped(gyro, "gyro")
    checks.add_clipping(time, clip_a, clip_g)
    return _nan_where(accel, clip_a.mask), clip_a.mask


def clipped_nan(accel: np.ndarray) -> np.ndarray:
    """``accel`` (N,3) m/s² as the filter takes it: NaN at its clipped samples (:func:`drop_clipped`, unreported)."""
    return _nan_where(accel, clipped(accel, "accel").mask)


def _nan_where(accel: np.ndarray, mask: np.ndarray) -> np.ndarray:
    if not mask.any():
        return accel
    accel = np.array(accel, dtype=np.float64)
    accel[mask] = np.nan
    return accel


def ship_lever_arm(
    params: EkfParams,
    motion: MotionChoice,
    lever_arm: np.ndarray | None,
    time: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    mag: np.ndarray | None,
    run_params: EkfParams,
    sog: np.ndarray | None,
    cog: np.ndarray | None,
    vel: np.ndarray | None,
    heading: np.ndarray | None,
    antenna_arm: np.ndarray | None,
) -> tuple[np.ndarray | None, LeverArmEstimate | None]:
    """(the lever arm the filter runs with, the estimate or None): ``lever_arm`` when given; on ship motion
    without one (and ``params.lever_arm_estimate``) the one :func:`estimate_lever_arm` finds on the first rows of
    the inputs (the filter's own inputs: SI, body FRD; ``accel`` with clipped samples NaN), the filter run once on
    them with no arm and ``run_params`` as the whole run is. An in-memory run and a stream pass the same rows."""
    if lever_arm is not None or motion.kind != "ship" or not params.lever_arm_estimate or len(time) == 0:
        return lever_arm, None
    span = analysis_span(time)

    def cut(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.asarray(a)[span]

    def run(arm: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        res, _ = run_ekf(
            time[span], gyro[span], accel[span], cut(mag), run_params, cut(sog), cut(cog),
            lever_arm=arm, heading_deg=cut(heading), velocity_ne=cut(vel), antenna_arm=antenna_arm,
        )  # fmt: skip
        return res.q, res.bias

    est = estimate_lever_arm(time[span], gyro[span], accel[span], run)
    return est.arm_m, est


def flag_clipped(res: AttitudeResult, rows: np.ndarray) -> None:
    """The clipped accelerometer rows are flagged as rejected (the output's accel_rejected = 1)."""
    if rows.any():
        res.flags[rows] |= F_ACC_REJ


def ekf_recording(
    rec: Recording,
    params: EkfParams | None = None,
    smooth: bool = False,
    use_gnss: bool = True,
    lever_arm: np.ndarray | None = None,
    progress: Progress | None = None,
    antenna_arm: np.ndarray | None = None,
) -> tuple[Recording, dict]:
    """Run the EKF (and optionally the smoother) on a recording; returns (estimate recording, summary).

    Needs ``gyro`` and ``accel``; uses ``mag`` when present, ``sog``/``cog`` when present and use_gnss.
    Output channels: roll, pitch, heading (deg), q, gyro_bias (rad/s), roll_std/pitch_std/heading_std (deg),
    accel_rejected, mag_rejected, rest (0/1); ``ref_*`` and label channels of the input are carried over.
    """
    params = params or EkfParams()
    for ch in ("gyro", "accel"):
        if ch not in rec.channels:
            raise ImutoolError(f"the EKF needs channel {ch!r}; the recording has {', '.join(rec.channels)}")
    gyro = rec.in_unit("gyro", "rad/s")
    accel = rec.in_unit("accel", "m/s^2")
    mag = rec["mag"] if "mag" in rec.channels else None
    heading_raw = heading_channel(rec)  # deg, as it came
    heading = None if heading_raw is None else _read_later(rec.time, heading_raw, params.heading_input_latency)
    sog, cog, vel = gnss_inputs(rec, use_gnss)
    if smooth:
        check_smoother_memory(len(rec))
    motion = choose_motion(params, rec.time, gyro)
    run_params = params_for_motion(params, motion)  # the low-pass of the platform's motion
    checks = SelfCheck(run_params, nominal_dt(rec.time), lever_arm)  # the same accumulator as a streamed run's
    checks.motion = motion.kind
    accel, clipped_rows = drop_clipped(gyro, accel, checks, rec.time)
    lever_arm, lever_est = ship_lever_arm(
        params, motion, lever_arm, rec.time, gyro, accel, mag, run_params, sog, cog, vel, heading, antenna_arm
    )
    checks.lever_arm = lever_arm
    res, _ = run_ekf(
        rec.time,
        gyro,
        accel,
        mag,
        run_params,
        sog,
        cog,
        keep_cov=smooth,
        lever_arm=lever_arm,
        progress=progress,
        keep_force=True,
        heading_deg=heading,
        velocity_ne=vel,
        antenna_arm=antenna_arm,
    )
    flag_clipped(res, clipped_rows)
    summary = dict(res.summary)
    checks.add(
        res,
        gyro,
        mag_given=mag is not None,
        gnss_used=vel is not None,
        heading_deg=heading_raw,
        speed_used=sog is not None and vel is None,
    )
    report = checks.report()
    summary.update(report.summary)
    warnings = report.warnings
    aided = None
    # roll and pitch from the velocity-aided filter, where the EKF aided with the velocity (a heading held: the
    # aided filter takes the EKF's heading); not on an estimated lever arm (a metre off at 0.2 rad/s is 0.2 m/s
    # in the sensor's velocity)
    aid = vel is not None and params.aided and not smooth and lever_est is None
    if aid and res.summary.get("velocity_aiding") and velocity_is_fixes(vel):
        res, aided, _ = aided_result(
            rec.time, gyro, accel, vel, res, run_params, lever_arm, antenna_arm, nominal_dt(rec.time),
            smooth=params.aided_smoother,
        )  # fmt: skip
        summary["aided"] = aided.summary
        if "note" in aided.summary:  # the gyro's bias instability widened after a divergence
            warnings = [*warnings, aided.summary["note"]]
    if lever_est is not None:
        summary["lever_arm_estimate"] = lever_est.summary()
        warnings = [m for m in (lever_est.message(),) if m] + warnings
    if smooth:
        res = zero_lag_smooth(res, gyro, accel, mag, run_params, sog, cog, lever_arm, heading_deg=heading)
    out = result_recording(rec, res, params)
    if aided is not None:
        add_aided_channels(out, aided)
        out.meta["aided"] = aided.summary
    out.meta["motion"] = summary["motion"] = motion.summary()
    out.meta.update(report.metadata)
    if lever_est is not None:
        out.meta["lever_arm_estimate"] = lever_est.summary()
    if warnings:
        out.meta["warnings"] = merged_warnings(out.meta, warnings)
        summary["warnings"] = list(summary.get("warnings") or []) + warnings
    summary["method"] = "ekf" + ("+zero-lag smoother" if smooth else "")
    return out, summary


def result_recording(rec: Recording, res: AttitudeResult, params: EkfParams | None = None) -> Recording:
    """Estimate channels (degrees at the surface) plus the input's ref_* and label channels."""
    out = Recording(res.time.copy(), meta=dict(rec.meta))
    r, p, h = res.euler_deg()
    h[h >= 360.0 - 0.5 * 10.0 ** -OUTPUT_DECIMALS["heading"]] = 0.0  # within the printed resolution of 360: 0
    out.add("roll", r)
    out.add("pitch", p)
    out.add("heading", h)
    out.add("q", res.q)
    out.add("gyro_bias", res.bias)
    sd = np.degrees(res.std)
    out.add("roll_std", sd[:, 0], "deg")
    out.add("pitch_std", sd[:, 1], "deg")
    out.add("heading_std", sd[:, 2], "deg")
    out.add("accel_rejected", has_flag(res.flags, SampleFlag.ACCEL_REJECTED).astype(float), "1")
    out.add("mag_rejected", has_flag(res.flags, SampleFlag.MAG_REJECTED).astype(float), "1")
    out.add("rest", has_flag(res.flags, SampleFlag.REST).astype(float), "1")
    out.add("inconsistent", has_flag(res.flags, SampleFlag.INCONSISTENT).astype(float), "1")
    out.add("heading_inconsistent", has_flag(res.flags, SampleFlag.HEADING_INCONSISTENT).astype(float), "1")
    carry_labels(rec, out)
    out.meta[DECIMALS_KEY] = dict(OUTPUT_DECIMALS)
    if params is not None:
        out.meta["filter"] = params.as_dict()
    return out


# Printed resolution of the estimate columns in CSV outputs (stated in the file header): 1e-6° for angles and
# their σ, 1e-9 for quaternion components (≈ 1e-7°) and bias (rad/s ≈ 2e-4 °/h) — far below any sensor's noise,
# and ~40 % fewer bytes and much faster to write than 17 significant digits. Time stays exact.
OUTPUT_DECIMALS = {
    "roll": 6,
    "pitch": 6,
    "heading": 6,
    "q": 9,
    "gyro_bias": 9,
    "roll_std": 6,
    "pitch_std": 6,
    "heading_std": 6,
    "accel_rejected": 0,
    "mag_rejected": 0,
    "rest": 0,
    "inconsistent": 0,
    "heading_inconsistent": 0,
}


LABEL_CHANNELS = ("movement", "zvi")


def add_aided_channels(out: Recording, aided) -> None:
    """The aided filter's accelerometer bias and its σ (m/s², body FRD) as output channels."""
    out.add("accel_bias", aided.accel_bias, "m/s^2")
    out.add("accel_bias_std", aided.accel_bias_std, "m/s^2")
    out.meta[DECIMALS_KEY] = {**out.meta[DECIMALS_KEY], "accel_bias": 7, "accel_bias_std": 7}


def carry_labels(src: Recording, dst: Recording) -> None:
    """Copy truth (``ref_*``) and label channels (movement, sog, cog...) from the input to an estimate."""
    for name, arr in src.channels.items():
        if name.startswith("ref_") or name in LABEL_CHANNELS or name in ("sog", "cog"):
            if name not in dst.channels:
                dst.add(name, arr, src.units.get(name), src.columns.get(name))


def quat_error_metrics(q_est: np.ndarray, q_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """BROAD error angles (rad) per sample: d = q_est ⊗ q_ref* (world frame); total = 2·acos|d_w|,
    heading = 2·atan|d_z/d_w|, inclination = 2·acos√(d_w² + d_z²)."""
    d = quat_multiply(q_est, quat_conjugate(q_ref))
    dw, dz = np.abs(d[..., 0]), d[..., 3]
    total = 2 * np.arccos(np.clip(dw, 0, 1))
    heading = 2 * np.arctan(np.abs(dz) / np.maximum(dw, 1e-12))
    incl = 2 * np.arccos(np.clip(np.sqrt(d[..., 0] ** 2 + dz**2), 0, 1))
    return total, heading, incl
