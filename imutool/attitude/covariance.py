"""Covariance algebra of the 6×6 error state [δθ, δb] (rad, rad/s): propagation, vertical forms, resets."""

from __future__ import annotations

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.jit.decorators import njit
from imutool.attitude.layout import (
    ATT,
    BIAS,
    INLINED,
    P_BIAS_RW,
    P_GYRO_NOISE,
    P_GYRO_SCALE,
    P_HEAD_SCALE,
    S_DQ,
    S_TACC,
)
from imutool.quaternion import vertical_in_body


@njit
def _propagate_cov(P, phi, T, qa, qb, F, tmp):
    """P ← F P Fᵀ + Q with F = [[Φ, −T I], [0, I]], Q = diag(qa I, qb I). F (returned filled) and tmp: 6×6
    scratch preallocated by the caller (no allocation per sample)."""
    for i in range(6):
        for j in range(6):
            F[i, j] = 0.0
    for i in range(3):
        for j in range(3):
            F[i, j] = phi[i, j]
        F[i, 3 + i] = -T
        F[3 + i, 3 + i] = 1.0
    # FP (only the first three rows differ from P)
    for i in range(3):
        for j in range(6):
            s = 0.0
            for k in range(3):
                s += phi[i, k] * P[k, j]
            tmp[i, j] = s - T * P[3 + i, j]
    for i in range(3, 6):
        for j in range(6):
            tmp[i, j] = P[i, j]
    # (FP)Fᵀ
    for i in range(6):
        for j in range(3):
            s = 0.0
            for k in range(3):
                s += tmp[i, k] * phi[j, k]
            P[i, j] = s - T * tmp[i, 3 + j]
        for j in range(3, 6):
            P[i, j] = tmp[i, j]
    for i in range(3):
        P[i, i] += qa
        P[3 + i, 3 + i] += qb
    for i in range(6):
        for j in range(i + 1, 6):
            m = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = m
            P[j, i] = m


@njit(**INLINED)
def _propagate_pending(st, P, prm):
    """Propagate P over the rotation and time accumulated since its last propagation (S_DQ, S_TACC), if any.
    Process noise (eq. 10) + the gyro scale-factor noise ∝ the angle turned: white rate noise of density ε·|ω|,
    (ε·angle/T)²·T with angle² ≈ 4‖vector part of Δq‖² (small angle); ε_tilt across the world vertical r,
    ε_head along it."""
    T = st[S_TACC]
    if T > 0:
        qa = prm[P_GYRO_NOISE] ** 2 * T
        ang2 = 4.0 * (st[S_DQ + 1] ** 2 + st[S_DQ + 2] ** 2 + st[S_DQ + 3] ** 2)
        qs = prm[P_GYRO_SCALE] ** 2 * ang2 / T
        _propagate_cov_q(P, st[S_DQ], st[S_DQ + 1], st[S_DQ + 2], st[S_DQ + 3], T, qa + qs, prm[P_BIAS_RW] ** 2 * T)
        if prm[P_HEAD_SCALE] > 0 or qs > 0:
            z0, z1, z2 = vertical_in_body(st[0], st[1], st[2], st[3])
            _add_rrt(P, ATT, ATT, prm[P_HEAD_SCALE] ** 2 * ang2 / T - qs, z0, z1, z2)
        st[S_DQ], st[S_DQ + 1], st[S_DQ + 2], st[S_DQ + 3] = 1.0, 0.0, 0.0, 0.0
        st[S_TACC] = 0.0


