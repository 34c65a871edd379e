"""Magnetometer calibration on a ship: a heading swing (the sensor turns about the near-vertical only).

Model (same as the sphere fit): m = A (m_meas − b), with the horizontal block estimated and the vertical terms
taken from a prior:

    b = [bx, by, bz_prior],   A = [[a11, a12, 0], [a12, a22, 0], [0, 0, a33_prior]]

Roll φ and pitch θ come from the accelerometer, φ = atan2(−f_y, −f_z), θ = atan2(f_x, √(f_y² + f_z²))
(FRD, specific force, at rest/slow motion), and level the corrected field: h = R_y(θ) R_x(φ) m. The residuals
are r_h = |h_xy| − H (horizontal field) and r_v = h_z − Z (vertical field, a free parameter), minimised with
scipy.optimize.least_squares (starting from a 2-D algebraic ellipse fit of the horizontal components).
Scale: H = given horizontal field (µT) or, when not given, det(A_xy) = 1 (heading does not depend on the scale).
Magnetic heading ψ = atan2(−h_y, h_x).

What a swing cannot observe (reported with the fit): bz and a33 (the vertical channel sees a nearly constant
field; only their combination a33 (m_z − bz) = Z is seen), and the cross terms a13, a23 (with m_z nearly
constant, a13 (m_z − bz) is a constant horizontal offset indistinguishable from bx, so the fitted bx, by are the
*effective* horizontal hard iron at this latitude and trim). Small tilts make these weakly observable at best.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from formats.errors import ImutoolError

from .magnetometer import COVERAGE_WINDOW, MagFit, check_soft_iron


def roll_pitch_from_accel(f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Roll, pitch (rad) from specific force (N,3) in FRD (reads −g on z when level)."""
    f = np.asarray(f, dtype=float)
    roll = np.arctan2(-f[:, 1], -f[:, 2])
    pitch = np.arctan2(f[:, 0], np.hypot(f[:, 1], f[:, 2]))
    return roll, pitch


