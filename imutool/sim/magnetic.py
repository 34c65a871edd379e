"""Magnetic calibration scenarios: a hand-held sphere of rotations (``mag-sphere``) and a ship swinging through
360° in harbour (``compass-swing``).

Forward model of the magnetometer (imutool.sim.sensor): m_meas = A_s m_true + b (+ noise, quantisation).
The calibration recovers m_true = A (m_meas − b) with A = A_s⁻¹ (A_s symmetric here, so A is too).
True parameters are in ``rec.meta``: ``mag_hard_iron_ut`` (b), ``mag_soft_iron`` (A_s), ``mag_correction_A``
(A = A_s⁻¹), ``field_ut`` and, for the swing, ``deviation_deg`` = [A, B, C, D, E].
"""

from __future__ import annotations

import numpy as np

from formats.errors import ImutoolError
from formats.frames import euler_to_quat, quat_multiply
from imutool.sim.sensor import (
    HMC5883L_MAG,
    SensorErrors,
    earth_field_ned,
    field_in_body,
    imu_recording,
    sample_times,
)


def _vec(v, n: int, what: str) -> np.ndarray:
    if isinstance(v, str):
        try:
            v = [float(x) for x in v.replace(";", ",").split(",") if x.strip()]
        except ValueError:
            raise ImutoolError(f"{what}: expected {n} comma-separated numbers, got {v!r}") from None
    a = np.asarray(v, dtype=float).ravel()
    if a.size != n:
        raise ImutoolError(f"{what}: expected {n} numbers, got {a.size}")
    return a


def _mag_errors(hard_iron, soft_iron, noise_density: float) -> tuple[SensorErrors, np.ndarray, np.ndarray]:
    b = _vec(hard_iron, 3, "hard_iron")
    a_s = _vec(soft_iron, 9, "soft_iron").reshape(3, 3)
    if not np.allclose(a_s, a_s.T):
        raise ImutoolError("soft_iron must be symmetric (9 numbers, row by row)")
    e = SensorErrors(**{**HMC5883L_MAG.__dict__})
    e.hard_iron, e.soft_iron, e.noise_density = b, a_s, float(noise_density)
    return e, b, a_s


def _sphere_attitude(t: np.ndarray, duration: float, f_hat: np.ndarray) -> np.ndarray:
    """Quaternions (N,4) body→NED whose body-frame field direction u(t) spirals uniformly over the sphere."""
    z = 2.0 / np.pi * np.arcsin(np.sin(2 * np.pi * t / duration - np.pi / 2))  # triangle −1 → 1 → −1
    lon = 2 * np.pi * 20.0 * t / duration  # 20 loops: spiral spacing in z < the coverage grid's bands
    rho = np.sqrt(np.clip(1 - z * z, 0, None))
    u = np.stack([rho * np.cos(lon), rho * np.sin(lon), z], axis=1)
    axis = np.cross(u, f_hat)
    s = np.linalg.norm(axis, axis=1)
    c = u @ f_hat
    perp = np.cross(f_hat, [1.0, 0.0, 0.0])
    perp /= np.linalg.norm(perp)
    axis = np.where(s[:, None] > 1e-9, axis / np.where(s > 1e-9, s, 1.0)[:, None], perp)
    ang = np.arctan2(s, c)
    q_min = np.column_stack([np.cos(ang / 2), np.sin(ang / 2)[:, None] * axis])  # rotates u onto f_hat
    g = 0.3 * t
    q_g = np.column_stack([np.cos(g / 2), np.sin(g / 2)[:, None] * f_hat])  # about the field (NED)
    return quat_multiply(q_g, q_min)


def mag_sphere(
    duration: float | None = None,
    rate_hz: float | None = None,
    seed: int = 0,
    *,
    hard_iron="12,-25,8",
    soft_iron="1.08,0.05,-0.03,0.05,0.93,0.06,-0.03,0.06,1.01",
    field_ut: float = 50.0,
    inclination_deg: float = 60.0,
    noise_density_ut: float = 0.02,
    coverage: str = "full",
) -> object:
    """Sensor rotated by hand through every orientation: the field direction seen in body axes follows a spiral
    that covers the sphere uniformly (z sweeps −1 → 1 → −1 linearly over the run, longitude makes 20 turns),
    while the sensor also turns about the field at 0.3 rad/s.

    Defaults: 120 s at 50 Hz; hard iron (12, −25, 8) µT; symmetric soft iron A_s (non-trivial off-diagonals);
    HMC5883L noise 0.02 µT/√Hz and 0.092 µT quantisation. ``coverage="half"`` keeps only the samples whose true
    body-frame field points into the +z hemisphere (a half sphere).
    """
    duration = 120.0 if duration is None else float(duration)
    rate_hz = 50.0 if rate_hz is None else float(rate_hz)
    rng = np.random.default_rng(seed)
    t = sample_times(duration, rate_hz, rng)
    fld = earth_field_ned(field_ut, inclination_deg)
    q = _sphere_attitude(t, duration, fld / np.linalg.norm(fld))
    errs, b, a_s = _mag_errors(hard_iron, soft_iron, noise_density_ut)
    rec = imu_recording(
        t,
        q,
        np.zeros((len(t), 3)),
        rng,
        mag_errors=errs,
        field_ned=fld,
        meta={"scenario": "mag-sphere", "sensor": "simulated HMC5883L + MPU6050"},
    )
    if coverage == "half":
        rec = rec.select(rec["ref_mag"][:, 2] >= 0)
    elif coverage != "full":
        raise ImutoolError(f"coverage {coverage!r}: expected full or half")
    rec.meta.update(
        {
            "mag_model": "m_meas = A_s m_true + b; correction m_true = A (m_meas - b), A = inv(A_s)",
            "mag_hard_iron_ut": b.tolist(),
            "mag_soft_iron": a_s.tolist(),
            "mag_correction_A": np.linalg.inv(a_s).tolist(),
            "field_ut": float(field_ut),
            "mag_coverage": coverage,
        }
    )
    return rec


