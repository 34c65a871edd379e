"""Digital magnetic compass with a Kalman filter (compass paper, 2019), done right.

Paper: heading Ψ from the horizontal field (eq. 1, a quadrant-corrected arctan), then a scalar Kalman filter
F = H = 1, B = 0, Q = 0.003, R = 2 (deg²), x0 = 0, P0 = 0 (Table 1):
  x⁻ = x,  P⁻ = P + Q,  K = P⁻/(P⁻ + R),  x = x⁻ + K (z − x⁻),  P = (1 − K) P⁻.
What the paper lacks and is done here:
- wrap-around: the innovation z − x⁻ is wrapped to [−180°, 180°) and the state to [0°, 360°), so 359° → 0°
  is a 1° step, not a 359° one;
- tilt compensation: the field is levelled with accelerometer roll/pitch (FRD: ψ = atan2(−m_y', m_x'); the
  paper's eq. 1, Ψ = atan2(H_y, H_x) for H_y ≠ 0, is the same angle in its y-to-port sensor axes);
- deviation and variation: magnetic = compass + δ(compass) (deviation card), true = magnetic + variation;
- initialisation at the first measurement (x0 = z0, P0 = R) instead of x0 = 0, P0 = 0 (``paper_init``);
- a two-state variant x = [ψ, b] driven by the gyro rate of turn r (world-vertical rate, °/s):
  ψ⁻ = ψ + (r − b)·dt, F = [[1, −dt], [0, 1]], Q = diag(q_rate·dt, q_bias·dt), H = [1, 0]; it follows a turn
  without the scalar filter's lag.
Units: degrees at this module's surface (headings, Q/R in deg²), time s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats import Recording
from formats.errors import ImutoolError
from formats.jit.decorators import njit


@dataclass
class CompassParams:
    q: float = 0.003  # deg² per sample: heading process noise of the scalar filter (paper)
    r: float = 2.0  # deg²: measurement noise of the raw heading (paper)
    model: str = "auto"  # scalar | gyro | auto (gyro when a gyro channel is present)
    rate_noise: float = 0.05  # deg/s/√Hz: rate-of-turn noise density (two-state model)
    bias_rw: float = 0.01  # deg/s/√s: gyro bias random walk (two-state model)
    variation_deg: float = 0.0  # east positive: true = magnetic + variation
    paper_init: bool = False  # x0 = 0, P0 = 0 as in the paper (default: x0 = first measurement, P0 = R)


@njit(cache=True)
def compass_kernel(t, z, rate, q, r, q_rate, q_bias, use_rate, paper_init, out, out_std, out_bias):
    """Wrapped heading KF over z (deg, NaN = no measurement); rate (deg/s) used when use_rate."""
    n = z.shape[0]
    x = 0.0
    b = 0.0
    p00, p01, p11 = 0.0, 0.0, 0.0
    started = paper_init
    if use_rate:
        p11 = 1.0  # (deg/s)² initial bias uncertainty
    for k in range(n):
        if not started:
            if np.isfinite(z[k]):
                x = z[k] % 360.0
                p00 = r
                started = True
            out[k] = x if started else np.nan
            out_std[k] = np.sqrt(p00) if started else np.nan
            out_bias[k] = b
            continue
        # predict
        if use_rate:
            dt = t[k] - t[k - 1] if k > 0 else 0.0
            rk = rate[k] if np.isfinite(rate[k]) else b
            x = x + (rk - b) * dt
            a00 = p00 - 2 * dt * p01 + dt * dt * p11 + q_rate * dt
            a01 = p01 - dt * p11
            a11 = p11 + q_bias * dt
            p00, p01, p11 = a00, a01, a11
        else:
            p00 = p00 + q
        # update (wrapped innovation)
        if np.isfinite(z[k]):
            y = (z[k] - x + 180.0) % 360.0 - 180.0
            s = p00 + r
            k0 = p00 / s
            k1 = p01 / s
            x = x + k0 * y
            b = b + k1 * y
            a00 = (1 - k0) * p00
            a01 = (1 - k0) * p01
            a11 = p11 - k1 * p01
            p00, p01, p11 = a00, a01, a11
        x = x % 360.0
        out[k] = x
        out_std[k] = np.sqrt(max(p00, 0.0))
        out_bias[k] = b


def wrapped_kf(
    z_deg: np.ndarray,
    time: np.ndarray | None = None,
    rate_deg_s: np.ndarray | None = None,
    params: CompassParams | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Filter a heading series (deg). Returns (heading deg [0,360), σ deg, rate bias deg/s)."""
    p = params or CompassParams()
    z = np.ascontiguousarray(z_deg, dtype=float)
    n = len(z)
    t = np.arange(n, dtype=float) if time is None else np.ascontiguousarray(time, dtype=float)
    use_rate = rate_deg_s is not None
    rr = np.ascontiguousarray(rate_deg_s, dtype=float) if use_rate else np.zeros(n)
    out, sd, bias = np.empty(n), np.empty(n), np.empty(n)
    compass_kernel(t, z, rr, p.q, p.r, p.rate_noise**2, p.bias_rw**2, use_rate, p.paper_init, out, sd, bias)
    return out, sd, bias