@njit(**INLINED)
def _propagate_cov_q(P, d0, d1, d2, d3, T, qa, qb):
    """P ← F P Fᵀ + Q as block algebra (the bias block of F is I), F = [[Φ, −T I], [0, I]], Φ = ΔRᵀ with ΔR =
    R(d) the rotation accumulated over T; Q = diag(qa I, qb I):
    P_θθ ← Φ P_θθ Φᵀ − T(Φ P_θb + P_bθ Φᵀ) + T² P_bb + qa I, P_θb ← Φ P_θb − T P_bb, P_bb ← P_bb + qb I.
    Straight-line scalar code; P stays exactly symmetric (upper triangle computed and mirrored)."""
    f00, f11, f22 = 1 - 2 * (d2 * d2 + d3 * d3), 1 - 2 * (d1 * d1 + d3 * d3), 1 - 2 * (d1 * d1 + d2 * d2)
    f01, f10 = 2 * (d1 * d2 + d0 * d3), 2 * (d1 * d2 - d0 * d3)
    f02, f20 = 2 * (d1 * d3 - d0 * d2), 2 * (d1 * d3 + d0 * d2)
    f12, f21 = 2 * (d2 * d3 + d0 * d1), 2 * (d2 * d3 - d0 * d1)
    # blocks A = P_θθ, B = P_θb, C = P_bb; Φ = ΔRᵀ, f_ij = Φ[i, j] = R_ji
    a00 = P[0, 0]
    a01 = P[0, 1]
    a02 = P[0, 2]
    a11 = P[1, 1]
    a12 = P[1, 2]
    a22 = P[2, 2]
    b00 = P[0, 3]
    b01 = P[0, 4]
    b02 = P[0, 5]
    b10 = P[1, 3]
    b11 = P[1, 4]
    b12 = P[1, 5]
    b20 = P[2, 3]
    b21 = P[2, 4]
    b22 = P[2, 5]
    c00 = P[3, 3]
    c01 = P[3, 4]
    c02 = P[3, 5]
    c11 = P[4, 4]
    c12 = P[4, 5]
    c22 = P[5, 5]
    # X = Φ A − T Bᵀ, Y = Φ B − T C
    x00 = f00 * a00 + f01 * a01 + f02 * a02 - T * b00
    x01 = f00 * a01 + f01 * a11 + f02 * a12 - T * b10
    x02 = f00 * a02 + f01 * a12 + f02 * a22 - T * b20
    x10 = f10 * a00 + f11 * a01 + f12 * a02 - T * b01
    x11 = f10 * a01 + f11 * a11 + f12 * a12 - T * b11
    x12 = f10 * a02 + f11 * a12 + f12 * a22 - T * b21
    x20 = f20 * a00 + f21 * a01 + f22 * a02 - T * b02
    x21 = f20 * a01 + f21 * a11 + f22 * a12 - T * b12
    x22 = f20 * a02 + f21 * a12 + f22 * a22 - T * b22
    y00 = f00 * b00 + f01 * b10 + f02 * b20 - T * c00
    y01 = f00 * b01 + f01 * b11 + f02 * b21 - T * c01
    y02 = f00 * b02 + f01 * b12 + f02 * b22 - T * c02
    y10 = f10 * b00 + f11 * b10 + f12 * b20 - T * c01
    y11 = f10 * b01 + f11 * b11 + f12 * b21 - T * c11
    y12 = f10 * b02 + f11 * b12 + f12 * b22 - T * c12
    y20 = f20 * b00 + f21 * b10 + f22 * b20 - T * c02
    y21 = f20 * b01 + f21 * b11 + f22 * b21 - T * c12
    y22 = f20 * b02 + f21 * b12 + f22 * b22 - T * c22
    # P_θθ ← X Φᵀ − T Y + qa I (upper triangle, mirrored), P_θb ← Y, P_bb ← C + qb I
    P[0, 0] = x00 * f00 + x01 * f01 + x02 * f02 - T * y00 + qa
    v = x00 * f10 + x01 * f11 + x02 * f12 - T * y01
    P[0, 1] = v
    P[1, 0] = v
    v = x00 * f20 + x01 * f21 + x02 * f22 - T * y02
    P[0, 2] = v
    P[2, 0] = v
    P[1, 1] = x10 * f10 + x11 * f11 + x12 * f12 - T * y11 + qa
    v = x10 * f20 + x11 * f21 + x12 * f22 - T * y12
    P[1, 2] = v
    P[2, 1] = v
    P[2, 2] = x20 * f20 + x21 * f21 + x22 * f22 - T * y22 + qa
    P[0, 3] = y00
    P[3, 0] = y00
    P[0, 4] = y01
    P[4, 0] = y01
    P[0, 5] = y02
    P[5, 0] = y02
    P[1, 3] = y10
    P[3, 1] = y10
    P[1, 4] = y11
    P[4, 1] = y11
    P[1, 5] = y12
    P[5, 1] = y12
    P[2, 3] = y20
    P[3, 2] = y20
    P[2, 4] = y21
    P[4, 2] = y21
    P[2, 5] = y22
    P[5, 2] = y22
    P[3, 3] = c00 + qb
    P[4, 4] = c11 + qb
    P[5, 5] = c22 + qb


