"""The accelerometer's sections of the EKF loop: its white-noise level, the gate, the quasi-inertial low-pass and the
update (roll paper eq. 7–9 and 11–18; VQF's low-pass, Laidig & Seel 2023; kernel.py's module docstring).

Frames and units: body FRD, world NED, I the gyro-only integrated frame (q_I, S_QI); specific force m/s² (reads −g
on z at rest), rates rad/s, time s. R = R(q) body→NED and RI = R(q_I) are 3×3 scratch arrays the kernel owns.
"""

from __future__ import annotations

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.jit.decorators import njit
from imutool.attitude.covariance import _drop_vertical, _propagate_pending, _reset_cov, _shear_cov, _vertical_forms
from imutool.attitude.layout import (
    F_ACC_REJ,
    F_ACC_USED,
    INLINED,
    LP_TAU_GROWTH,
    LP_TAU_START,
    P_ACC_ADAPT,
    P_ACC_BIAS_DEV,
    P_ACC_GATE,
    P_ACC_HEAD,
    P_ACC_LAG,
    P_ACC_NIS,
    P_ACC_NOISE,
    P_ACC_NOISE_RISE,
    P_ACC_SOFT,
    P_ACC_TAU,
    P_ACC_VBIAS,
    P_ACC_WN_GAIN,
    P_BIAS_HOLD,
    P_GRAVITY,
    P_NIS_TAU,
    P_REJ_TIMEOUT,
    P_SHOCK_MAX,
    P_TILT_WIN,
    S_AFLOOR,
    S_APREV,
    S_APREV2,
    S_AREJ_T,
    S_AVAR,
    S_BHOLD,
    S_CNT_A,
    S_GW1,
    S_GW2,
    S_GWN,
    S_GWT,
    S_LPINIT,
    S_LPT,
    S_LPV,
    S_LPY,
    S_NAREJ,
    S_NAVAR,
    S_NIS_A,
    S_NUPD,
    S_QI,
    S_SHOCK_T,
    S_USE_A,
    S_VA_IN,
    S_WV,
    S_WY,
    TRUE,
)
from imutool.attitude.lowpass import _butterworth_gains, _butterworth_step, _low_pass_gain, _low_pass_two_stages
from imutool.attitude.updates import _apply_correction, _vec_update
from imutool.quaternion import rmat


@njit(**INLINED)
def _accel_white_noise(st, prm, ax, ay, az, dt):
    """The accelerometer's white-noise level σ_w² (m²/s⁴, S_AVAR; its floor S_AFLOOR) from the raw sample a (m/s²)."""
    # from second differences (motion cancels to second order: a rotation at ω moves gravity by g·ω²·dt² per step,
    # not g·ω·dt as with first differences): σ_w² ≈ mean ‖a_k − 2a_{k−1} + a_{k−2}‖² / 18 (3 axes × 6σ²), averaged
    # over ~10 s (running mean at start-up)
    if st[S_NAVAR] > 1:
        d0 = ax - 2.0 * st[S_APREV] + st[S_APREV2]
        d1 = ay - 2.0 * st[S_APREV + 1] + st[S_APREV2 + 1]
        d2 = az - 2.0 * st[S_APREV + 2] + st[S_APREV2 + 2]
        dd = (d0 * d0 + d1 * d1 + d2 * d2) * (1.0 / 18.0)
        if dd < 100.0 * st[S_AVAR] or st[S_NAVAR] < 10:  # shocks do not inflate the noise estimate
            cnt = st[S_NAVAR] - 1.0
            bw = max(1.0 / cnt, dt / 10.0) if dt > 0 else 1.0 / cnt
            st[S_AVAR] += bw * (dd - st[S_AVAR])
            # the floor: at start-up (running mean) and whenever quieter, the 10-s mean itself; louder, it
            # rises with accel_noise_rise_time (a sensor's noise does not change with the motion)
            if prm[P_ACC_NOISE_RISE] <= 0 or bw > dt / 10.0 or st[S_AVAR] < st[S_AFLOOR]:
                st[S_AFLOOR] = st[S_AVAR]
            else:
                st[S_AFLOOR] += dt / prm[P_ACC_NOISE_RISE] * (st[S_AVAR] - st[S_AFLOOR])
    st[S_NAVAR] += 1.0
    st[S_APREV2], st[S_APREV2 + 1], st[S_APREV2 + 2] = st[S_APREV], st[S_APREV + 1], st[S_APREV + 2]
    st[S_APREV], st[S_APREV + 1], st[S_APREV + 2] = ax, ay, az