def compass_swing(
    duration: float | None = None,
    rate_hz: float | None = None,
    seed: int = 0,
    *,
    turns: float = 1.1,
    start_heading_deg: float = 10.0,
    deviation="1.5,3.0,-2.0,0.8,-0.6",
    hard_iron="6,-4,0",
    soft_iron="1.05,0.03,0,0.03,0.95,0,0,0,1",
    field_ut: float = 50.0,
    inclination_deg: float = 60.0,
    variation_deg: float = 0.0,
    roll_amplitude_deg: float = 2.0,
    roll_period_s: float = 8.0,
    pitch_amplitude_deg: float = 1.0,
    pitch_period_s: float = 6.0,
    noise_density_ut: float = 0.02,
) -> object:
    """A ship swinging slowly through ``turns`` × 360° in harbour, rolling and pitching a little.

    The compass heading ψc sweeps uniformly; the vessel's true magnetic heading is ψc + δ(ψc) with
    δ = A + B sinψc + C cosψc + D sin2ψc + E cos2ψc (``deviation`` in degrees), i.e. the ship's own field turns
    the horizontal field the sensor sees by −δ. On top, the sensor has hard iron b and soft iron A_s (horizontal by
    default; the vertical terms cannot be observed in a swing). ``ref_heading`` is the true heading (deg),
    ``ref_heading_mag`` the magnetic heading (true − variation, east positive).
    Defaults: 400 s at 10 Hz, 1.1 turns clockwise.
    """
    duration = 400.0 if duration is None else float(duration)
    rate_hz = 10.0 if rate_hz is None else float(rate_hz)
    rng = np.random.default_rng(seed)
    t = sample_times(duration, rate_hz, rng)
    coef = _vec(deviation, 5, "deviation")
    psi_c = np.radians(start_heading_deg) + 2 * np.pi * turns * t / duration
    dev = coef @ np.stack([np.ones_like(psi_c), np.sin(psi_c), np.cos(psi_c), np.sin(2 * psi_c), np.cos(2 * psi_c)])
    psi_mag = psi_c + np.radians(dev)
    var = np.radians(variation_deg)
    roll = np.radians(roll_amplitude_deg) * np.sin(2 * np.pi * t / roll_period_s)
    pitch = np.radians(pitch_amplitude_deg) * np.sin(2 * np.pi * t / pitch_period_s + 0.7)
    q_true = euler_to_quat(roll, pitch, psi_mag + var)
    fld = earth_field_ned(field_ut, inclination_deg, variation_deg)
    rec = imu_recording(
        t,
        q_true,
        np.zeros((len(t), 3)),
        rng,
        mag_errors=None,
        meta={"scenario": "compass-swing", "sensor": "simulated HMC5883L + MPU6050"},
    )
    errs, b, a_s = _mag_errors(hard_iron, soft_iron, noise_density_ut)
    seen = field_in_body(euler_to_quat(roll, pitch, psi_c + var), fld)  # the field the sensor sees
    m, _ = errs.apply(seen, rate_hz, rng)
    rec.add("mag", m, "uT")
    rec.add("ref_mag", field_in_body(q_true, fld), "uT")
    rec.add("ref_heading_mag", np.degrees(psi_mag) % 360.0, "deg")
    rec.add("ref_compass_heading", np.degrees(psi_c) % 360.0, "deg")
    rec.meta.update(
        {
            "mag_model": "m_meas = A_s m_seen + b; correction m = A (m_meas - b), A = inv(A_s)",
            "mag_hard_iron_ut": b.tolist(),
            "mag_soft_iron": a_s.tolist(),
            "mag_correction_A": np.linalg.inv(a_s).tolist(),
            "field_ut": float(field_ut),
            "deviation_deg": coef.tolist(),
            "deviation_model": "magnetic = compass + A + B sin(psi) + C cos(psi) + D sin(2 psi) + E cos(2 psi)",
            "variation_deg": float(variation_deg),
        }
    )
    return rec
