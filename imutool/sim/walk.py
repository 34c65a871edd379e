"""Scenario ``walk``: a foot-mounted IMU taking steps with stance (zero-velocity) phases.

The foot rests (``initial_rest_s``), then repeats: swing (``swing_s``) and stance (``stance_s``, foot flat and
still). During swing number i (normalised time τ ∈ [0, 1]):

- horizontal: along the chord heading χ_i = ψ_i + turn/2, distance L·(τ − sin 2πτ / 2π) (L = step length);
- vertical (NED down): d = −h·(1 − cos 2πτ)²/4 (foot clearance h at mid-swing);
- heading ψ = ψ_i + turn·(τ − sin 2πτ / 2π); roll 0;
- pitch θ = −A·sin(2πτ)·w(τ): toe-down after heel-off, toe-up before heel-strike, where
  w(τ) = (1 − e^{−(τ/τ_r)²})(1 − e^{−((1−τ)/τ_r)²}) gives the quick but smooth (C²) onset of a real heel-off
  (τ_r = onset_s / swing_s).

Velocity, acceleration and Euler rates are central differences of these closed forms (h = 20 µs: errors
≪ the sensor noise). The sensor may be tilted on the foot (``tilt_deg`` roll,pitch): q_sensor = q_foot ⊗ q_mount.
Truth: ref_pos (pos_n/e/d, m, origin at the start), ref_vel (m/s NED), ref_zvi (1 in rest/stance), ref_q and
the columns of :func:`imutool.sim.sensor.imu_recording`. ``geometry="paper"`` reproduces the INS paper's test:
3 steps over 2 m at 100 Hz.
"""

from __future__ import annotations

import numpy as np

from formats import Recording
from formats.errors import ImutoolError
from formats.frames import euler_to_quat, quat_multiply, quat_to_matrix
from imutool.sim.sensor import SensorErrors, body_rates_from_euler, imu_recording, sample_times

_H = 2e-5  # s, step of the central differences


def foot_sensors(rng: np.random.Generator, kind: str = "mems") -> tuple[SensorErrors | None, SensorErrors | None]:
    """Gyro and accelerometer error models for a foot IMU (wide ranges: a foot turns at up to ~800 deg/s).

    ``mems``: consumer MEMS (0.01 deg/s/√Hz, constant bias N(0, 0.2 deg/s), 150 µg/√Hz, bias N(0, 0.02 m/s²));
    ``ideal``: no errors.
    """
    if kind == "ideal":
        return SensorErrors(), SensorErrors()
    if kind != "mems":
        raise ImutoolError(f"walk: unknown sensor {kind!r} (mems, ideal)")
    g = 9.80665
    gyro = SensorErrors(
        noise_density=np.radians(0.01),
        bias=rng.normal(0.0, np.radians(0.2), 3),
        bias_rw=np.radians(0.002),
        quantum=np.radians(2000.0 / 32768),
        full_range=np.radians(2000.0),
    )
    accel = SensorErrors(
        noise_density=150e-6 * g, bias=rng.normal(0.0, 0.02, 3), quantum=16 * g / 32768, full_range=16 * g
    )
    return gyro, accel


def _profiles(
    t: np.ndarray,
    starts: np.ndarray,
    origins: np.ndarray,
    headings: np.ndarray,
    swing_s: float,
    step_length: float,
    turn: float,
    height: float,
    pitch_amp: float,
    tau_r: float,
) -> np.ndarray:
    """Foot pose at times t: columns n, e, d (m), roll, pitch, heading (rad)."""
    k = np.searchsorted(starts, t, side="right") - 1  # the last swing started at or before t
    out = np.zeros((len(t), 6))
    before = k < 0
    kk = np.clip(k, 0, len(starts) - 1)
    tau = np.clip((t - starts[kk]) / swing_s, 0.0, 1.0)
    tau = np.where(before, 0.0, tau)
    s = tau - np.sin(2 * np.pi * tau) / (2 * np.pi)
    chord = headings[kk] + turn / 2
    out[:, 0] = origins[kk, 0] + step_length * s * np.cos(chord)
    out[:, 1] = origins[kk, 1] + step_length * s * np.sin(chord)
    out[:, 2] = -height * (1 - np.cos(2 * np.pi * tau)) ** 2 / 4
    w = (1 - np.exp(-((tau / tau_r) ** 2))) * (1 - np.exp(-(((1 - tau) / tau_r) ** 2)))
    out[:, 4] = -pitch_amp * np.sin(2 * np.pi * tau) * w
    out[:, 5] = headings[kk] + turn * s
    out[before] = np.concatenate([origins[0], [0.0, 0.0, 0.0, headings[0]]])
    return out


