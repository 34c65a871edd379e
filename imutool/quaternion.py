"""Scalar quaternion steps for the numba kernels (q = [w, x, y, z] body→NED, FRD/NED; rad, s)."""

from __future__ import annotations

import numpy as np

from formats.jit.decorators import njit


@njit(inline="always")  # small and on the per-sample path: compiled into each caller
def qmul(a0, a1, a2, a3, b0, b1, b2, b3):
    return (
        a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
        a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
        a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
        a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
    )


SERIES_ANGLE2 = 4e-4  # rad²: below this squared angle a rotation vector's exponential is its series (rotvec_quat)


@njit(inline="always")  # small and on the per-sample path: compiled into each caller
def rotvec_quat(x, y, z):
    """Unit quaternion of the rotation vector (x, y, z) rad (exact exponential)."""
    a2 = x * x + y * y + z * z
    if a2 < SERIES_ANGLE2:  # |a| < 0.02 rad: Taylor series, truncation < 1e-15 (no sin/cos per sample)
        s = 0.5 - a2 * (1.0 / 48.0) + a2 * a2 * (1.0 / 3840.0)
        return 1.0 - a2 * 0.125 + a2 * a2 * (1.0 / 384.0), s * x, s * y, s * z
    a = np.sqrt(a2)
    s = np.sin(0.5 * a) / a
    return np.cos(0.5 * a), s * x, s * y, s * z


@njit(inline="always")  # small and on the per-sample path: compiled into each caller
def qturn(a0, a1, a2, a3, x, y, z):
    """The unit quaternion a ⊗ exp(x, y, z) (a rotation vector in rad, body axes), renormalised: one step of a
    gyro integration."""
    e0, e1, e2, e3 = rotvec_quat(x, y, z)
    a0, a1, a2, a3 = qmul(a0, a1, a2, a3, e0, e1, e2, e3)
    nq = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3)
    return a0 / nq, a1 / nq, a2 / nq, a3 / nq


@njit(inline="always")  # small and on the per-sample path: compiled into each caller
def vertical_in_body(q0, q1, q2, q3):
    """The world vertical (NED down) in body axes for q body→NED: the third row of R(q)."""
    return 2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), 1 - 2 * (q1 * q1 + q2 * q2)


@njit(inline="always")  # small and on the per-sample path: compiled into each caller
def atan_series(t):
    """atan(t) for |t| ≤ 0.1: odd Taylor series to t¹⁷ (truncation < |t|¹⁹/19 ≈ 5e-21, below 1 ulp)."""
    u = t * t
    return t * (
        1.0
        - u
        * (
            1.0 / 3.0
            - u
            * (
                1.0 / 5.0
                - u
                * (
                    1.0 / 7.0
                    - u * (1.0 / 9.0 - u * (1.0 / 11.0 - u * (1.0 / 13.0 - u * (1.0 / 15.0 - u * (1.0 / 17.0)))))
                )
            )
        )
    )


@njit(inline="always")  # small and on the per-sample path: compiled into each caller
def fast_atan2(y, x):
    """atan2(y, x) in [−π, π] (≈ 1 ulp) with no library call: a libm call inside the EKF loop costs ~150 ns per
    sample in register spills, the call itself ~40 ns. Hot path (small heading innovation): x > 0, |y| ≤ 0.1 x →
    series of y/x. Otherwise t = min/max(|x|, |y|) ∈ [0, 1] is reduced by three angle halvings,
    atan t = 2 atan(t / (1 + √(1 + t²))) (→ |t| ≤ tan(π/32) < 0.1), then octant/quadrant fixed."""
    if x > 0 and abs(y) <= 0.1 * x:
        return atan_series(y / x)
    ax, ay = abs(x), abs(y)
    swap = ay > ax
    t = (ax / ay if swap else ay / ax) if ax > 0 or ay > 0 else 0.0  # atan2(±0, ±0) = ±0 or ±π, as libm
    for _ in range(3):
        t = t / (1.0 + np.sqrt(1.0 + t * t))
    a = 8.0 * atan_series(t)
    if swap:
        a = 0.5 * np.pi - a
    if np.signbit(x):
        a = np.pi - a
    return -a if np.signbit(y) else a


@njit(inline="always")  # small and on the per-sample path: compiled into each caller
def rmat(q0, q1, q2, q3, r):
    r[0, 0] = 1 - 2 * (q2 * q2 + q3 * q3)
    r[0, 1] = 2 * (q1 * q2 - q0 * q3)
    r[0, 2] = 2 * (q1 * q3 + q0 * q2)
    r[1, 0] = 2 * (q1 * q2 + q0 * q3)
    r[1, 1] = 1 - 2 * (q1 * q1 + q3 * q3)
    r[1, 2] = 2 * (q2 * q3 - q0 * q1)
    r[2, 0] = 2 * (q1 * q3 - q0 * q2)
    r[2, 1] = 2 * (q2 * q3 + q0 * q1)
    r[2, 2] = 1 - 2 * (q1 * q1 + q2 * q2)


@njit(inline="always")  # small and on the per-sample path: compiled into each caller
def rotate(q0, q1, q2, q3, f0, f1, f2):
    """R(q) f: the body vector f in the world frame, for q body→NED; the same operations as :func:`rmat` and the
    product row by row, without the matrix in memory."""
    r00 = 1 - 2 * (q2 * q2 + q3 * q3)
    r01 = 2 * (q1 * q2 - q0 * q3)
    r02 = 2 * (q1 * q3 + q0 * q2)
    r10 = 2 * (q1 * q2 + q0 * q3)
    r11 = 1 - 2 * (q1 * q1 + q3 * q3)
    r12 = 2 * (q2 * q3 - q0 * q1)
    r20 = 2 * (q1 * q3 - q0 * q2)
    r21 = 2 * (q2 * q3 + q0 * q1)
    r22 = 1 - 2 * (q1 * q1 + q2 * q2)
    return r00 * f0 + r01 * f1 + r02 * f2, r10 * f0 + r11 * f1 + r12 * f2, r20 * f0 + r21 * f1 + r22 * f2


def vertical_rate(q: np.ndarray, om: np.ndarray) -> np.ndarray:
    """(R(q) ω)_z per sample: the rate (rad/s) about the world vertical of the body rates ``om`` (N,3) for q (N,4)
    body→NED, R's third row (2(xz − wy), 2(yz + wx), 1 − 2(x² + y²)) times ω, row by row, in place (the same
    operations as the row's products and sums in one expression: the same bits)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    out = x * z
    out -= w * y
    out *= 2.0
    out *= om[:, 0]
    part = y * z
    part += w * x
    part *= 2.0
    part *= om[:, 1]
    out += part
    np.multiply(x, x, out=part)
    part += y * y
    part *= 2.0
    np.subtract(1.0, part, out=part)
    part *= om[:, 2]
    out += part
    return out
