"""Measurement updates of the error state: vector (accelerometer, magnetometer), scalar heading, reset."""

from __future__ import annotations

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.jit.decorators import njit
from imutool.attitude.covariance import _add_rrt
from imutool.attitude.layout import ATT, INLINED, S_BIASMAX
from imutool.quaternion import qmul


@njit(**INLINED)
def _vec_update(P, h0, h1, h2, y0, y1, y2, sig2, nis_gate, force, dx, consider_bias=False, nis_extra=0.0):
    """Update with a unit-vector measurement: H = [[h×], 0], R = sig2·I (the zero block of H exploited;
    3×3 innovation covariance inverted in closed form). Returns (accepted, NIS); dx filled. Straight-line code.
    The NIS (and its gate) is taken against S + nis_extra·I: an update standing for n samples has R = σ²/n, and
    its NIS is the one of an update of R = σ² (nis_extra = σ² − σ²/n), so the self-check reads the same at any N."""
    p00, p01, p02, p03, p04, p05 = P[0, 0], P[0, 1], P[0, 2], P[0, 3], P[0, 4], P[0, 5]
    p11, p12, p13, p14, p15 = P[1, 1], P[1, 2], P[1, 3], P[1, 4], P[1, 5]
    p22, p23, p24, p25 = P[2, 2], P[2, 3], P[2, 4], P[2, 5]
    p33, p34, p35 = P[3, 3], P[3, 4], P[3, 5]
    p44, p45 = P[4, 4], P[4, 5]
    p55 = P[5, 5]
    # M = P Hᵀ, row i = h × P[i, :3]
    m00 = h1 * p02 - h2 * p01
    m01 = h2 * p00 - h0 * p02
    m02 = h0 * p01 - h1 * p00
    m10 = h1 * p12 - h2 * p11
    m11 = h2 * p01 - h0 * p12
    m12 = h0 * p11 - h1 * p01
    m20 = h1 * p22 - h2 * p12
    m21 = h2 * p02 - h0 * p22
    m22 = h0 * p12 - h1 * p02
    m30 = h1 * p23 - h2 * p13
    m31 = h2 * p03 - h0 * p23
    m32 = h0 * p13 - h1 * p03
    m40 = h1 * p24 - h2 * p14
    m41 = h2 * p04 - h0 * p24
    m42 = h0 * p14 - h1 * p04
    m50 = h1 * p25 - h2 * p15
    m51 = h2 * p05 - h0 * p25
    m52 = h0 * p15 - h1 * p05
    # S = H M + sig2 I (symmetric: upper triangle only), H rows [h×] = [[0,-h2,h1],[h2,0,-h0],[-h1,h0,0]]
    a = h1 * m20 - h2 * m10 + sig2
    b = h1 * m21 - h2 * m11
    c = h1 * m22 - h2 * m12
    d = h2 * m01 - h0 * m21 + sig2
    e = h2 * m02 - h0 * m22
    f = h0 * m12 - h1 * m02 + sig2
    # W = S⁻¹ (symmetric 3×3, cofactors)
    A = d * f - e * e
    B = c * e - b * f
    C = b * e - c * d
    det = a * A + b * B + c * C
    w00, w01, w02 = A / det, B / det, C / det
    w11, w12, w22 = (a * f - c * c) / det, (b * c - a * e) / det, (a * d - b * b) / det
    wy0 = w00 * y0 + w01 * y1 + w02 * y2
    wy1 = w01 * y0 + w11 * y1 + w12 * y2
    wy2 = w02 * y0 + w12 * y1 + w22 * y2
    an, dn, fn = a + nis_extra, d + nis_extra, f + nis_extra  # S + nis_extra·I, its inverse by cofactors
    An, Bn, Cn = dn * fn - e * e, c * e - b * fn, b * e - c * dn
    detn = an * An + b * Bn + c * Cn
    nis = (
        y0 * (An * y0 + Bn * y1 + Cn * y2)
        + y1 * (Bn * y0 + (an * fn - c * c) * y1 + (b * c - an * e) * y2)
        + y2 * (Cn * y0 + (b * c - an * e) * y1 + (an * dn - b * b) * y2)
    ) / detn
    accepted = not (nis_gate > 0 and nis > nis_gate and not force)
    # straight-line code, no early return (either costs an array refcount per call in the compiled loop): a
    # rejected update runs with a zero gain (P and dx unchanged), a consider (Schmidt) update with a zero bias gain
    # (the bias is neither corrected nor its variance reduced)
    ga = 1.0 if accepted else 0.0
    cb = 0.0 if consider_bias else 1.0
    w00, w01, w02, w11, w12, w22 = ga * w00, ga * w01, ga * w02, ga * w11, ga * w12, ga * w22
    wy0, wy1, wy2 = ga * wy0, ga * wy1, ga * wy2
    dx[0] = m00 * wy0 + m01 * wy1 + m02 * wy2
    dx[1] = m10 * wy0 + m11 * wy1 + m12 * wy2
    dx[2] = m20 * wy0 + m21 * wy1 + m22 * wy2
    dx[3] = cb * (m30 * wy0 + m31 * wy1 + m32 * wy2)
    dx[4] = cb * (m40 * wy0 + m41 * wy1 + m42 * wy2)
    dx[5] = cb * (m50 * wy0 + m51 * wy1 + m52 * wy2)
    # P ← P − K Mᵀ, K = M W
    k00 = m00 * w00 + m01 * w01 + m02 * w02
    k01 = m00 * w01 + m01 * w11 + m02 * w12
    k02 = m00 * w02 + m01 * w12 + m02 * w22
    k10 = m10 * w00 + m11 * w01 + m12 * w02
    k11 = m10 * w01 + m11 * w11 + m12 * w12
    k12 = m10 * w02 + m11 * w12 + m12 * w22
    k20 = m20 * w00 + m21 * w01 + m22 * w02
    k21 = m20 * w01 + m21 * w11 + m22 * w12
    k22 = m20 * w02 + m21 * w12 + m22 * w22
    k30 = cb * (m30 * w00 + m31 * w01 + m32 * w02)
    k31 = cb * (m30 * w01 + m31 * w11 + m32 * w12)
    k32 = cb * (m30 * w02 + m31 * w12 + m32 * w22)
    k40 = cb * (m40 * w00 + m41 * w01 + m42 * w02)
    k41 = cb * (m40 * w01 + m41 * w11 + m42 * w12)
    k42 = cb * (m40 * w02 + m41 * w12 + m42 * w22)
    k50 = cb * (m50 * w00 + m51 * w01 + m52 * w02)
    k51 = cb * (m50 * w01 + m51 * w11 + m52 * w12)
    k52 = cb * (m50 * w02 + m51 * w12 + m52 * w22)
    P[0, 0] = p00 - (k00 * m00 + k01 * m01 + k02 * m02)
    P[0, 1] = P[1, 0] = p01 - (k00 * m10 + k01 * m11 + k02 * m12)
    P[0, 2] = P[2, 0] = p02 - (k00 * m20 + k01 * m21 + k02 * m22)
    P[0, 3] = P[3, 0] = p03 - (k00 * m30 + k01 * m31 + k02 * m32)
    P[0, 4] = P[4, 0] = p04 - (k00 * m40 + k01 * m41 + k02 * m42)
    P[0, 5] = P[5, 0] = p05 - (k00 * m50 + k01 * m51 + k02 * m52)
    P[1, 1] = p11 - (k10 * m10 + k11 * m11 + k12 * m12)
    P[1, 2] = P[2, 1] = p12 - (k10 * m20 + k11 * m21 + k12 * m22)
    P[1, 3] = P[3, 1] = p13 - (k10 * m30 + k11 * m31 + k12 * m32)
    P[1, 4] = P[4, 1] = p14 - (k10 * m40 + k11 * m41 + k12 * m42)
    P[1, 5] = P[5, 1] = p15 - (k10 * m50 + k11 * m51 + k12 * m52)
    P[2, 2] = p22 - (k20 * m20 + k21 * m21 + k22 * m22)
    P[2, 3] = P[3, 2] = p23 - (k20 * m30 + k21 * m31 + k22 * m32)
    P[2, 4] = P[4, 2] = p24 - (k20 * m40 + k21 * m41 + k22 * m42)
    P[2, 5] = P[5, 2] = p25 - (k20 * m50 + k21 * m51 + k22 * m52)
    P[3, 3] = p33 - (k30 * m30 + k31 * m31 + k32 * m32)
    P[3, 4] = P[4, 3] = p34 - (k30 * m40 + k31 * m41 + k32 * m42)
    P[3, 5] = P[5, 3] = p35 - (k30 * m50 + k31 * m51 + k32 * m52)
    P[4, 4] = p44 - (k40 * m40 + k41 * m41 + k42 * m42)
    P[4, 5] = P[5, 4] = p45 - (k40 * m50 + k41 * m51 + k42 * m52)
    P[5, 5] = p55 - (k50 * m50 + k51 * m51 + k52 * m52)
    return accepted, nis