@njit(**INLINED)
def _vertical_forms(P, r0, r1, r2):
    """rᵀ P_θθ r, rᵀ P_θb r, rᵀ P_bb r for a unit vector r (body axes)."""
    a = (
        r0 * r0 * P[0, 0]
        + r1 * r1 * P[1, 1]
        + r2 * r2 * P[2, 2]
        + 2 * (r0 * r1 * P[0, 1] + r0 * r2 * P[0, 2] + r1 * r2 * P[1, 2])
    )
    x = (
        r0 * (r0 * P[0, 3] + r1 * P[0, 4] + r2 * P[0, 5])
        + r1 * (r0 * P[1, 3] + r1 * P[1, 4] + r2 * P[1, 5])
        + r2 * (r0 * P[2, 3] + r1 * P[2, 4] + r2 * P[2, 5])
    )
    b = (
        r0 * r0 * P[3, 3]
        + r1 * r1 * P[4, 4]
        + r2 * r2 * P[5, 5]
        + 2 * (r0 * r1 * P[3, 4] + r0 * r2 * P[3, 5] + r1 * r2 * P[4, 5])
    )
    return a, x, b


@njit(**INLINED)
def _drop_vertical(P, fa, fx, fb, r0, r1, r2, drop_att, drop_bias, dx):
    """Turn the vector update just made into one that leaves the attitude (drop_att) and/or the gyro bias
    (drop_bias) unchanged along r, the world vertical in body axes: gain K' = T K, T = I − Π, Π = diag(α r rᵀ,
    β r rᵀ). Joseph form for that gain is P_opt + Π G Π with G = P_before − P_opt; every block of Π G Π is a
    multiple of r rᵀ: (α², αβ, β²) × rᵀ G_block r. fa, fx, fb: :func:`_vertical_forms` of P before the update."""
    ga, gx, gb = _vertical_forms(P, r0, r1, r2)
    al = 1.0 if drop_att else 0.0
    be = 1.0 if drop_bias else 0.0
    sa, sx, sb = al * (fa - ga), al * be * (fx - gx), be * (fb - gb)
    va = al * (r0 * dx[0] + r1 * dx[1] + r2 * dx[2])
    vb = be * (r0 * dx[3] + r1 * dx[4] + r2 * dx[5])
    dx[0] -= r0 * va
    dx[1] -= r1 * va
    dx[2] -= r2 * va
    dx[3] -= r0 * vb
    dx[4] -= r1 * vb
    dx[5] -= r2 * vb
    if drop_att:
        _add_rrt(P, ATT, ATT, sa, r0, r1, r2)
    if drop_bias:
        _add_rrt(P, BIAS, BIAS, sb, r0, r1, r2)
    if drop_att and drop_bias:  # cross block P_θb (and its transpose P_bθ)
        _add_rrt(P, ATT, BIAS, sx, r0, r1, r2)


@njit(**INLINED)
def _add_rrt(P, i0, j0, s, r0, r1, r2):
    """P[i0:i0+3, j0:j0+3] += s·r rᵀ, mirrored into P[j0:j0+3, i0:i0+3] when that is another block.

    Called by the EKF's sections and by the RTS pass: its flags are its own (numba would otherwise give it the
    flags of whichever caller compiles first in a process, and the RTS pass may compile in another process, see
    imutool/filter_warm.py) — the ones the EKF's sections pass down."""
    r = (r0, r1, r2)
    for i in range(3):
        for j in range(3):
            v = s * r[i] * r[j]
            P[i0 + i, j0 + j] += v
            if i0 != j0:
                P[j0 + j, i0 + i] += v


