"""Accelerometer-array scenario (gyro-free paper §2): the paper's angular rates, any layout, truth columns.

ω(t) in body FRD (rad/s), paper: ωx = 0.005 t + 0.1, ωy = 0.1 sin(0.1 t), ωz = 2.6 for t ≤ 8 s then
2.6 + 0.006 (t − 8). The centre of mass also translates gently (option ``translation``), gravity acts in NED.
Every accelerometer axis measures d·(f_O + ω̇×r + ω×(ω×r)) + noise (+ optional bias).
Truth: ref_gyro (ω), ref_angular_accel (ω̇), ref_accel (f_O), ref_q and ref_roll/pitch/heading (deg).
"""

from __future__ import annotations

import numpy as np

from formats import Recording
from formats.frames import quat_multiply, quat_normalize, quat_to_euler
from formats.units import convert
from imutool.sim.sensor import GRAVITY, specific_force


def paper_rates(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ω (N,3) rad/s and ω̇ (N,3) rad/s² of the paper's simulation."""
    t = np.asarray(t, float)
    w = np.stack([0.005 * t + 0.1, 0.1 * np.sin(0.1 * t), np.where(t <= 8.0, 2.6, 2.6 + 0.006 * (t - 8.0))], 1)
    wd = np.stack([np.full_like(t, 0.005), 0.01 * np.cos(0.1 * t), np.where(t <= 8.0, 0.0, 0.006)], 1)
    return w, wd


def integrate_quaternion(t: np.ndarray, w: np.ndarray, q0: np.ndarray | None = None) -> np.ndarray:
    """Body→NED quaternions from body rates (exact rotation per step with the mid-point rate)."""
    n = len(t)
    q = np.empty((n, 4))
    q[0] = np.array([1.0, 0, 0, 0]) if q0 is None else q0
    wm = 0.5 * (w[1:] + w[:-1])
    dt = np.diff(t)
    ang = np.linalg.norm(wm, axis=1) * dt
    axis = np.divide(
        wm,
        np.linalg.norm(wm, axis=1, keepdims=True),
        out=np.zeros_like(wm),
        where=np.linalg.norm(wm, axis=1, keepdims=True) > 0,
    )
    dq = np.concatenate([np.cos(ang / 2)[:, None], axis * np.sin(ang / 2)[:, None]], 1)
    for k in range(1, n):  # short scenarios: a plain loop is fine here (simulator only)
        q[k] = quat_multiply(q[k - 1], dq[k - 1])
    return quat_normalize(q)


def accel_array(
    duration: float | None = None,
    rate_hz: float | None = None,
    seed: int = 0,
    layout: str = "paper",
    r: float = 0.1,
    noise_ug: float = 100.0,
    bias_mps2: float = 0.0,
    translation: float = 0.2,
) -> Recording:
    """Paper rates, array ``layout`` ('paper' preset with distance r m, or a layout TOML path).

    Defaults: 20 s at 100 Hz, noise density ``noise_ug`` µg/√Hz per axis (a mid-range MEMS), no bias
    (``bias_mps2`` adds a random constant bias of that one-sigma per axis), translational acceleration of the
    centre ``translation`` m/s² amplitude (slow sinusoids in NED)."""
    from imutool.gyrofree import design_matrix, load_layout, paper_layout  # noqa: PLC0415

    duration = 20.0 if duration is None else float(duration)
    rate_hz = 100.0 if rate_hz is None else float(rate_hz)
    rng = np.random.default_rng(seed)
    lay = paper_layout(float(r)) if layout == "paper" else load_layout(str(layout))
    t = np.arange(int(round(duration * rate_hz)) + 1) / rate_hz
    w, wd = paper_rates(t)
    q = integrate_quaternion(t, w)
    acc_ned = translation * np.stack([np.sin(0.3 * t), np.cos(0.2 * t), 0.5 * np.sin(0.5 * t)], 1)
    f0 = specific_force(q, acc_ned, GRAVITY)
    pos, dirs, cols, units = lay.rows()
    a = design_matrix(pos, dirs)
    quad = np.stack(
        [w[:, 0] ** 2, w[:, 1] ** 2, w[:, 2] ** 2, w[:, 0] * w[:, 1], w[:, 0] * w[:, 2], w[:, 1] * w[:, 2]], 1
    )
    u = np.concatenate([f0, wd, quad], 1)
    y = u @ a.T
    sigma = noise_ug * 1e-6 * GRAVITY * np.sqrt(rate_hz)
    y = y + rng.standard_normal(y.shape) * sigma
    if bias_mps2 > 0:
        y = y + rng.standard_normal(y.shape[1]) * bias_mps2
    rec = Recording(t)

    for j, (c, un) in enumerate(zip(cols, units, strict=True)):
        v = y[:, j] if un in ("m/s^2", "m/s2") else convert(y[:, j], "m/s^2", un)
        rec.add(c, v, un)
    roll, pitch, heading = quat_to_euler(q)
    rec.add("ref_gyro", w, "rad/s")
    rec.add(
        "ref_angular_accel",
        wd,
        "rad/s^2",
        columns=["ref_angular_accel_x", "ref_angular_accel_y", "ref_angular_accel_z"],
    )
    rec.add("ref_accel", f0, "m/s^2")
    rec.add("ref_q", q)
    rec.add("ref_roll", np.degrees(roll))
    rec.add("ref_pitch", np.degrees(pitch))
    rec.add("ref_heading", np.degrees(heading))
    rec.meta.update(
        {
            "rate_hz": rate_hz,
            "layout": lay.name,
            "accel_noise_ug_per_rthz": noise_ug,
            "accel_noise_sigma_mps2": round(float(sigma), 6),
            "accel_bias_sigma_mps2": bias_mps2,
            "frame": "body FRD; positions m; ref_q body->NED",
            "source": "imutool simulator (accel-array)",
            "rates": "paper: wx=0.005t+0.1, wy=0.1 sin(0.1t), wz=2.6 (+0.006(t-8) after 8 s)",
        }
    )
    return rec