@njit(**INLINED)
def _heading_update(P, r0, r1, r2, y, sig2, dx, consider_bias=False, nis_extra=0.0, bias_gate2=0.0, sig2_0=0.0):
    """Scalar heading update H = [r, 0] (r = world vertical in body axes) with the correction projected on the world
    vertical (Joseph form). Straight-line code. Returns the NIS y² / (S + nis_extra) (see :func:`_vec_update`).
    The bias is left as it is (a Schmidt update) with ``consider_bias``, or where y² > bias_gate2 · (rᵀP r +
    sig2_0): an innovation beyond the gate against the undisturbed σ² ``sig2_0`` (rad²)."""
    p00, p01, p02, p03, p04, p05 = P[0, 0], P[0, 1], P[0, 2], P[0, 3], P[0, 4], P[0, 5]
    p11, p12, p13, p14, p15 = P[1, 1], P[1, 2], P[1, 3], P[1, 4], P[1, 5]
    p22, p23, p24, p25 = P[2, 2], P[2, 3], P[2, 4], P[2, 5]
    p33, p34, p35 = P[3, 3], P[3, 4], P[3, 5]
    p44, p45 = P[4, 4], P[4, 5]
    p55 = P[5, 5]
    m0 = p00 * r0 + p01 * r1 + p02 * r2
    m1 = p01 * r0 + p11 * r1 + p12 * r2
    m2 = p02 * r0 + p12 * r1 + p22 * r2
    m3 = p03 * r0 + p13 * r1 + p23 * r2
    m4 = p04 * r0 + p14 * r1 + p24 * r2
    m5 = p05 * r0 + p15 * r1 + p25 * r2
    hm = m0 * r0 + m1 * r1 + m2 * r2
    S = hm + sig2
    ka = hm / S  # world-vertical part of the attitude gain
    kb = (m3 * r0 + m4 * r1 + m5 * r2) / S  # world-vertical part of the bias gain
    if consider_bias or (bias_gate2 > 0 and y * y > bias_gate2 * (hm + sig2_0)):
        kb = 0.0  # Schmidt: Joseph form with a zero bias gain is exact for that suboptimal gain
    k0, k1, k2, k3, k4, k5 = r0 * ka, r1 * ka, r2 * ka, r0 * kb, r1 * kb, r2 * kb
    dx[0], dx[1], dx[2], dx[3], dx[4], dx[5] = k0 * y, k1 * y, k2 * y, k3 * y, k4 * y, k5 * y
    # Joseph: P ← (I − K H) P (I − K H)ᵀ + K sig2 Kᵀ = P − K Mᵀ − M Kᵀ + S K Kᵀ
    P[0, 0] = p00 - k0 * m0 - m0 * k0 + S * k0 * k0
    v = p01 - k0 * m1 - m0 * k1 + S * k0 * k1
    P[0, 1] = v
    P[1, 0] = v
    v = p02 - k0 * m2 - m0 * k2 + S * k0 * k2
    P[0, 2] = v
    P[2, 0] = v
    v = p03 - k0 * m3 - m0 * k3 + S * k0 * k3
    P[0, 3] = v
    P[3, 0] = v
    v = p04 - k0 * m4 - m0 * k4 + S * k0 * k4
    P[0, 4] = v
    P[4, 0] = v
    v = p05 - k0 * m5 - m0 * k5 + S * k0 * k5
    P[0, 5] = v
    P[5, 0] = v
    P[1, 1] = p11 - k1 * m1 - m1 * k1 + S * k1 * k1
    v = p12 - k1 * m2 - m1 * k2 + S * k1 * k2
    P[1, 2] = v
    P[2, 1] = v
    v = p13 - k1 * m3 - m1 * k3 + S * k1 * k3
    P[1, 3] = v
    P[3, 1] = v
    v = p14 - k1 * m4 - m1 * k4 + S * k1 * k4
    P[1, 4] = v
    P[4, 1] = v
    v = p15 - k1 * m5 - m1 * k5 + S * k1 * k5
    P[1, 5] = v
    P[5, 1] = v
    P[2, 2] = p22 - k2 * m2 - m2 * k2 + S * k2 * k2
    v = p23 - k2 * m3 - m2 * k3 + S * k2 * k3
    P[2, 3] = v
    P[3, 2] = v
    v = p24 - k2 * m4 - m2 * k4 + S * k2 * k4
    P[2, 4] = v
    P[4, 2] = v
    v = p25 - k2 * m5 - m2 * k5 + S * k2 * k5
    P[2, 5] = v
    P[5, 2] = v
    P[3, 3] = p33 - k3 * m3 - m3 * k3 + S * k3 * k3
    v = p34 - k3 * m4 - m3 * k4 + S * k3 * k4
    P[3, 4] = v
    P[4, 3] = v
    v = p35 - k3 * m5 - m3 * k5 + S * k3 * k5
    P[3, 5] = v
    P[5, 3] = v
    P[4, 4] = p44 - k4 * m4 - m4 * k4 + S * k4 * k4
    v = p45 - k4 * m5 - m4 * k5 + S * k4 * k5
    P[4, 5] = v
    P[5, 4] = v
    P[5, 5] = p55 - k5 * m5 - m5 * k5 + S * k5 * k5
    return y * y / (S + nis_extra)