@njit(**INLINED)
def _accel_gate(st, prm, R, ax, ay, az, dt, gap):
    """The gate on the compensated force a (m/s², body; finite) and the tilt check's window. Returns (rejected,
    forced back in after reject_timeout s, ‖a‖ m/s², | ‖a‖ − g | m/s²). A rejected sample that is not forced
    counts as rejected (S_NAREJ, S_AREJ_T); the bias is held (S_BHOLD) while ‖a‖ departs from g."""
    na = np.sqrt(ax * ax + ay * ay + az * az)
    dev_a = abs(na - prm[P_GRAVITY])
    if prm[P_ACC_BIAS_DEV] > 0 and dev_a > prm[P_ACC_BIAS_DEV]:
        st[S_BHOLD] = prm[P_BIAS_HOLD]
    elif dt > 0:
        st[S_BHOLD] = max(0.0, st[S_BHOLD] - dt)
    above = prm[P_ACC_GATE] > 0 and dev_a > prm[P_ACC_GATE]
    if above:  # a shock, or sustained acceleration once it lasts longer than shock_max
        st[S_SHOCK_T] += dt
        st[S_BHOLD] = prm[P_BIAS_HOLD]
    else:
        st[S_SHOCK_T] = 0.0
    rej = (above and st[S_SHOCK_T] <= prm[P_SHOCK_MAX]) or not na > 0
    force = st[S_AREJ_T] >= prm[P_REJ_TIMEOUT]
    if prm[P_TILT_WIN] > 0 and (not rej or force):
        # tilt check: the compensated force in the world frame with the current attitude, two first-order
        # stages of τ/2 (running mean until τ/2 is reached); its mean is −g·ẑ if the attitude is right,
        # since a bounded velocity averages the acceleration out (|Δv| / τ)
        fw0 = R[0, 0] * ax + R[0, 1] * ay + R[0, 2] * az
        fw1 = R[1, 0] * ax + R[1, 1] * ay + R[1, 2] * az
        fw2 = R[2, 0] * ax + R[2, 1] * ay + R[2, 2] * az
        st[S_GWN] += 1.0
        al = _low_pass_gain(dt, 0.5 * prm[P_TILT_WIN], st[S_GWN])
        _low_pass_two_stages(st, S_GW1, S_GW2, fw0, fw1, fw2, al)
        if not gap:  # the time the window has seen (a gap restarts it)
            st[S_GWT] += max(dt, 0.0)
    if rej and not force:  # a shock: flagged as rejected, and a due update waits for the next sample
        st[S_NAREJ] += 1
        st[S_AREJ_T] += dt
    return rej, force, na, dev_a


