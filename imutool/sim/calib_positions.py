"""Calibration-table scenarios: a sensor held still in known orientations (six-position accelerometer test).

The sensor is turned by hand or on a table into each pose, held ``hold_s`` seconds, then rotated smoothly to the
next pose over ``move_s`` seconds. The accelerometer carries a known bias (m/s²), scale-factor error and axis
misalignment; the truth is stored in the metadata (``accel_bias_m_s2``, ``accel_scale``, ``accel_misalignment``)
and the error-free specific force in ``ref_accel`` (m/s², body FRD).
"""

from __future__ import annotations

import numpy as np

from formats import Recording
from formats.errors import ImutoolError
from formats.frames import euler_to_quat
from imutool.sim.sensor import MPU6050_ACCEL, MPU6050_GYRO, SensorErrors, imu_recording

# (roll, pitch) in degrees, heading 0: each body axis down once and up once (x, y, z ± g).
SIX_POSES = ((0.0, 0.0), (180.0, 0.0), (90.0, 0.0), (-90.0, 0.0), (0.0, 90.0), (0.0, -90.0))
# six tilted poses added by ``poses=12`` so that misalignment (the full 9-parameter fit) is observable
EXTRA_POSES = ((45.0, 30.0), (-60.0, -20.0), (120.0, 40.0), (30.0, -60.0), (-135.0, 10.0), (70.0, 70.0))


def six_position(
    duration: float | None = None,
    rate_hz: float | None = None,
    seed: int = 0,
    *,
    poses: int = 6,
    hold_s: float = 6.0,
    move_s: float = 3.0,
    accel_bias_mg: float = 15.0,
    accel_scale_pct: float = 1.5,
    accel_misalignment_deg: float = 0.25,
    accel_noise_ug_rthz: float = 400.0,
    gyro_bias_deg_s: float = 0.5,
) -> Recording:
    """Six-position (``poses=6``) or twelve-position (``poses=12``) accelerometer calibration recording.

    Accelerometer errors (drawn once per seed): bias uniform in ±accel_bias_mg mg per axis, scale-factor error
    uniform in ±accel_scale_pct %, misalignment (off-diagonal coupling) uniform in ±accel_misalignment_deg deg.
    ``duration`` (s), when given, stretches or shrinks hold and move times in proportion. Default 100 Hz.
    """
    if poses not in (6, 12):
        raise ImutoolError(f"six-position: poses must be 6 or 12 (got {poses})")
    if hold_s <= 0 or move_s <= 0:
        raise ImutoolError("six-position: hold_s and move_s must be > 0")
    table = SIX_POSES + (EXTRA_POSES if poses == 12 else ())
    period = hold_s + move_s
    if duration is not None:
        if not duration > 0:
            raise ImutoolError(f"six-position: duration must be > 0 (got {duration})")
        scale = float(duration) / (len(table) * period)
        hold_s, move_s, period = hold_s * scale, move_s * scale, period * scale
    rate_hz = 100.0 if rate_hz is None else float(rate_hz)
    rng = np.random.default_rng(seed)
    n = int(round(len(table) * period * rate_hz)) + 1
    t = np.arange(n) / rate_hz
    k = np.minimum((t // period).astype(int), len(table) - 1)
    nxt = np.minimum(k + 1, len(table) - 1)
    s = np.clip((t - k * period - hold_s) / move_s, 0.0, 1.0)
    s = s * s * (3.0 - 2.0 * s)  # smoothstep: rate zero at both ends of each move
    r = np.radians([p[0] for p in table])
    p = np.radians([p[1] for p in table])
    quats = euler_to_quat(r, p, np.zeros_like(r))
    q0, q1 = quats[k], quats[nxt]
    q1 = np.where(np.sum(q0 * q1, axis=1)[:, None] < 0, -q1, q1)
    q = (1.0 - s)[:, None] * q0 + s[:, None] * q1
    q /= np.linalg.norm(q, axis=1, keepdims=True)

    aerr = SensorErrors(**{**MPU6050_ACCEL.__dict__})
    aerr.noise_density = accel_noise_ug_rthz * 1e-6 * 9.80665
    aerr.bias = rng.uniform(-1.0, 1.0, 3) * accel_bias_mg * 1e-3 * 9.80665
    aerr.scale = rng.uniform(-1.0, 1.0, 3) * accel_scale_pct / 100.0
    mis = rng.uniform(-1.0, 1.0, (3, 3)) * np.radians(accel_misalignment_deg)
    np.fill_diagonal(mis, 0.0)
    aerr.misalignment = mis
    aerr.full_range = np.inf
    gerr = SensorErrors(**{**MPU6050_GYRO.__dict__})
    gerr.bias = np.radians(rng.uniform(-gyro_bias_deg_s, gyro_bias_deg_s, 3))
    gerr.bias_rw = 0.0
    gerr.full_range = np.inf
    meta = {
        "scenario": "six-position",
        "poses": len(table),
        "hold_s": round(hold_s, 6),
        "move_s": round(move_s, 6),
        "accel_model": "f_meas = (I + diag(scale) + misalignment) f_true + bias",
        "accel_bias_m_s2": np.asarray(aerr.bias).tolist(),
        "accel_scale": np.asarray(aerr.scale).tolist(),
        "accel_misalignment": mis.tolist(),
    }
    return imu_recording(t, q, np.zeros((n, 3)), rng, gyro_errors=gerr, accel_errors=aerr, mag_errors=None, meta=meta)