def walk(
    duration: float | None = None,
    rate_hz: float | None = None,
    seed: int = 0,
    n_steps: int = 20,
    step_length: float = 1.4,
    stance_s: float = 0.5,
    swing_s: float = 0.6,
    turn_deg: float = 0.0,
    swing_height: float = 0.12,
    pitch_amplitude_deg: float = 25.0,
    onset_s: float = 0.02,
    initial_rest_s: float = 2.0,
    final_rest_s: float = 1.0,
    heading_deg: float = 0.0,
    tilt_deg: str | tuple[float, float] = (3.0, -8.0),
    sensor: str = "mems",
    geometry: str = "default",
    jitter_s: float = 0.0,
) -> Recording:
    """Foot-mounted IMU walk with truth (see module doc). Units: m, s, deg at the interface.

    ``n_steps`` swings of ``step_length`` m each (stride of the instrumented foot), ``turn_deg`` heading change
    per step (e.g. 30 with 12 steps walks a closed polygon), ``duration`` (s) if given sets the number of steps
    that fit and pads with rest. ``geometry="paper"``: 3 steps over 2 m at 100 Hz (the INS paper's test).
    """
    if geometry == "paper":
        n_steps, step_length = 3, 2.0 / 3.0
        rate_hz = 100.0 if rate_hz is None else rate_hz
    elif geometry != "default":
        raise ImutoolError(f"walk: unknown geometry {geometry!r} (default, paper)")
    rate_hz = 400.0 if rate_hz is None else float(rate_hz)
    cycle = swing_s + stance_s
    if min(swing_s, stance_s, rate_hz) <= 0 or initial_rest_s < 0 or final_rest_s < 0:
        raise ImutoolError("walk: swing_s, stance_s, rate_hz must be > 0 and rests ≥ 0")
    if duration is not None:
        n_steps = int(max(1, np.floor((duration - initial_rest_s - final_rest_s + stance_s) / cycle)))
    n_steps = int(n_steps)
    total = initial_rest_s + n_steps * cycle - stance_s + final_rest_s
    if duration is not None:
        total = max(total, float(duration))
    if isinstance(tilt_deg, str):
        tilt = [float(x) for x in tilt_deg.split(",")]
    else:
        tilt = [float(x) for x in tilt_deg]
    if len(tilt) != 2:
        raise ImutoolError(f"walk: tilt_deg needs roll,pitch (deg); got {tilt_deg!r}")
    rng = np.random.default_rng(seed)
    t = sample_times(total, rate_hz, rng, jitter_s=jitter_s)

    turn = np.radians(turn_deg)
    starts = initial_rest_s + np.arange(n_steps) * cycle
    headings = np.radians(heading_deg) + turn * np.arange(n_steps + 1)
    chord = headings[:-1] + turn / 2
    origins = np.zeros((n_steps + 1, 2))
    origins[1:, 0] = np.cumsum(step_length * np.cos(chord))
    origins[1:, 1] = np.cumsum(step_length * np.sin(chord))
    args = (
        starts,
        origins,
        headings,
        swing_s,
        step_length,
        turn,
        swing_height,
        np.radians(pitch_amplitude_deg),
        onset_s / swing_s,
    )
    p0 = _profiles(t, *args)
    pp = _profiles(t + _H, *args)
    pm = _profiles(t - _H, *args)
    rate = (pp - pm) / (2 * _H)
    acc = (pp - 2 * p0 + pm) / _H**2
    pos, vel, acc_ned = p0[:, :3], rate[:, :3], acc[:, :3]
    roll, pitch, heading = p0[:, 3], p0[:, 4], p0[:, 5]
    w_foot = body_rates_from_euler(roll, pitch, rate[:, 3], rate[:, 4], rate[:, 5])
    q_foot = euler_to_quat(roll, pitch, heading)
    q_mount = euler_to_quat(np.radians(tilt[0]), np.radians(tilt[1]), 0.0)
    q_true = quat_multiply(q_foot, np.broadcast_to(q_mount, q_foot.shape))
    w_sensor = w_foot @ quat_to_matrix(q_mount)  # R_mᵀ ω (row vectors)

    in_swing = np.zeros(len(t), dtype=bool)
    for s in starts:
        in_swing |= (t > s) & (t < s + swing_s)
    zvi = (~in_swing).astype(float)

    gyro_err, accel_err = foot_sensors(rng, sensor)
    distance = n_steps * step_length
    meta = {
        "scenario": "walk",
        "n_steps": n_steps,
        "step_length_m": step_length,
        "distance_m": distance,
        "turn_deg_per_step": turn_deg,
        "stance_s": stance_s,
        "swing_s": swing_s,
        "geometry": geometry,
        "sensor_model": sensor,
        "tilt_deg": f"{tilt[0]},{tilt[1]}",
        "true_gyro_bias_rad_s": ",".join(f"{v:.6g}" for v in np.broadcast_to(gyro_err.bias, (3,))),
        "true_accel_bias_m_s2": ",".join(f"{v:.6g}" for v in np.broadcast_to(accel_err.bias, (3,))),
        "frame": "body FRD (sensor on the foot); NED world, origin at the start",
    }
    rec = imu_recording(
        t,
        q_true,
        acc_ned,
        rng,
        gyro_errors=gyro_err,
        accel_errors=accel_err,
        mag_errors=None,
        gyro_true=w_sensor,
        meta=meta,
    )
    rec.add("ref_pos", pos, "m")
    rec.add("ref_vel", vel, "m/s")
    rec.add("ref_zvi", zvi, "1")
    return rec
