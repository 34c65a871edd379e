"""The EKF's per-sample outputs (q, bias, roll/pitch/heading σ in rad) and its self-check flag."""

from __future__ import annotations

import numpy as np
from numba import njit

from imutool.attitude.layout import (
    _FASTMATH,
    P_NIS_LIMIT,
    P_TILT_LIM,
    P_TILT_WIN,
    S_GW2,
    S_GWT,
    S_NIS_A,
    S_NIS_M,
    S_NTILT,
    S_TILTMAX,
)


@njit(fastmath=_FASTMATH, error_model="numpy", inline="always")
def output_step(st, P, prm, q_out, b_out, std_out, k):
    """Write sample k's quaternion, bias and roll/pitch/heading σ (rad), and run the self-check (windowed NIS, the
    tilt check). Returns whether the filter is inconsistent at this sample."""
    for i in range(4):
        q_out[k, i] = st[i]
    for i in range(3):
        b_out[k, i] = st[4 + i]
    # Euler-angle σ: δ(φ,θ,ψ) = E δθ, E the body-rate → Euler-rate matrix (ZYX)
    # sin/cos of roll and pitch straight from R(q) (no transcendental per sample)
    q0, q1, q2, q3 = st[0], st[1], st[2], st[3]
    r21, r22 = 2 * (q0 * q1 + q2 * q3), 1 - 2 * (q1 * q1 + q2 * q2)
    hr = np.sqrt(r21 * r21 + r22 * r22)
    if hr > 1e-12:
        sr, cr = r21 / hr, r22 / hr
    else:
        sr, cr = 0.0, 1.0
    sp = min(1.0, max(-1.0, 2 * (q0 * q2 - q3 * q1)))
    cp = max(np.sqrt(1 - sp * sp), 1e-6)
    tp = sp / cp
    e00, e01, e02 = 1.0, sr * tp, cr * tp
    e11, e12 = cr, -sr
    e21, e22 = sr / cp, cr / cp
    v0 = (
        e00 * (e00 * P[0, 0] + e01 * P[1, 0] + e02 * P[2, 0])
        + e01 * (e00 * P[0, 1] + e01 * P[1, 1] + e02 * P[2, 1])
        + e02 * (e00 * P[0, 2] + e01 * P[1, 2] + e02 * P[2, 2])
    )
    v1 = e11 * e11 * P[1, 1] + 2 * e11 * e12 * P[1, 2] + e12 * e12 * P[2, 2]
    v2 = e21 * e21 * P[1, 1] + 2 * e21 * e22 * P[1, 2] + e22 * e22 * P[2, 2]
    std_out[k, 0] = np.sqrt(max(v0, 0.0))
    std_out[k, 1] = np.sqrt(max(v1, 0.0))
    std_out[k, 2] = np.sqrt(max(v2, 0.0))
    bad = prm[P_NIS_LIMIT] > 0 and (st[S_NIS_A] > prm[P_NIS_LIMIT] or st[S_NIS_M] > prm[P_NIS_LIMIT])
    if prm[P_TILT_WIN] > 0 and st[S_GWT] >= prm[P_TILT_WIN]:
        # the low-passed world force against the estimate's vertical: flagged beyond √(limit² + (3 σ)²), σ² the
        # estimate's roll + pitch variance; tan x ≥ x keeps the arctangent off the common path
        h2 = st[S_GW2] * st[S_GW2] + st[S_GW2 + 1] * st[S_GW2 + 1]
        vz = -st[S_GW2 + 2]
        tan2 = h2 / (vz * vz) if vz > 0.0 else 1e12
        st[S_TILTMAX] = max(st[S_TILTMAX], tan2)
        lim2 = prm[P_TILT_LIM] * prm[P_TILT_LIM] + 9.0 * (max(v0, 0.0) + max(v1, 0.0))
        if tan2 > lim2:
            ang = np.arctan2(np.sqrt(h2), vz)
            if ang * ang > lim2:
                bad = True
                st[S_NTILT] += 1
    return bad
