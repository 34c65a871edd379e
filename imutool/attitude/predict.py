"""The EKF's predict step (paper eq. 2–6, 10): the gyro integrated over each sample interval (rad/s, s)."""

from __future__ import annotations

import numpy as np
from numba import njit

from imutool.attitude.covariance import _propagate_pending
from imutool.attitude.layout import (
    _FASTMATH,
    P_GAP_DT,
    P_GAP_RATE,
    P_GYRO_PREV_W,
    S_CNT_A,
    S_CNT_M,
    S_CNT_R,
    S_DQ,
    S_GPREV,
    S_GWN,
    S_GWT,
    S_INIT,
    S_LPINIT,
    S_MCCNT,
    S_MCT,
    S_MDT,
    S_MNSUM,
    S_MSUM,
    S_NGAPS,
    S_NGNAN,
    S_QI,
    S_RSUM,
    S_TACC,
    S_TPREV,
    S_USE_A,
    S_USE_M,
    S_USE_R,
)
from imutool.quaternion import qmul, rotvec_quat


@njit(fastmath=_FASTMATH, error_model="numpy", inline="always")
def predict_step(st, P, prm, tk, gk0, gk1, gk2, use_lp, cov_every_sample):
    """Predict (paper eq. 2–6, 10) to time ``tk`` (s) with the gyro sample (rad/s; NaN: the last good one): the
    attitude, the gyro-only frame q_I, the rotation and time pending for the covariance, a gap's variance growth
    and restarts. Returns (dt s, gap, ω − b rad/s ×3, the gyro sample used ×3)."""
    wp = prm[P_GYRO_PREV_W]  # weight of the previous gyro sample over the step (0.5: trapezoid, 0: rectangular)
    wc = 1.0 - wp
    if not (np.isfinite(gk0) and np.isfinite(gk1) and np.isfinite(gk2)):
        gk0, gk1, gk2 = st[S_GPREV], st[S_GPREV + 1], st[S_GPREV + 2]
        st[S_NGNAN] += 1
    if st[S_INIT] == 0.0:
        st[S_TPREV] = tk
        st[S_GPREV], st[S_GPREV + 1], st[S_GPREV + 2] = gk0, gk1, gk2
    dt = tk - st[S_TPREV]
    # ---------------- predict (eq. 2–6, 10) ----------------
    w0 = wc * gk0 + wp * st[S_GPREV] - st[4]
    w1 = wc * gk1 + wp * st[S_GPREV + 1] - st[5]
    w2 = wc * gk2 + wp * st[S_GPREV + 2] - st[6]
    if not (np.isfinite(w0) and np.isfinite(w1) and np.isfinite(w2)):
        w0, w1, w2 = 0.0, 0.0, 0.0
    gap = dt > prm[P_GAP_DT]
    dti = prm[P_GAP_DT] if gap else dt
    if dt > 0:
        st[S_MDT] += dti
    if dt > 0:
        e0, e1, e2, e3 = rotvec_quat(w0 * dti, w1 * dti, w2 * dti)
        q0, q1, q2, q3 = qmul(st[0], st[1], st[2], st[3], e0, e1, e2, e3)
        nq = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        st[0], st[1], st[2], st[3] = q0 / nq, q1 / nq, q2 / nq, q3 / nq
        a0, a1, a2, a3 = qmul(st[S_DQ], st[S_DQ + 1], st[S_DQ + 2], st[S_DQ + 3], e0, e1, e2, e3)
        st[S_DQ], st[S_DQ + 1], st[S_DQ + 2], st[S_DQ + 3] = a0, a1, a2, a3
        st[S_TACC] += dt
        if use_lp:
            a0, a1, a2, a3 = qmul(st[S_QI], st[S_QI + 1], st[S_QI + 2], st[S_QI + 3], e0, e1, e2, e3)
            nq = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3)
            st[S_QI], st[S_QI + 1], st[S_QI + 2], st[S_QI + 3] = a0 / nq, a1 / nq, a2 / nq, a3 / nq
    if gap:
        st[S_NGAPS] += 1
        inc = (prm[P_GAP_RATE] * dt) ** 2
        for i in range(3):
            P[i, i] = min(P[i, i] + inc, 10.0)
        st[S_GWN], st[S_GWT] = 0.0, 0.0  # the tilt check's window restarts: no mean across a gap
        st[S_MCCNT], st[S_MCT] = 0.0, 0.0  # so does a candidate new field (the attitude after it is the gyro's)
        st[S_LPINIT] = 0.0  # so does the quasi-inertial low-pass: the frame I lost the gap's rotation
        # and what the next updates average: nothing from before the gap
        st[S_USE_A], st[S_USE_M], st[S_USE_R], st[S_MNSUM] = 0.0, 0.0, 0.0, 0.0
        for i in range(3):
            st[S_MSUM + i], st[S_RSUM + i] = 0.0, 0.0
    st[S_TPREV] = tk
    st[S_GPREV], st[S_GPREV + 1], st[S_GPREV + 2] = gk0, gk1, gk2
    # multi-rate: each sensor is used every N samples, at its first usable sample once due; P is propagated
    # only before an update (and every sample when the smoother stores it)
    st[S_CNT_A] += 1.0
    st[S_CNT_M] += 1.0
    st[S_CNT_R] += 1.0
    if cov_every_sample:
        _propagate_pending(st, P, prm)
    st[S_INIT] = 1.0
    return dt, gap, w0, w1, w2, gk0, gk1, gk2
