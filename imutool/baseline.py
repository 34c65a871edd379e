"""Baselines the EKF is compared with (roll paper §4.3): accelerometer tilt and tilt-compensated magnetic
heading, optionally through a causal 2nd-order Butterworth low-pass (fc = 0.5 Hz in the paper).

Frames: body FRD, NED. Specific force reads −g on z at rest, so roll φ = atan2(−f_y, −f_z),
pitch θ = atan2(f_x, √(f_y² + f_z²)); heading ψ = atan2(−m_y', m_x') of the field levelled by (φ, θ).
The low-pass acts on the accelerometer and magnetometer *vectors* component-wise (no angle wrap problem),
then the angles are computed. NaN samples are held at the last valid value for filtering and are NaN in the
output.
"""

from __future__ import annotations

import numpy as np

from formats import Recording
from formats.errors import ImutoolError


def accel_tilt(accel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Roll and pitch (rad) from specific force (N,3) in FRD."""
    a = np.asarray(accel, dtype=float)
    roll = np.arctan2(-a[:, 1], -a[:, 2])
    pitch = np.arctan2(a[:, 0], np.hypot(a[:, 1], a[:, 2]))
    return roll, pitch


def tilt_compensated_heading(mag: np.ndarray, roll: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Magnetic heading (rad, [0, 2π)) from the body field (N,3) levelled with roll/pitch (rad)."""
    m = np.asarray(mag, dtype=float)
    sr, cr = np.sin(roll), np.cos(roll)
    sp, cp = np.sin(pitch), np.cos(pitch)
    # horizontal components: m_h = Ry(θ) Rx(φ) m_b
    mx = m[:, 0] * cp + (m[:, 1] * sr + m[:, 2] * cr) * sp
    my = m[:, 1] * cr - m[:, 2] * sr
    return np.mod(np.arctan2(-my, mx), 2 * np.pi)


def _hold_nan(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x = np.array(x, dtype=float)
    bad = ~np.all(np.isfinite(x.reshape(len(x), -1)), axis=1)
    if bad.all():
        return x, bad
    if bad.any():
        idx = np.where(~bad, np.arange(len(x)), -1)
        np.maximum.accumulate(idx, out=idx)
        first = int(np.flatnonzero(~bad)[0])
        idx[idx < 0] = first
        x = x[idx]
    return x, bad


def butter_lowpass(x: np.ndarray, cutoff_hz: float, rate_hz: float, order: int = 2) -> np.ndarray:
    """Causal Butterworth low-pass along axis 0, started in steady state at the first value (no start
    transient). NaN samples are held for filtering and returned as NaN."""
    from scipy.signal import butter, lfilter, lfilter_zi

    nyquist = rate_hz / 2
    # below the Nyquist frequency by more than the rounding of a rate measured from time steps (50.000000001 Hz)
    if not (0 < cutoff_hz < nyquist * (1 - 1e-6)):
        raise ImutoolError(f"cutoff {cutoff_hz} Hz must be between 0 and the Nyquist frequency {nyquist:.6g} Hz")
    xf, bad = _hold_nan(x)
    b, a = butter(order, cutoff_hz / (rate_hz / 2))
    zi = lfilter_zi(b, a)
    x2 = xf.reshape(len(xf), -1)
    out = np.empty_like(x2)
    for j in range(x2.shape[1]):
        out[:, j], _ = lfilter(b, a, x2[:, j], zi=zi * x2[0, j])
    out = out.reshape(xf.shape)
    out[bad] = np.nan
    return out


def lpf_attitude(rec: Recording, cutoff_hz: float | None = 0.5, order: int = 2) -> tuple[Recording, dict]:
    """The paper's baseline: low-passed accelerometer tilt and tilt-compensated magnetic heading.

    cutoff_hz None (or ≤ 0) gives the raw accelerometer-only estimate. Returns (estimate, summary).
    """
    if "accel" not in rec.channels:
        raise ImutoolError(f"the low-pass baseline needs 'accel'; the recording has {', '.join(rec.channels)}")
    fs = rec.rate_hz
    acc = rec.in_unit("accel", "m/s^2")
    mag = rec["mag"] if "mag" in rec.channels else None
    if cutoff_hz and cutoff_hz > 0:
        acc = butter_lowpass(acc, cutoff_hz, fs, order)
        if mag is not None:
            mag = butter_lowpass(mag, cutoff_hz, fs, order)
    roll, pitch = accel_tilt(acc)
    out = Recording(rec.time.copy(), meta=dict(rec.meta))
    out.add("roll", np.degrees(roll))
    out.add("pitch", np.degrees(pitch))
    if mag is not None:
        out.add("heading", np.degrees(tilt_compensated_heading(mag, roll, pitch)))
    from imutool.attitude import carry_labels

    carry_labels(rec, out)
    method = f"lpf (Butterworth order {order}, fc {cutoff_hz} Hz)" if cutoff_hz else "accel-only (no filter)"
    out.meta["filter"] = {"method": method}
    return out, {"method": method, "samples": len(rec), "rate_hz": round(fs, 3)}
