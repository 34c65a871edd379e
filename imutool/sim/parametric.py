"""Parametric-roll scenario: head-sea pitch/heave at the encounter period Te, roll growing at 2·Te after an onset.

Principal parametric resonance (IMO MSC.1/Circ.1228; ABS Guide for the Assessment of Parametric Roll Resonance;
MSC.1/Circ.1627 second-generation intact stability criteria): the waterplane changes with each passing wave, so
GM oscillates at the encounter frequency ωe; when the roll natural period is about twice the encounter period,
roll locks onto ωe/2 and grows exponentially until damping and non-linear restoring saturate it.

Model (deterministic for a seed; angles deg in options, SI inside; body FRD, NED, truth ``ref_*``):

- pitch θ = P sin(ωe t) + a little irregular pitch, heave ζ = H sin(ωe t + ½π) (m, up), ωe = 2π/Te;
- roll φ = A(t) sin(ωe t / 2 + φ0) + a little irregular roll at the roll period (so the background before the
  onset is a realistic ~1° roll), with the envelope ``A(t) = Amax / sqrt(1 + ((Amax/A0)² − 1) e^{−2σ(t−t0)})``
  for t ≥ t0 (A0 before): exponential growth e^{σ(t−t0)} from ``initial_roll_deg`` A0 at the onset t0,
  saturating at ``max_roll_deg``. Truth of the onset is ``meta['onset_s']`` (s, recording time).

``roll_ratio`` (roll period / Te, default 2) and a negative ``growth_rate`` allow detuned or decaying cases.
"""

from __future__ import annotations

import numpy as np

from formats import Recording
from formats.errors import ImutoolError
from formats.frames import euler_to_quat
from imutool.sim.sensor import MPU6050_ACCEL, MPU6050_GYRO, body_rates_from_euler, imu_recording


def envelope(t: np.ndarray, onset_s: float, a0: float, amax: float, rate: float) -> np.ndarray:
    """Roll amplitude envelope (same unit as a0/amax): a0 before the onset, logistic-saturated e^{rate (t−onset)}."""
    t = np.asarray(t, float)
    dt = np.maximum(t - onset_s, 0.0)
    if amax <= a0 or rate == 0:
        return np.full_like(t, a0)
    with np.errstate(over="ignore"):
        return amax / np.sqrt(1.0 + ((amax / a0) ** 2 - 1.0) * np.exp(-2.0 * rate * dt))


def _irregular(t: np.ndarray, period: float, amp: float, rng: np.random.Generator, n: int = 12) -> tuple:
    """A narrow-band irregular signal around ``period`` (value, derivative) with RMS ≈ amp."""
    w0 = 2 * np.pi / period
    w = w0 * rng.uniform(0.85, 1.15, n)
    c = rng.uniform(0.5, 1.5, n)
    a = amp * np.sqrt(2.0 / n) * c / np.sqrt(np.mean(c**2))
    ph = rng.uniform(0, 2 * np.pi, n)
    arg = np.outer(t, w) + ph
    return (np.sin(arg) * a).sum(1), (np.cos(arg) * (a * w)).sum(1)


def parametric_roll(
    duration: float | None = None,
    rate_hz: float | None = None,
    seed: int = 0,
    *,
    encounter_period_s: float = 10.0,
    roll_ratio: float = 2.0,
    onset_s: float = 300.0,
    growth_rate: float = 0.025,
    initial_roll_deg: float = 1.0,
    max_roll_deg: float = 25.0,
    pitch_amplitude_deg: float = 3.0,
    heave_amplitude_m: float = 2.0,
    irregular_roll_deg: float = 0.5,
    irregular_pitch_deg: float = 0.3,  # RMS, deg
    heading_deg: float = 0.0,
) -> Recording:
    """A container ship in head seas entering parametric roll (module docstring for the model).

    Defaults: 900 s at 20 Hz; Te 10 s, roll at 2·Te = 20 s from 1° at the onset 300 s growing with
    σ = 0.025 1/s (e-folding 40 s) to 25°; pitch ±3°, heave ±2 m at Te. 6-axis MEMS IMU at the centre of gravity.
    Truth: ref_roll/ref_pitch/ref_heading (deg), ref_heave (m, up), ref_q, ref_gyro, ref_accel;
    ``meta['onset_s']``, ``meta['encounter_period_s']``, ``meta['roll_period_s']``.
    """
    duration = 900.0 if duration is None else float(duration)
    rate_hz = 20.0 if rate_hz is None else float(rate_hz)
    if encounter_period_s <= 0 or roll_ratio <= 0:
        raise ImutoolError("parametric-roll: encounter_period_s and roll_ratio must be > 0")
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration * rate_hz)) + 1) / rate_hz
    we = 2 * np.pi / encounter_period_s
    wr = we / roll_ratio
    env = np.radians(envelope(t, onset_s, initial_roll_deg, max_roll_deg, growth_rate))
    h = 1e-3
    denv = (np.radians(envelope(t + h, onset_s, initial_roll_deg, max_roll_deg, growth_rate)) - env) / h
    ph0 = rng.uniform(0, 2 * np.pi)
    ir, dir_ = _irregular(t, encounter_period_s * roll_ratio, np.radians(irregular_roll_deg), rng)
    roll = env * np.sin(wr * t + ph0) + ir
    droll = denv * np.sin(wr * t + ph0) + env * wr * np.cos(wr * t + ph0) + dir_
    p = np.radians(pitch_amplitude_deg)
    ip, dip = _irregular(t, encounter_period_s, np.radians(irregular_pitch_deg), rng)
    pitch = p * np.sin(we * t) + ip
    dpitch = p * we * np.cos(we * t) + dip
    heave = heave_amplitude_m * np.cos(we * t)
    dheave = -heave_amplitude_m * we * np.sin(we * t)
    ddheave = -(we**2) * heave
    psi = np.radians(heading_deg)
    rates = body_rates_from_euler(roll, pitch, droll, dpitch, np.zeros_like(t))
    q = euler_to_quat(roll, pitch, np.full_like(t, psi))
    accel_ned = np.zeros((len(t), 3))
    accel_ned[:, 2] = -ddheave  # NED down = −heave
    meta = {
        "scenario": "parametric-roll",
        "onset_s": float(onset_s),
        "encounter_period_s": encounter_period_s,
        "roll_period_s": encounter_period_s * roll_ratio,
        "growth_rate_per_s": growth_rate,
        "initial_roll_deg": initial_roll_deg,
        "max_roll_deg": max_roll_deg,
        "pitch_amplitude_deg": pitch_amplitude_deg,
        "heave_amplitude_m": heave_amplitude_m,
        "heave_convention": "heave m positive UP at the IMU (vessel CoG); accel body FRD",
    }
    rec = imu_recording(
        t,
        q,
        accel_ned,
        rng,
        gyro_errors=MPU6050_GYRO,
        accel_errors=MPU6050_ACCEL,
        mag_errors=None,
        gyro_true=rates,
        meta=meta,
    )
    rec.add("ref_heave", heave, "m")
    rec.add("ref_heave_rate", dheave, "m/s")
    return rec
