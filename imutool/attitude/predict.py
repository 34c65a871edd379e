"""The EKF's prediction step, every sample (roll paper, eq. 2–6 and 10; kernel.py's module docstring).

One gyro sample (rad/s, body FRD) at time t_k (s): a NaN sample replaced by the last good one, the attitude q
(body→NED) and the gyro-only quaternion q_I integrated over dt_k = t_k − t_{k−1} with the exact exponential
q ← q ⊗ exp(½ ω dt), the rotation and time accumulated for the next covariance propagation (S_DQ, S_TACC; the
multi-rate scheme: P is propagated only before an update), and a step longer than ``gap_dt`` handled as a gap.
"""

from __future__ import annotations

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.jit.decorators import njit
from imutool.attitude.covariance import _propagate_pending
from imutool.attitude.layout import (
    INLINED,
    P_ACC_TAU,
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


@njit(**INLINED)
def _gap(st, P, prm, dt):
    """A step of dt (s) longer than gap_dt: the attitude variance grows by (gap_rate_sigma·dt)² (rad², at most 10)
    and what spans samples restarts — the tilt check's window, a candidate new field, the quasi-inertial low-pass
    (its frame I lost the gap's rotation) and the sums the next updates average."""
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


@njit(**INLINED)
def _predict(st, P, prm, tk, gk0, gk1, gk2, cov_every_sample):
    """Predict (eq. 2–6, 10) with the gyro sample g_k (rad/s) at time tk (s). Returns the sample as used (a NaN one
    replaced by the previous), dt (s), the bias-free rate over the step w (rad/s; ``gyro_integration`` weights
    the previous sample by gyro_prev_weight) and whether the step was a gap. The per-sensor sample counters of the
    multi-rate updates advance; P is propagated now only when ``cov_every_sample`` (the smoother stores it)."""
    if not (np.isfinite(gk0) and np.isfinite(gk1) and np.isfinite(gk2)):
        gk0, gk1, gk2 = st[S_GPREV], st[S_GPREV + 1], st[S_GPREV + 2]
        st[S_NGNAN] += 1
    if st[S_INIT] == 0.0:
        st[S_TPREV] = tk
        st[S_GPREV], st[S_GPREV + 1], st[S_GPREV + 2] = gk0, gk1, gk2
    dt = tk - st[S_TPREV]
    wp = prm[P_GYRO_PREV_W]  # weight of the previous gyro sample over the step (0.5: trapezoid, 0: rectangular)
    wc = 1.0 - wp
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
        if prm[P_ACC_TAU] > 0:  # the quasi-inertial frame of the accelerometer's low-pass
            a0, a1, a2, a3 = qmul(st[S_QI], st[S_QI + 1], st[S_QI + 2], st[S_QI + 3], e0, e1, e2, e3)
            nq = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3)
            st[S_QI], st[S_QI + 1], st[S_QI + 2], st[S_QI + 3] = a0 / nq, a1 / nq, a2 / nq, a3 / nq
    if gap:
        _gap(st, P, prm, dt)
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
    return gk0, gk1, gk2, dt, w0, w1, w2, gap