def level(m: np.ndarray, roll: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Body-frame vectors (N,3) rotated into the level (heading-only) frame: h = R_y(θ) R_x(φ) m."""
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    x, y, z = m[:, 0], m[:, 1], m[:, 2]
    y1 = cr * y - sr * z
    z1 = sr * y + cr * z
    return np.stack([cp * x + sp * z1, y1, -sp * x + cp * z1], axis=1)


def heading_from_mag(m: np.ndarray, roll: np.ndarray | None = None, pitch: np.ndarray | None = None) -> np.ndarray:
    """Tilt-compensated magnetic heading (deg, [0, 360)) from body-frame field (N,3) µT and roll/pitch (rad)."""
    m = np.asarray(m, dtype=float)
    if roll is None or pitch is None:
        h = m
    else:
        h = level(m, roll, pitch)
    return np.degrees(np.arctan2(-h[:, 1], h[:, 0])) % 360.0


def _ellipse2d(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Algebraic ellipse fit (x, y) → (centre (2,), symmetric 2×2 A with |A (p − c)| ≈ 1)."""
    mx, my = x.mean(), y.mean()
    sc = float(np.sqrt(np.mean((x - mx) ** 2 + (y - my) ** 2)))
    u, v = (x - mx) / sc, (y - my) / sc
    d = np.column_stack([u * u, 2 * u * v, v * v, 2 * u, 2 * v])
    sol, *_ = np.linalg.lstsq(d, np.ones_like(u), rcond=None)
    a, h, bb, p, q = sol
    qm = np.array([[a, h], [h, bb]])
    c = np.linalg.solve(qm, [p, q])  # centre: Q c = −(p, q) with the sign of the equation below
    c = -c
    # (w − c)ᵀ Q (w − c) = 1 + cᵀ Q c for the form wᵀQw + 2 (p,q)·w = 1
    rhs = 1.0 + c @ qm @ c
    qn = qm / rhs
    ev, evec = np.linalg.eigh(qn)
    if np.any(ev <= 0):
        raise ImutoolError("swing fit: the horizontal field does not trace an ellipse (did the vessel turn 360°?)")
    a2 = evec @ np.diag(np.sqrt(ev)) @ evec.T / sc
    return np.array([mx, my]) + sc * c, a2


def calibrate_swing(
    mag_ut: np.ndarray,
    accel: np.ndarray | None = None,
    *,
    horizontal_ut: float | None = None,
    bz_prior: float = 0.0,
    a33_prior: float | None = None,
    min_turn_deg: float = 300.0,
) -> MagFit:
    """2-D (heading swing) hard/soft-iron fit; see the module docstring. mag (N,3) µT; accel (N,3) m/s² FRD.

    a33_prior: vertical scale (default √det A_xy, i.e. the same sensitivity as the horizontal axes).
    Refuses when the horizontal field direction turns through less than ``min_turn_deg``.
    """
    for name, v in (("horizontal field", horizontal_ut), ("vertical soft-iron prior", a33_prior)):
        if v is not None and not (np.isfinite(v) and v > 0):
            raise ImutoolError(f"{name} {v}: must be a positive number")
    if not np.isfinite(bz_prior):
        raise ImutoolError(f"vertical hard-iron prior {bz_prior} µT: must be a finite number")
    m = np.asarray(mag_ut, dtype=float)
    ok = np.all(np.isfinite(m), axis=1)
    warns: list[str] = []
    if accel is not None:
        f = np.asarray(accel, dtype=float)
        ok &= np.all(np.isfinite(f), axis=1)
        roll, pitch = roll_pitch_from_accel(f[ok])
    else:
        roll = pitch = np.zeros(int(ok.sum()))
        warns.append("no accelerometer: the sensor is assumed level (tilt errors go into heading)")
    m = m[ok]
    if len(m) < 20:
        raise ImutoolError(f"swing fit needs at least 20 valid samples; got {len(m)}")
    c2, a2 = _ellipse2d(m[:, 0], m[:, 1])
    # headings of the field, not of the noise: moving means (noise ÷ 5) whose corrected radius is within ±30 % of
    # the fitted ellipse; a motionless recording collapses to the centre or to one heading (as for the sphere)
    w = int(max(1, min(COVERAGE_WINDOW, len(m) // 20)))
    cs = np.cumsum(np.vstack([np.zeros((1, 2)), m[:, :2]]), axis=0)
    u = ((cs[w:] - cs[:-w]) / w - c2) @ a2.T
    u = u[np.abs(np.hypot(u[:, 0], u[:, 1]) - 1.0) <= 0.3]
    ang = np.degrees(np.arctan2(u[:, 1], u[:, 0]))
    counts = np.bincount(((ang + 180) // 10).astype(int) % 36, minlength=36)
    covered = float(np.count_nonzero(counts >= max(1, int(0.05 * len(u) / 36))) * 10)
    if covered < min_turn_deg:
        raise ImutoolError(
            f"the heading swing covers only {covered:.0f}° (< {min_turn_deg:.0f}° needed); "
            "turn the vessel through a full circle"
        )
    h_target = 1.0

    def unpack(p):
        b = np.array([p[0], p[1], bz_prior])
        a = np.array([[p[2], p[3], 0.0], [p[3], p[4], 0.0], [0.0, 0.0, p[5]]])
        return b, a

    def fun(p):
        b, a = unpack(p)
        hl = level((m - b) @ a.T, roll, pitch)
        return np.concatenate([np.hypot(hl[:, 0], hl[:, 1]) - h_target, hl[:, 2] - p[6]])

    a33 = float(np.sqrt(np.linalg.det(a2))) if a33_prior is None else float(a33_prior)
    z0 = float(np.mean(level((m - [c2[0], c2[1], bz_prior]) @ np.diag([a2[0, 0], a2[1, 1], a33]).T, roll, pitch)[:, 2]))
    p0 = np.array([c2[0], c2[1], a2[0, 0], a2[0, 1], a2[1, 1], a33, z0])
    # a33 is a prior (held), so optimise the rest: wrap to keep p[5] fixed
    free = [0, 1, 2, 3, 4, 6]

    def fun_free(q):
        p = p0.copy()
        p[free] = q
        return fun(p)

    sol = least_squares(fun_free, p0[free], method="lm", x_scale="jac")
    p = p0.copy()
    p[free] = sol.x
    b, a = unpack(p)

    why = check_soft_iron(b, a, "swing fit:")
    if why is not None:
        raise ImutoolError(f"{why}; the swing did not determine the soft iron: turn through a full, steady circle")
    det2 = float(np.linalg.det(a[:2, :2]))
    if det2 <= 0:
        raise ImutoolError("swing fit: horizontal soft-iron matrix is not positive-definite (data too noisy?)")
    s = float(horizontal_ut) if horizontal_ut else 1.0 / np.sqrt(det2)
    if a33_prior is None:
        a[2, 2] = np.sqrt(det2)
    a = a * s
    hl = level((m - b) @ a.T, roll, pitch)
    hor = np.hypot(hl[:, 0], hl[:, 1])
    res = hor - np.mean(hor) if not horizontal_ut else hor - s
    n_h = len(m)
    j = sol.jac[:n_h]
    dof = max(1, n_h - j.shape[1])
    s2 = float(sol.fun[:n_h] @ sol.fun[:n_h]) / dof
    try:
        cov = s2 * np.linalg.pinv(sol.jac.T @ sol.jac)
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    except np.linalg.LinAlgError:
        sd = np.full(len(free), np.nan)
    b_std = np.array([sd[0], sd[1], np.nan])
    a_std = np.full((3, 3), np.nan)
    a_std[0, 0], a_std[0, 1], a_std[1, 0], a_std[1, 1] = sd[2] * s, sd[3] * s, sd[3] * s, sd[4] * s
    raw_h = np.hypot(*level(m, roll, pitch)[:, :2].T)
    tilt = float(np.degrees(np.max(np.hypot(roll, pitch))))
    fit = MagFit(
        b=b,
        A=a,
        field_ut=float(np.mean(np.linalg.norm(hl, axis=1))),
        kind="swing-2d",
        residual_rms_ut=float(np.sqrt(np.mean(res**2))),
        residual_rel=float(np.sqrt(np.mean(res**2)) / np.mean(hor)),
        coverage=covered / 360.0,
        n=n_h,
        b_std=b_std,
        A_std=a_std,
        raw_rel_std=float(np.std(raw_h) / np.mean(raw_h)),
        cal_rel_std=float(np.std(hor) / np.mean(hor)),
        reason="heading swing: horizontal hard/soft iron fitted; vertical terms from the prior",
        warnings=warns,
        method="swing",
    )
    fit.extra = {
        "section": {
            "horizontal_field_ut": float(np.mean(hor)),
            "vertical_field_ut": float(np.mean(hl[:, 2])),
            "bz_prior_ut": float(bz_prior),
            "a33_prior": float(a[2, 2]),
            "unobservable": "bz and a33 (only a33 (m_z - bz) is seen); a13, a23 absorbed into effective bx, by",
            "max_tilt_deg": tilt,
        }
    }
    return fit