@njit(**INLINED)
def _accel_low_pass(st, prm, RI, ax, ay, az, dt, aided, ri_now):
    """VQF's idea: the specific force a (m/s², body) low-passed in the gyro-integrated frame I, where gravity is
    (nearly) constant and translational acceleration averages out; second-order Butterworth, delay τ =
    accel_lp_tau (a running mean at start-up, a long τ grown from LP_TAU_START). ``aided``: the last velocity-aiding
    interval's force (S_VA_IN, in I) instead. RI = R(q_I) is computed here unless ``ri_now``. With accel_lp_lag,
    the lag weight W (S_WY, S_WV) is advanced too."""
    if not ri_now:
        rmat(st[S_QI], st[S_QI + 1], st[S_QI + 2], st[S_QI + 3], RI)
    if aided:
        i0, i1, i2 = st[S_VA_IN], st[S_VA_IN + 1], st[S_VA_IN + 2]
    else:
        i0 = RI[0, 0] * ax + RI[0, 1] * ay + RI[0, 2] * az
        i1 = RI[1, 0] * ax + RI[1, 1] * ay + RI[1, 2] * az
        i2 = RI[2, 0] * ax + RI[2, 1] * ay + RI[2, 2] * az
    if st[S_LPINIT] == 0.0:
        st[S_LPV], st[S_LPV + 1], st[S_LPV + 2] = 0.0, 0.0, 0.0
        st[S_LPY], st[S_LPY + 1], st[S_LPY + 2] = i0, i1, i2
        st[S_LPT] = 0.0
        for m in range(18):
            st[S_WV + m] = 0.0
    st[S_LPINIT] += 1.0
    st[S_USE_A] += 1.0
    st[S_LPT] += max(dt, 0.0)
    tau = prm[P_ACC_TAU]
    if tau > LP_TAU_START:  # a long low-pass starts short (its lag is learned while it is short)
        tau = min(tau, max(LP_TAU_START, LP_TAU_GROWTH * st[S_LPT]))
    lm, la, le = _butterworth_gains(dt, tau, st[S_LPINIT])  # running mean at start-up
    st[S_LPV], st[S_LPY] = _butterworth_step(st[S_LPV], st[S_LPY], i0, lm, la, le, dt)
    st[S_LPV + 1], st[S_LPY + 1] = _butterworth_step(st[S_LPV + 1], st[S_LPY + 1], i1, lm, la, le, dt)
    st[S_LPV + 2], st[S_LPY + 2] = _butterworth_step(st[S_LPV + 2], st[S_LPY + 2], i2, lm, la, le, dt)
    if prm[P_ACC_LAG] > 0:
        # lag weight W = Σ_k h_k ∫_{t−k}^{t} R_I dt over the low-pass's weights h: the age-weighted
        # companion of its state, which every row ages by R_I·dt and the homogeneous step then filters
        # (W is the output's companion, W_V the rate's; a constant R_I gives W = τ·R_I)
        dtp = max(dt, 0.0)
        for m in range(9):
            st[S_WY + m] += RI[m // 3, m % 3] * dtp
            st[S_WV + m], st[S_WY + m] = _butterworth_step(st[S_WV + m], st[S_WY + m], 0.0, lm, la, le, dt)


@njit(**INLINED)
def _age_low_pass(st, RI, dt):
    """A row the low-pass skips (NaN, shock) still ages its content (α = 0): W += R_I·dt (s); RI = R(q_I) computed."""
    rmat(st[S_QI], st[S_QI + 1], st[S_QI + 2], st[S_QI + 3], RI)
    for m in range(9):
        st[S_WY + m] += RI[m // 3, m % 3] * dt


@njit(**INLINED)
def _accel_update(st, P, prm, R, RI, MLAG, X33, dx, ax, ay, az, na, dev_a, dt, force, ri_now, ext_meas):
    """The accelerometer update (eq. 7–9, 11–18), when due: z = the low-passed force back in the body frame
    (z = R_Iᵀ·LP; the raw or the smoother's force a m/s² of norm na otherwise), ẑ = Rᵀ(q)·[0, 0, −1], its NIS
    gate, the soft de-weighting, the lag's shear and the projection that keeps heading and the vertical bias out.
    R is refreshed after a correction. Returns the flag bits (F_ACC_USED or F_ACC_REJ)."""
    flag = 0
    use_lp = prm[P_ACC_TAU] > 0
    g = prm[P_GRAVITY]
    st[S_NUPD] += 1
    t_since = dt * st[S_CNT_A]  # since the last accelerometer update (s): the self-check's window weight
    st[S_CNT_A] = 0.0
    n_use = max(st[S_USE_A], 1.0)
    st[S_USE_A] = 0.0
    _propagate_pending(st, P, prm)
    if use_lp and not ext_meas:  # the low-passed vector back in the body frame: z = R_Iᵀ·LP
        if not ri_now:
            rmat(st[S_QI], st[S_QI + 1], st[S_QI + 2], st[S_QI + 3], RI)
        l0, l1, l2 = st[S_LPY], st[S_LPY + 1], st[S_LPY + 2]
        ax = RI[0, 0] * l0 + RI[1, 0] * l1 + RI[2, 0] * l2
        ay = RI[0, 1] * l0 + RI[1, 1] * l1 + RI[2, 1] * l2
        az = RI[0, 2] * l0 + RI[1, 2] * l1 + RI[2, 2] * l2
        na = max(np.sqrt(ax * ax + ay * ay + az * az), 1e-300)
    h0, h1, h2 = -R[2, 0], -R[2, 1], -R[2, 2]
    y0, y1, y2 = ax / na - h0, ay / na - h1, az / na - h2
    # independent error sources add in variance: model floor² + (gain·σ_w/g)²
    sig2 = prm[P_ACC_NOISE] * prm[P_ACC_NOISE]
    if prm[P_ACC_WN_GAIN] > 0:
        sig2 += prm[P_ACC_WN_GAIN] * prm[P_ACC_WN_GAIN] * st[S_AFLOOR] / (g * g)
    if prm[P_ACC_ADAPT] > 0:  # de-weight by the non-gravitational part of ‖a‖
        sig2 *= 1.0 + (dev_a / prm[P_ACC_ADAPT]) ** 2
    # σ is per sample: the low-pass's output stands for the n samples it took in since the last
    # update (R = σ²/n; the NIS still against σ²); a raw sample (no low-pass) is one sample
    sig2_nis = sig2
    if use_lp or ext_meas:
        sig2 /= n_use
    cons = st[S_BHOLD] > 0
    # gravity observes neither heading nor the bias about the vertical: optionally keep the update
    # from moving them through cross-covariances (exact Joseph form for the projected gain)
    vb = prm[P_ACC_VBIAS] == 0.0 and not cons
    va = prm[P_ACC_HEAD] == 0.0
    vdrop = va or vb
    lagh = prm[P_ACC_LAG] > 0 and use_lp and not ext_meas
    if lagh:  # M = R_Iᵀ W: the low-pass output's tilt error per unit bias error (body, s)
        for a_ in range(3):
            for b_ in range(3):
                MLAG[a_, b_] = RI[0, a_] * st[S_WY + b_] + RI[1, a_] * st[S_WY + 3 + b_] + RI[2, a_] * st[S_WY + 6 + b_]
    fa, fx, fb = _vertical_forms(P, -h0, -h1, -h2)  # before the update, error coordinates δθ
    if lagh:  # H = [[h×], [h×]M] is [[h×], 0] in δθ' = δθ + M δb: update there, shear back
        _shear_cov(P, MLAG, 1.0, X33)
    ok, nis = _vec_update(P, h0, h1, h2, y0, y1, y2, sig2, prm[P_ACC_NIS], force, dx, cons, sig2_nis - sig2)
    soft = not ok and prm[P_ACC_SOFT] > 0  # de-weight instead of skipping (flagged as rejected)
    if soft:
        _vec_update(P, h0, h1, h2, y0, y1, y2, sig2 * nis / prm[P_ACC_NIS], 0.0, TRUE, dx, cons, 0.0)
    if lagh:
        _shear_cov(P, MLAG, -1.0, X33)
        if ok or soft:
            for a_ in range(3):
                dx[a_] -= MLAG[a_, 0] * dx[3] + MLAG[a_, 1] * dx[4] + MLAG[a_, 2] * dx[5]
    if (ok or soft) and vdrop:  # in δθ coordinates, so the heading is not moved
        _drop_vertical(P, fa, fx, fb, -h0, -h1, -h2, va, vb, dx)
    if soft:
        _apply_correction(st, dx)
        _reset_cov(P, dx, R[2, 0], R[2, 1], R[2, 2])
        rmat(st[0], st[1], st[2], st[3], R)
    if prm[P_NIS_TAU] > 0 and dt > 0:  # self-check: windowed NIS per degree of freedom
        aw = min(1.0, t_since / prm[P_NIS_TAU])
        st[S_NIS_A] += aw * (min(nis, 1e6) / 3.0 - st[S_NIS_A])
    if ok:
        _apply_correction(st, dx)
        _reset_cov(P, dx, R[2, 0], R[2, 1], R[2, 2])
        rmat(st[0], st[1], st[2], st[3], R)
        st[S_AREJ_T] = 0.0
        flag = F_ACC_USED
    else:  # the NIS gate turned the update away
        flag = F_ACC_REJ
        st[S_NAREJ] += 1
        st[S_AREJ_T] += t_since
    return flag