@njit(**INLINED)
def _reset_cov(P, dx, r0, r1, r2):
    """Error-state reset after the correction dx (rad, body axes) was put into q; r = the world vertical in body
    axes before it. The tilt part of dx, dₜ = dx − (r·dx) r, moves the body-frame vertical; the heading uncertainty
    must move with it, or a tilt correction turns heading variance into tilt variance and roll and pitch come to
    depend on the magnetometer (up to 12° between a run with and one without it on `simulate ship-at-sea`
    before this reset). So P_θθ ← G P_θθ Gᵀ, P_θb ← G P_θb with G = ΔR(dₜ)ᵀ, the rotation dₜ applies, exactly
    orthogonal (a first-order G lets a large heading variance leak through). A heading correction (along r)
    leaves r where it is: G = I. Solà 2017 eq. 287's first-order G = I − ½[dx×] still left half of the leak."""
    v = r0 * dx[0] + r1 * dx[1] + r2 * dx[2]
    # δq = (1, dₜ/2)/‖·‖ as in _apply_correction; G = R(δq)ᵀ
    w, x, y, z = 1.0, 0.5 * (dx[0] - v * r0), 0.5 * (dx[1] - v * r1), 0.5 * (dx[2] - v * r2)
    n2 = w * w + x * x + y * y + z * z
    s = 2.0 / n2
    g00, g01, g02 = 1 - s * (y * y + z * z), s * (x * y + w * z), s * (x * z - w * y)
    g10, g11, g12 = s * (x * y - w * z), 1 - s * (x * x + z * z), s * (y * z + w * x)
    g20, g21, g22 = s * (x * z + w * y), s * (y * z - w * x), 1 - s * (x * x + y * y)
    for j in range(6):  # rows 0–2 of P ← G P (P_θθ and P_θb)
        x0, x1, x2 = P[0, j], P[1, j], P[2, j]
        P[0, j] = g00 * x0 + g01 * x1 + g02 * x2
        P[1, j] = g10 * x0 + g11 * x1 + g12 * x2
        P[2, j] = g20 * x0 + g21 * x1 + g22 * x2
    for i in range(3):  # columns 0–2 of the attitude rows ← (G P_θθ) Gᵀ
        x0, x1, x2 = P[i, 0], P[i, 1], P[i, 2]
        P[i, 0] = g00 * x0 + g01 * x1 + g02 * x2
        P[i, 1] = g10 * x0 + g11 * x1 + g12 * x2
        P[i, 2] = g20 * x0 + g21 * x1 + g22 * x2
    v = 0.5 * (P[0, 1] + P[1, 0])
    P[0, 1] = v
    P[1, 0] = v
    v = 0.5 * (P[0, 2] + P[2, 0])
    P[0, 2] = v
    P[2, 0] = v
    v = 0.5 * (P[1, 2] + P[2, 1])
    P[1, 2] = v
    P[2, 1] = v
    for i in range(3):  # P_bθ = P_θbᵀ
        for j in range(3, 6):
            P[j, i] = P[i, j]


@njit(**INLINED)
def _shear_cov(P, M, s, X):
    """P ← T P Tᵀ with T = [[I, s·M], [0, I]]: the covariance in error coordinates δθ' = δθ + s·M δb (M 3×3;
    s = 1 there, s = −1 back). P_bb is unchanged, P'_ab = X = P_ab + s·M P_bb, P'_aa = P_aa + s(P_ab Mᵀ + M Xᵀ).
    X: a 3×3 scratch array."""
    for i in range(3):
        for j in range(3):
            X[i, j] = P[i, 3 + j] + s * (M[i, 0] * P[3, 3 + j] + M[i, 1] * P[4, 3 + j] + M[i, 2] * P[5, 3 + j])
    for i in range(3):
        for j in range(i, 3):
            v = P[i, j] + s * (
                P[i, 3] * M[j, 0]
                + P[i, 4] * M[j, 1]
                + P[i, 5] * M[j, 2]
                + M[i, 0] * X[j, 0]
                + M[i, 1] * X[j, 1]
                + M[i, 2] * X[j, 2]
            )
            P[i, j] = v
            P[j, i] = v
    for i in range(3):
        for j in range(3):
            P[i, 3 + j] = X[i, j]
            P[3 + j, i] = X[i, j]
