"""MEMS sensor error model and rigid-body kinematics for the simulator.

Errors per axis (all in the sensor's SI unit): white noise from a noise density (unit/√Hz, σ = nd·√fs),
constant bias, bias random walk (unit/√s), scale-factor error, axis misalignment (small-angle matrix),
quantisation step and saturation range. The magnetometer adds hard iron b (µT) and soft iron A:
m_measured = A · m_true + b (so the correction is m_true = A⁻¹ (m_measured − b)).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from formats import Recording
from formats.frames import quat_conjugate, quat_multiply, quat_to_euler, quat_to_matrix

GRAVITY = 9.80665  # m/s², local gravity used by the simulator (NED: g points down, +z)


@dataclass
class SensorErrors:
    """Error parameters of one triaxial sensor (SI units of that sensor)."""

    noise_density: float = 0.0  # unit/√Hz
    bias: np.ndarray | float = 0.0  # constant bias (3,) or scalar
    bias_rw: float = 0.0  # bias random walk, unit/√s
    scale: np.ndarray | float = 0.0  # scale-factor error (fraction), (3,) or scalar
    misalignment: np.ndarray | None = None  # 3×3 small-angle cross-coupling (zero diagonal)
    quantum: float = 0.0  # quantisation step (0 = none)
    full_range: float = np.inf  # saturation |value|
    hard_iron: np.ndarray | None = None  # magnetometer only: b (µT)
    soft_iron: np.ndarray | None = None  # magnetometer only: A (3×3)
    extra: dict = field(default_factory=dict)

    def apply(self, truth: np.ndarray, rate_hz: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Measured values (N,3) from true values (N,3); also returns the bias actually applied (N,3)."""
        x = np.asarray(truth, dtype=float)
        n = x.shape[0]
        if self.soft_iron is not None:
            x = x @ np.asarray(self.soft_iron).T
        if self.hard_iron is not None:
            x = x + np.asarray(self.hard_iron)
        m = np.eye(3) + np.diag(np.broadcast_to(np.asarray(self.scale, dtype=float), (3,)))
        if self.misalignment is not None:
            m = m + np.asarray(self.misalignment)
        y = x @ m.T
        bias = np.broadcast_to(np.asarray(self.bias, dtype=float), (3,)).copy()
        b = np.tile(bias, (n, 1))
        if self.bias_rw > 0:
            steps = rng.standard_normal((n, 3)) * self.bias_rw / np.sqrt(rate_hz)
            steps[0] = 0.0
            b = b + np.cumsum(steps, axis=0)
        y = y + b
        if self.noise_density > 0:
            y = y + rng.standard_normal((n, 3)) * self.noise_density * np.sqrt(rate_hz)
        if self.quantum > 0:
            y = np.round(y / self.quantum) * self.quantum
        if np.isfinite(self.full_range):
            y = np.clip(y, -self.full_range, self.full_range)
        return y, b


# Typical consumer MEMS (MPU6050 / HMC5883L class) figures, SI units.
MPU6050_GYRO = SensorErrors(
    noise_density=np.radians(0.005),
    bias=0.0,
    bias_rw=np.radians(0.002),
    quantum=np.radians(250.0 / 32768),
    full_range=np.radians(250.0),
)
MPU6050_ACCEL = SensorErrors(noise_density=400e-6 * GRAVITY, quantum=2 * GRAVITY / 32768, full_range=2 * GRAVITY)
HMC5883L_MAG = SensorErrors(noise_density=0.02, quantum=100.0 / 1090.0)


def body_rates_from_euler(roll, pitch, roll_rate, pitch_rate, heading_rate) -> np.ndarray:
    """Body angular rate ω (N,3) rad/s in FRD from ZYX Euler angles and their time derivatives (rad, rad/s).

    p = φ̇ − ψ̇ sinθ;  q = θ̇ cosφ + ψ̇ sinφ cosθ;  r = −θ̇ sinφ + ψ̇ cosφ cosθ.
    """
    sr, cr = np.sin(roll), np.cos(roll)
    sp, cp = np.sin(pitch), np.cos(pitch)
    p = roll_rate - heading_rate * sp
    q = pitch_rate * cr + heading_rate * sr * cp
    r = -pitch_rate * sr + heading_rate * cr * cp
    return np.stack([p, q, r], axis=-1)


def specific_force(q_body_to_ned: np.ndarray, accel_ned: np.ndarray, gravity: float = GRAVITY) -> np.ndarray:
    """Specific force in the body frame: f_b = Rᵀ (a_ned − g_ned), g_ned = [0, 0, +g] (reads −g on z at rest)."""
    r = quat_to_matrix(q_body_to_ned)
    a = np.asarray(accel_ned, dtype=float) - np.array([0.0, 0.0, gravity])
    return np.einsum("nji,nj->ni", r, a)


