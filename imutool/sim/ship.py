"""Ship motion scenarios: sinusoidal roll (paper 1 §4.1), a sustained turn, and a sensor at rest.

Frames: body FRD (x bow, y starboard, z down), world NED, quaternions body→NED. Angles in the options are
degrees, everything inside SI. Truth columns are ``ref_*`` (see :func:`imutool.sim.sensor.imu_recording`).

Noise interpretation of the roll paper's "white noise σ = 1.5°": the accelerometer white noise is chosen so
that the roll computed from a *single* accelerometer sample, atan2(−f_y, −f_z), scatters with σ = 1.5° about
the true roll. For a specific force of magnitude g the roll noise is σ_f / g (rad) whatever the roll angle,
so σ_f = g · radians(1.5°) ≈ 0.257 m/s² per sample, i.e. a noise density σ_f / √fs. The kinematic
(lever-arm, centripetal) accelerations come on top, as they do at sea.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from formats import Recording
from formats.frames import euler_to_quat, quat_conjugate, quat_multiply, quat_rotate
from imutool.sim.sensor import (
    GRAVITY,
    HMC5883L_MAG,
    MPU6050_ACCEL,
    MPU6050_GYRO,
    SensorErrors,
    earth_field_ned,
    imu_recording,
    sample_times,
)

EulerFn = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]

_H = 1e-3  # s, step of the central differences used for rates and lever-arm accelerations


def _quat(fn: EulerFn, t: np.ndarray) -> np.ndarray:
    r, p, h = fn(t)
    return euler_to_quat(r, p, h)


def _body_rate(fn: EulerFn, t: np.ndarray) -> np.ndarray:
    """Body angular rate (N,3) rad/s: ω = 2·vec(q* ⊗ q̇), q̇ by a central difference of step _H."""
    q = _quat(fn, t)
    qd = (_quat(fn, t + _H) - _quat(fn, t - _H)) / (2 * _H)
    return 2.0 * quat_multiply(quat_conjugate(q), qd)[:, 1:]


def _lever_accel(fn: EulerFn, t: np.ndarray, lever_b: np.ndarray) -> np.ndarray:
    """NED acceleration (N,3) m/s² of a point at ``lever_b`` (body, m) from the rotation centre: d²(R r)/dt²."""
    if not np.any(lever_b):
        return np.zeros((len(t), 3))
    lv = np.broadcast_to(lever_b, (len(t), 3))
    p0 = quat_rotate(_quat(fn, t), lv)
    pp = quat_rotate(_quat(fn, t + _H), lv)
    pm = quat_rotate(_quat(fn, t - _H), lv)
    return (pp - 2 * p0 + pm) / (_H * _H)


def _sensors(
    rate_hz: float,
    accel_roll_noise_deg: float,
    gyro_bias_deg_s: float,
    gyro_bias_rw_deg_s: float,
    rng: np.random.Generator,
    gyro_noise_deg_s_rthz: float,
) -> tuple[SensorErrors, SensorErrors]:
    g = SensorErrors(**{**MPU6050_GYRO.__dict__})
    g.bias = np.radians(rng.uniform(-gyro_bias_deg_s, gyro_bias_deg_s, 3))
    g.bias_rw = np.radians(gyro_bias_rw_deg_s)
    g.noise_density = np.radians(gyro_noise_deg_s_rthz)
    a = SensorErrors(**{**MPU6050_ACCEL.__dict__})
    a.noise_density = GRAVITY * np.radians(accel_roll_noise_deg) / np.sqrt(rate_hz)
    a.full_range = 4 * GRAVITY
    return g, a


def ship_roll(
    duration: float | None = None,
    rate_hz: float | None = None,
    seed: int = 0,
    *,
    roll_amplitude_deg: float = 15.0,
    roll_period_s: float = 10.0,
    pitch_amplitude_deg: float = 2.0,
    pitch_period_s: float = 7.0,
    heading_deg: float = 45.0,
    yaw_amplitude_deg: float = 1.0,
    accel_roll_noise_deg: float = 1.5,
    gyro_noise_deg_s_rthz: float = 0.005,
    gyro_bias_deg_s: float = 0.5,
    gyro_bias_rw_deg_s: float = 0.002,
    lever_x_m: float = 0.0,
    lever_y_m: float = 0.0,
    lever_z_m: float = -2.0,
    mag_inclination_deg: float = 60.0,
    mag_declination_deg: float = 0.0,
    jitter_s: float = 0.0,
    dropout_fraction: float = 0.0,
    mag: int = 1,
) -> Recording:
    """The roll paper's simulation (§4.1): ±15° sinusoidal roll, small pitch/yaw, white noise, drifting bias.

    duration 120 s, 200 Hz by default. roll φ = A sin(2πt/T), pitch θ = B sin(2πt/Tp + 0.7), heading
    ψ = ψ0 + C sin(2πt/Tp). The sensor sits at ``lever_*_m`` (body FRD, m) from the centre of rotation
    (default 2 m *above* it: lever_z_m = −2), so roll adds tangential/centripetal acceleration that fools an
    accelerometer-only tilt. Gyro: MPU6050 class noise, constant bias drawn uniformly in ±gyro_bias_deg_s per
    axis plus a random walk of gyro_bias_rw_deg_s °/s/√s. Accelerometer white noise: σ = g·radians(
    accel_roll_noise_deg) per sample (module docstring). ``mag=0`` gives a 6-axis recording.
    """
    duration = 120.0 if duration is None else float(duration)
    rate_hz = 200.0 if rate_hz is None else float(rate_hz)
    rng = np.random.default_rng(seed)
    t = sample_times(duration, rate_hz, rng, jitter_s, dropout_fraction)
    a, b, c = np.radians([roll_amplitude_deg, pitch_amplitude_deg, yaw_amplitude_deg])
    w_r, w_p = 2 * np.pi / roll_period_s, 2 * np.pi / pitch_period_s
    psi0 = np.radians(heading_deg)

    def euler(tt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return a * np.sin(w_r * tt), b * np.sin(w_p * tt + 0.7), psi0 + c * np.sin(w_p * tt)

    lever = np.array([lever_x_m, lever_y_m, lever_z_m], dtype=float)
    q = _quat(euler, t)
    acc = _lever_accel(euler, t, lever)
    gerr, aerr = _sensors(
        rate_hz, accel_roll_noise_deg, gyro_bias_deg_s, gyro_bias_rw_deg_s, rng, gyro_noise_deg_s_rthz
    )
    fld = earth_field_ned(50.0, mag_inclination_deg, mag_declination_deg)
    meta = {
        "scenario": "ship-roll",
        "roll_amplitude_deg": roll_amplitude_deg,
        "roll_period_s": roll_period_s,
        "pitch_amplitude_deg": pitch_amplitude_deg,
        "heading_deg": heading_deg,
        "accel_noise_sigma_m_s2": float(aerr.noise_density * np.sqrt(rate_hz)),
        "accel_roll_noise_deg": accel_roll_noise_deg,
        "gyro_bias_rad_s": np.asarray(gerr.bias).tolist(),
        "gyro_bias_rw_rad_s_rts": float(gerr.bias_rw),
        "lever_arm_m": lever.tolist(),
        "mag_field_ned_uT": fld.tolist(),
    }
    return imu_recording(
        t,
        q,
        acc,
        rng,
        gyro_errors=gerr,
        accel_errors=aerr,
        mag_errors=HMC5883L_MAG if mag else None,
        field_ned=fld,
        gyro_true=_body_rate(euler, t),
        meta=meta,
    )


def _smoothstep_integral(x: np.ndarray) -> np.ndarray:
    """∫₀ˣ s(u) du for the cubic smoothstep s = 3u² − 2u³ clipped to [0, 1] (x in ramp units)."""
    xc = np.clip(x, 0.0, 1.0)
    return xc**3 - xc**4 / 2 + np.maximum(x - 1.0, 0.0)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    xc = np.clip(x, 0.0, 1.0)
    return 3 * xc**2 - 2 * xc**3


def turning_ship(
    duration: float | None = None,
    rate_hz: float | None = None,
    seed: int = 0,
    *,
    speed_m_s: float = 10.0,
    rate_of_turn_deg_s: float = 3.0,
    straight_s: float = 20.0,
    ramp_s: float = 10.0,
    heel_deg: float = 3.0,
    heading_deg: float = 0.0,
    roll_amplitude_deg: float = 5.0,
    roll_period_s: float = 10.0,
    pitch_amplitude_deg: float = 1.0,
    pitch_period_s: float = 7.0,
    accel_roll_noise_deg: float = 1.5,
    gyro_noise_deg_s_rthz: float = 0.005,
    gyro_bias_deg_s: float = 0.5,
    gyro_bias_rw_deg_s: float = 0.002,
    lever_x_m: float = 0.0,
    lever_y_m: float = 0.0,
    lever_z_m: float = -2.0,
    gnss_rate_hz: float = 1.0,
    sog_noise_m_s: float = 0.05,
    cog_noise_deg: float = 0.5,
    mag_inclination_deg: float = 60.0,
    jitter_s: float = 0.0,
) -> Recording:
    """A ship that runs straight for ``straight_s``, eases into a sustained turn over ``ramp_s`` and keeps it.

    Speed U (m/s) constant, rate of turn r (°/s, + = to starboard): centripetal acceleration U·r toward the
    centre of the turn (10 m/s at 3 °/s ≈ 0.52 m/s², a 3° error for accelerometer-only tilt). The ship heels
    outward by ``heel_deg`` in the steady turn and rolls ±roll_amplitude_deg about that. GNSS channels
    ``sog`` (m/s) and ``cog`` (deg, = heading: no drift angle) are sampled at ``gnss_rate_hz`` and held between
    fixes (zero-order hold, like a logger that repeats the last RMC), with white noise.
    """
    duration = 180.0 if duration is None else float(duration)
    rate_hz = 200.0 if rate_hz is None else float(rate_hz)
    rng = np.random.default_rng(seed)
    t = sample_times(duration, rate_hz, rng, jitter_s, 0.0)
    r_max = np.radians(rate_of_turn_deg_s)
    a, b = np.radians([roll_amplitude_deg, pitch_amplitude_deg])
    heel = -np.sign(r_max) * np.radians(heel_deg)
    w_r, w_p = 2 * np.pi / roll_period_s, 2 * np.pi / pitch_period_s
    psi0 = np.radians(heading_deg)
    ramp = max(ramp_s, 1e-6)

    def frac(tt: np.ndarray) -> np.ndarray:
        return _smoothstep((tt - straight_s) / ramp)

    def psi(tt: np.ndarray) -> np.ndarray:
        return psi0 + r_max * ramp * _smoothstep_integral((tt - straight_s) / ramp)

    def euler(tt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return heel * frac(tt) + a * np.sin(w_r * tt), b * np.sin(w_p * tt + 0.7), psi(tt)

    lever = np.array([lever_x_m, lever_y_m, lever_z_m], dtype=float)
    q = _quat(euler, t)
    hd = psi(t)
    rate = r_max * frac(t)
    # centre-of-rotation acceleration: U ψ̇ (−sin ψ, cos ψ, 0) (constant speed), plus the lever arm
    acc = speed_m_s * rate[:, None] * np.stack([-np.sin(hd), np.cos(hd), np.zeros_like(hd)], axis=1)
    acc = acc + _lever_accel(euler, t, lever)
    gerr, aerr = _sensors(
        rate_hz, accel_roll_noise_deg, gyro_bias_deg_s, gyro_bias_rw_deg_s, rng, gyro_noise_deg_s_rthz
    )
    fld = earth_field_ned(50.0, mag_inclination_deg, 0.0)
    meta = {
        "scenario": "turn",
        "speed_m_s": speed_m_s,
        "rate_of_turn_deg_s": rate_of_turn_deg_s,
        "centripetal_m_s2": float(speed_m_s * abs(r_max)),
        "heel_deg": heel_deg,
        "accel_roll_noise_deg": accel_roll_noise_deg,
        "gyro_bias_rad_s": np.asarray(gerr.bias).tolist(),
        "lever_arm_m": lever.tolist(),
        "gnss_rate_hz": gnss_rate_hz,
    }
    rec = imu_recording(
        t,
        q,
        acc,
        rng,
        gyro_errors=gerr,
        accel_errors=aerr,
        mag_errors=HMC5883L_MAG,
        field_ned=fld,
        gyro_true=_body_rate(euler, t),
        meta=meta,
    )
    # GNSS: fixes at gnss_rate_hz, held until the next fix
    fix_idx = np.searchsorted(t, np.floor(t * gnss_rate_hz) / gnss_rate_hz, side="left")
    sog_fix = speed_m_s + rng.normal(0.0, sog_noise_m_s, len(t))
    cog_fix = np.degrees(hd) + rng.normal(0.0, cog_noise_deg, len(t))
    rec.add("sog", sog_fix[fix_idx], "m/s")
    rec.add("cog", np.mod(cog_fix[fix_idx], 360.0), "deg")
    rec.add("ref_sog", np.full(len(t), speed_m_s), "m/s")
    rec.add("ref_cog", np.mod(np.degrees(hd), 360.0), "deg")
    rec.add("ref_rate_of_turn", np.degrees(rate), "deg/s")
    return rec


def static(
    duration: float | None = None,
    rate_hz: float | None = None,
    seed: int = 0,
    *,
    roll_deg: float = 0.0,
    pitch_deg: float = 0.0,
    heading_deg: float = 0.0,
    gyro_noise_deg_s_rthz: float = 0.005,
    gyro_bias_deg_s: float = 0.5,
    gyro_bias_rw_deg_s: float = 0.002,
    gyro_bias_instability_deg_s: float = 0.0,
    gyro_bias_tau_s: float = 100.0,
    accel_noise_ug_rthz: float = 400.0,
    accel_bias_mg: float = 0.0,
    mag: int = 1,
) -> Recording:
    """A sensor at rest (for Allan deviation, bias and noise work), vectorised so hours are cheap.

    Gyro: white noise (angle random walk N = gyro_noise_deg_s_rthz °/s/√Hz), constant bias drawn in
    ±gyro_bias_deg_s, rate random walk K = gyro_bias_rw_deg_s °/s/√s and, optionally, a first-order
    Gauss-Markov bias of standard deviation gyro_bias_instability_deg_s and correlation time
    gyro_bias_tau_s (a bump in the Allan deviation near τ ≈ 1.9·T_c). Accelerometer: noise density in µg/√Hz,
    constant bias ±accel_bias_mg. True values in ``meta``.
    """
    duration = 600.0 if duration is None else float(duration)
    rate_hz = 200.0 if rate_hz is None else float(rate_hz)
    rng = np.random.default_rng(seed)
    n = int(round(duration * rate_hz)) + 1
    t = np.arange(n) / rate_hz
    q0 = euler_to_quat(*np.radians([roll_deg, pitch_deg, heading_deg]))
    q = np.broadcast_to(q0, (n, 4))
    gerr = SensorErrors(**{**MPU6050_GYRO.__dict__})
    gerr.bias = np.radians(rng.uniform(-gyro_bias_deg_s, gyro_bias_deg_s, 3))
    gerr.bias_rw = np.radians(gyro_bias_rw_deg_s)
    gerr.noise_density = np.radians(gyro_noise_deg_s_rthz)
    aerr = SensorErrors(**{**MPU6050_ACCEL.__dict__})
    aerr.noise_density = accel_noise_ug_rthz * 1e-6 * GRAVITY
    aerr.bias = rng.uniform(-1, 1, 3) * accel_bias_mg * 1e-3 * GRAVITY
    meta = {
        "scenario": "static",
        "gyro_noise_density_rad_s_rthz": float(gerr.noise_density),
        "gyro_bias_rad_s": np.asarray(gerr.bias).tolist(),
        "gyro_bias_rw_rad_s_rts": float(gerr.bias_rw),
        "accel_noise_density_m_s2_rthz": float(aerr.noise_density),
        "accel_bias_m_s2": np.asarray(aerr.bias).tolist(),
        "gyro_bias_instability_rad_s": float(np.radians(gyro_bias_instability_deg_s)),
        "gyro_bias_tau_s": gyro_bias_tau_s,
    }
    rec = imu_recording(
        t,
        np.ascontiguousarray(q),
        np.zeros((n, 3)),
        rng,
        gyro_errors=gerr,
        accel_errors=aerr,
        mag_errors=HMC5883L_MAG if mag else None,
        gyro_true=np.zeros((n, 3)),
        meta=meta,
    )
    if gyro_bias_instability_deg_s > 0:
        # exact discretisation of a first-order Gauss-Markov process, run as a linear recursion (lfilter)
        from scipy.signal import lfilter

        phi = np.exp(-1.0 / (rate_hz * gyro_bias_tau_s))
        sig = np.radians(gyro_bias_instability_deg_s)
        drive = rng.standard_normal((n, 3)) * sig * np.sqrt(1 - phi * phi)
        drive[0] = rng.standard_normal(3) * sig
        gm = lfilter([1.0], [1.0, -phi], drive, axis=0)
        rec.channels["gyro"] = rec["gyro"] + gm
        rec.channels["ref_gyro_bias"] = rec["ref_gyro_bias"] + gm
    return rec
