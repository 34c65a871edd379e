"""Rest detection and the zero-rate pseudo-measurement of the gyro bias (beyond the paper; docs/attitude.md).

Still = every axis of the bias-free gyro rate below ``rest_gyro`` (rad/s) and | ‖a‖ − g | below ``rest_accel``
(m/s²) for ``rest_time`` s; then the mean gyro rate of the still samples since the last rest
update is a measurement of the bias b (rad/s), per axis, of σ ``rest_noise`` per sample (R = σ²/n).
"""

from __future__ import annotations

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.jit.decorators import njit
from imutool.attitude.covariance import _propagate_pending, _reset_cov
from imutool.attitude.layout import (
    F_REST,
    INLINED,
    P_GRAVITY,
    P_REST_ACC,
    P_REST_GYRO,
    P_REST_NOISE,
    P_REST_TIME,
    S_CNT_R,
    S_NREST,
    S_REST_T,
    S_RSUM,
    S_USE_R,
)
from imutool.attitude.updates import _apply_correction
from imutool.quaternion import rmat


@njit(**INLINED)
def _rest_update(st, P, prm, dx, R):
    """The zero-rate pseudo-measurement of the bias, per axis, and R refreshed (s, rad/s). Sections of the loop that
    run rarely or only with an option are compiled apart (a call only where they run; the loop compiles faster)."""
    _propagate_pending(st, P, prm)
    # σ per sample: the update is the mean rate of the still samples since the last one, and
    # stands for them (R = σ²/n; a vibration at the update rate averages out, not aliases)
    n_use = st[S_USE_R]
    r_rest = prm[P_REST_NOISE] ** 2 / n_use
    st[S_CNT_R], st[S_USE_R] = 0.0, 0.0
    for i in range(3):
        s_ = P[3 + i, 3 + i] + r_rest
        yy = st[S_RSUM + i] / n_use - st[4 + i]
        for j in range(6):
            dx[j] = P[j, 3 + i] / s_ * yy
        for a_ in range(6):
            for b_ in range(a_, 6):
                v = P[a_, b_] - P[a_, 3 + i] * P[b_, 3 + i] / s_
                P[a_, b_] = v
                P[b_, a_] = v
        _apply_correction(st, dx)
        _reset_cov(P, dx, R[2, 0], R[2, 1], R[2, 2])
    st[S_RSUM], st[S_RSUM + 1], st[S_RSUM + 2] = 0.0, 0.0, 0.0
    rmat(st[0], st[1], st[2], st[3], R)


@njit(**INLINED)
def _rest(st, P, prm, dx, R, gk0, gk1, gk2, ax, ay, az, dt, update_every):
    """Rest detection at one sample (gyro g_k rad/s, accelerometer a m/s², dt s; called where rest_time > 0 and the
    accelerometer sample is finite): the still samples' rates summed, the update when due (R is refreshed after
    it). Returns the flag bits (F_REST while at rest)."""
    flag = 0
    still = (
        abs(gk0 - st[4]) < prm[P_REST_GYRO]
        and abs(gk1 - st[5]) < prm[P_REST_GYRO]
        and abs(gk2 - st[6]) < prm[P_REST_GYRO]
        and abs(np.sqrt(ax * ax + ay * ay + az * az) - prm[P_GRAVITY]) < prm[P_REST_ACC]
    )
    st[S_REST_T] = st[S_REST_T] + dt if still else 0.0
    if st[S_REST_T] >= prm[P_REST_TIME]:
        flag = F_REST
        st[S_NREST] += 1
        st[S_USE_R] += 1.0
        st[S_RSUM] += gk0
        st[S_RSUM + 1] += gk1
        st[S_RSUM + 2] += gk2
        if st[S_CNT_R] >= update_every:
            _rest_update(st, P, prm, dx, R)
    elif st[S_USE_R] > 0:  # the rest ended between updates: its samples are not carried to the next rest
        st[S_USE_R] = 0.0
        st[S_RSUM], st[S_RSUM + 1], st[S_RSUM + 2] = 0.0, 0.0, 0.0
    return flag