def raw_heading(rec: Recording, deviation=None) -> tuple[np.ndarray, str]:
    """Raw magnetic heading (deg) per sample: tilt-compensated from ``mag`` (+ ``accel``), or an NMEA heading
    channel (heading_mag, heading_sensor, heading_true). A deviation card (``.deviation_deg``) is applied to
    compass headings. Returns (heading, description of the source)."""
    from imutool.baseline import accel_tilt, tilt_compensated_heading

    if "mag" in rec.channels:
        mag = rec["mag"]
        if "accel" in rec.channels:
            roll, pitch = accel_tilt(rec.in_unit("accel", "m/s^2"))
            src = "tilt-compensated magnetometer"
        else:
            roll = pitch = np.zeros(len(rec))
            src = "magnetometer (no accelerometer: not tilt-compensated)"
        h = np.degrees(tilt_compensated_heading(mag, roll, pitch))
    elif "heading_sensor" in rec.channels:
        h, src = np.asarray(rec["heading_sensor"], float), "NMEA HDG sensor heading"
    elif "heading_mag" in rec.channels:
        h, src = np.asarray(rec["heading_mag"], float), "NMEA magnetic heading (HDM/HDG)"
        deviation = None  # already magnetic
    elif "heading" in rec.channels:
        h, src = np.asarray(rec["heading"], float), "heading channel"
    else:
        raise ImutoolError(
            "the compass filter needs 'mag' (with 'accel' for tilt compensation) or a heading "
            f"channel (heading_mag, heading_sensor, heading); the recording has "
            f"{', '.join(rec.channels)}"
        )
    if deviation is not None:
        h = (h + deviation.deviation_deg(h)) % 360.0
        src += " + deviation card"
    return h, src


def vertical_rate_deg_s(rec: Recording) -> np.ndarray | None:
    """Rate of turn about the world vertical (deg/s) from the gyro, levelled with accelerometer tilt
    (ψ̇ = (q sinφ + r cosφ)/cosθ, FRD); the NMEA ``rot`` channel (deg/min) when there is no gyro."""
    if "gyro" in rec.channels:
        from imutool.baseline import accel_tilt

        g = rec.in_unit("gyro", "rad/s")
        if "accel" in rec.channels:
            roll, pitch = accel_tilt(rec.in_unit("accel", "m/s^2"))
        else:
            roll = pitch = np.zeros(len(rec))
        return np.degrees((g[:, 1] * np.sin(roll) + g[:, 2] * np.cos(roll)) / np.maximum(np.cos(pitch), 1e-3))
    if "rot" in rec.channels:
        return np.asarray(rec["rot"], float) / 60.0
    return None


def compass_recording(rec: Recording, params: CompassParams | None = None, deviation=None) -> tuple[Recording, dict]:
    """Run the compass filter over a recording. Output: heading (deg, true when a variation is given, else
    magnetic), heading_std (deg), heading_raw (deg, the unfiltered input heading) and ref_* carried over."""
    p = params or CompassParams()
    z, src = raw_heading(rec, deviation)
    rate = None
    model = p.model
    if model not in ("scalar", "gyro", "auto"):
        raise ImutoolError(f"compass model {model!r}: expected scalar, gyro or auto")
    if model in ("gyro", "auto"):
        rate = vertical_rate_deg_s(rec)
        if rate is None and model == "gyro":
            raise ImutoolError("compass model 'gyro' needs a gyro channel (or NMEA ROT)")
        model = "gyro" if rate is not None else "scalar"
    h, sd, bias = wrapped_kf(z, rec.time, rate if model == "gyro" else None, p)
    h = (h + p.variation_deg) % 360.0
    out = Recording(rec.time.copy(), meta=dict(rec.meta))
    out.add("heading", h)
    out.add("heading_std", sd, "deg")
    out.add("heading_raw", (z + p.variation_deg) % 360.0, "deg")
    from imutool.attitude import carry_labels

    carry_labels(rec, out)
    out.meta["filter"] = {"method": f"compass KF ({model})", "q": p.q, "r": p.r, "variation_deg": p.variation_deg}
    summary = {
        "method": f"compass-{model}",
        "source": src,
        "samples": len(rec),
        "measurements": int(np.isfinite(z).sum()),
        "variation_deg": p.variation_deg,
        "deviation_card": deviation is not None,
    }
    if model == "gyro":
        summary["rate_bias_deg_s_final"] = round(float(bias[-1]), 4)
    return out, summary