def earth_field_ned(
    intensity_ut: float = 50.0, inclination_deg: float = 60.0, declination_deg: float = 0.0
) -> np.ndarray:
    """Earth magnetic field vector in NED (µT); inclination positive down (northern hemisphere)."""
    inc, dec = np.radians(inclination_deg), np.radians(declination_deg)
    return intensity_ut * np.array([np.cos(inc) * np.cos(dec), np.cos(inc) * np.sin(dec), np.sin(inc)])


def field_in_body(q_body_to_ned: np.ndarray, field_ned: np.ndarray) -> np.ndarray:
    """A world (NED) vector expressed in body axes: v_b = Rᵀ v_ned, for each quaternion (N,4)."""
    r = quat_to_matrix(q_body_to_ned)
    v = np.broadcast_to(np.asarray(field_ned, dtype=float), (r.shape[0], 3))
    return np.einsum("nji,nj->ni", r, v)


def sample_times(
    duration: float, rate_hz: float, rng: np.random.Generator, jitter_s: float = 0.0, dropout_fraction: float = 0.0
) -> np.ndarray:
    """Sample instants: a uniform clock with optional Gaussian jitter (kept monotonic) and random dropouts."""
    n = int(round(duration * rate_hz)) + 1
    t = np.arange(n) / rate_hz
    if jitter_s > 0:
        t = t + rng.normal(0.0, jitter_s, n)
        t = np.maximum.accumulate(t)
        t[1:] = np.maximum(t[1:], t[:-1] + 1e-6)
    if dropout_fraction > 0:
        keep = rng.random(n) >= dropout_fraction
        keep[0] = True
        t = t[keep]
    return t


def imu_recording(
    t: np.ndarray,
    q_true: np.ndarray,
    accel_ned: np.ndarray,
    rng: np.random.Generator,
    gyro_errors: SensorErrors | None = MPU6050_GYRO,
    accel_errors: SensorErrors | None = MPU6050_ACCEL,
    mag_errors: SensorErrors | None = HMC5883L_MAG,
    field_ned: np.ndarray | None = None,
    gyro_true: np.ndarray | None = None,
    gravity: float = GRAVITY,
    meta: dict | None = None,
) -> Recording:
    """Build a 9-axis (or 6-axis with ``mag_errors=None``) recording with truth columns.

    t (N,) s; q_true (N,4) body→NED; accel_ned (N,3) m/s² kinematic acceleration of the sensor in NED;
    gyro_true (N,3) rad/s body rate (derived from q_true by finite differences when not given).
    Truth columns: ref_q, ref_roll/ref_pitch/ref_heading (deg), ref_gyro (rad/s), ref_gyro_bias (rad/s),
    ref_accel (m/s², error-free specific force) and ref_mag (µT, undistorted field in body axes).
    """
    t = np.asarray(t, dtype=float)
    fs = 1.0 / float(np.median(np.diff(t)))
    if gyro_true is None:
        dq = quat_multiply(quat_conjugate(q_true[:-1]), q_true[1:])
        dq = np.where(dq[:, :1] < 0, -dq, dq)
        ang = 2 * np.arctan2(np.linalg.norm(dq[:, 1:], axis=1), dq[:, 0])
        s = np.linalg.norm(dq[:, 1:], axis=1)
        axis = np.divide(dq[:, 1:], s[:, None], out=np.zeros_like(dq[:, 1:]), where=s[:, None] > 0)
        w_mid = axis * (ang / np.diff(t))[:, None]
        gyro_true = np.empty((len(t), 3))
        gyro_true[1:-1] = 0.5 * (w_mid[1:] + w_mid[:-1])
        gyro_true[0], gyro_true[-1] = w_mid[0], w_mid[-1]
    f_true = specific_force(q_true, accel_ned, gravity)
    roll, pitch, heading = quat_to_euler(q_true)
    rec = Recording(t, meta=dict(meta or {}))
    if gyro_errors is not None:
        g, gb = gyro_errors.apply(gyro_true, fs, rng)
        rec.add("gyro", g)
    if accel_errors is not None:
        a, _ = accel_errors.apply(f_true, fs, rng)
        rec.add("accel", a)
    if mag_errors is not None:
        fld = earth_field_ned() if field_ned is None else np.asarray(field_ned, dtype=float)
        m_true = field_in_body(q_true, fld)
        m, _ = mag_errors.apply(m_true, fs, rng)
        rec.add("mag", m)
        rec.add("ref_mag", m_true, "uT")
    rec.add("ref_roll", np.degrees(roll))
    rec.add("ref_pitch", np.degrees(pitch))
    rec.add("ref_heading", np.degrees(heading))
    rec.add("ref_q", q_true)
    rec.add("ref_gyro", gyro_true, "rad/s")
    if gyro_errors is not None:
        rec.add("ref_gyro_bias", gb)
    rec.add("ref_accel", f_true, "m/s^2")
    rec.meta.setdefault("rate_hz", round(fs, 6))
    rec.meta.setdefault("frame", "body FRD (x bow, y starboard, z down); ref_q body->NED")
    rec.meta.setdefault("source", "imutool simulator")
    return rec