@njit(**INLINED)
def _reset_heading(st, P, r0, r1, r2, y, s2):
    """Take a heading outright: turn q by y (rad) about the world vertical and let P forget the heading (its
    covariance along r, the world vertical in body axes, with everything) before setting its variance to s2
    (rad²): P_θθ ← (I − r rᵀ) P_θθ (I − r rᵀ) + s2 r rᵀ, P_θb ← (I − r rᵀ) P_θb."""
    c, s = np.cos(0.5 * y), np.sin(0.5 * y)
    q0, q1, q2, q3 = qmul(c, 0.0, 0.0, s, st[0], st[1], st[2], st[3])
    n = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    st[0], st[1], st[2], st[3] = q0 / n, q1 / n, q2 / n, q3 / n
    r = (r0, r1, r2)
    for j in range(6):  # rows: (I − r rᵀ) applied to the attitude rows
        v = r0 * P[0, j] + r1 * P[1, j] + r2 * P[2, j]
        for i in range(3):
            P[i, j] -= r[i] * v
    for i in range(6):  # columns: the same on the attitude columns
        v = P[i, 0] * r0 + P[i, 1] * r1 + P[i, 2] * r2
        for j in range(3):
            P[i, j] -= v * r[j]
    _add_rrt(P, ATT, ATT, s2, r0, r1, r2)


@njit(**INLINED)
def _apply_correction(st, dx):
    qc0, qc1, qc2, qc3 = 1.0, 0.5 * dx[0], 0.5 * dx[1], 0.5 * dx[2]
    q0, q1, q2, q3 = qmul(st[0], st[1], st[2], st[3], qc0, qc1, qc2, qc3)
    n = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    st[0], st[1], st[2], st[3] = q0 / n, q1 / n, q2 / n, q3 / n
    # no loop (an array refcount per call); without a bound a NaN stays NaN, as before (min/max would make it −inf)
    bm = st[S_BIASMAX]
    b0, b1, b2 = st[4] + dx[3], st[5] + dx[4], st[6] + dx[5]
    st[4] = min(bm, max(-bm, b0)) if bm > 0 else b0
    st[5] = min(bm, max(-bm, b1)) if bm > 0 else b1
    st[6] = min(bm, max(-bm, b2)) if bm > 0 else b2
