"""The EKF's accelerometer: white-noise learning, lever-arm and GNSS compensation, the shock gate, the
quasi-inertial low-pass (VQF's idea) and the update (paper eq. 7–9, 11–18). Specific force m/s², body FRD."""

from __future__ import annotations

import numpy as np
from numba import njit

from imutool.attitude.covariance import _drop_vertical, _propagate_pending, _reset_cov, _shear_cov, _vertical_forms
from imutool.attitude.layout import (
    _FASTMATH,
    F_ACC_REJ,
    F_ACC_USED,
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
    P_LEVER_TAU,
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
    S_LPV,
    S_LPY,
    S_NAREJ,
    S_NAVAR,
    S_NIS_A,
    S_NUPD,
    S_QI,
    S_SHOCK_T,
    S_USE_A,
    S_WDOT,
    S_WINIT,
    S_WLP,
    S_WV,
    S_WY,
    TRUE,
)
from imutool.attitude.lowpass import _butterworth_gains, _butterworth_step, _low_pass_gain, _low_pass_two_stages
from imutool.attitude.updates import _apply_correction, _vec_update
from imutool.quaternion import rmat


@njit(fastmath=_FASTMATH, error_model="numpy", inline="always")
def learn_accel_noise(st, prm, ax, ay, az, dt):
    """The accelerometer's white-noise variance (m²/s⁴) and its floor, from second differences of the raw
    sample (m/s²)."""
    # white-noise level of the accelerometer from second differences (motion cancels to second order:
    # a rotation at ω moves gravity by g·ω²·dt² per step, not g·ω·dt as with first differences):
    # σ_w² ≈ mean ‖a_k − 2a_{k−1} + a_{k−2}‖² / 18 (3 axes × 6σ²), averaged over ~10 s (running mean at
    # start-up)
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


@njit(fastmath=_FASTMATH, error_model="numpy", inline="always")
def lever_rate_step(st, prm, gk0, gk1, gk2, dt):
    """The body rate low-passed (τ = lever_arm_lp_tau s) and differentiated, for the lever-arm compensation."""
    # rotation about the centre: the sensor at r feels ω̇ × r + ω × (ω × r); ω low-passed (τ = lever LP) and
    # differentiated (bias-free rate; the bias cancels in ω̇ and is negligible in ω × (ω × r))
    al = dt / (prm[P_LEVER_TAU] + dt) if prm[P_LEVER_TAU] > 0 else 1.0
    if st[S_WINIT] == 0.0:
        st[S_WLP], st[S_WLP + 1], st[S_WLP + 2] = gk0 - st[4], gk1 - st[5], gk2 - st[6]
        st[S_WINIT] = 1.0
    for i in range(3):
        wi = (gk0 if i == 0 else (gk1 if i == 1 else gk2)) - st[4 + i]
        new = st[S_WLP + i] + al * (wi - st[S_WLP + i])
        st[S_WDOT + i] = (new - st[S_WLP + i]) / dt
        st[S_WLP + i] = new


@njit(fastmath=_FASTMATH, error_model="numpy", inline="always")
def lever_compensate(st, lever, ax, ay, az):
    """The specific force (m/s², body) less ω̇ × r + ω × (ω × r) of a sensor at ``lever`` r (m, body FRD)."""
    wx, wy, wz = st[S_WLP], st[S_WLP + 1], st[S_WLP + 2]
    ex, ey, ez = st[S_WDOT], st[S_WDOT + 1], st[S_WDOT + 2]
    rx, ry, rz = lever[0], lever[1], lever[2]
    cx, cy, cz = wy * rz - wz * ry, wz * rx - wx * rz, wx * ry - wy * rx  # ω × r
    ax -= (ey * rz - ez * ry) + (wy * cz - wz * cy)
    ay -= (ez * rx - ex * rz) + (wz * cx - wx * cz)
    az -= (ex * ry - ey * rx) + (wx * cy - wy * cx)
    return ax, ay, az


@njit(fastmath=_FASTMATH, error_model="numpy", inline="always")
def accel_gate(st, prm, R, sog, cog, sogdot, k, use_gnss, gk0, gk1, gk2, ax, ay, az, dt):
    """GNSS kinematic compensation, then the shock gate and bias hold of a finite accelerometer sample (m/s²).
    Returns (ax, ay, az compensated, ‖a‖, | ‖a‖ − g |, rejected, forced back in)."""
    g = prm[P_GRAVITY]
    if use_gnss and np.isfinite(sog[k]) and np.isfinite(cog[k]):
        wr = R[2, 0] * (gk0 - st[4]) + R[2, 1] * (gk1 - st[5]) + R[2, 2] * (gk2 - st[6])
        c, s = np.cos(cog[k]), np.sin(cog[k])
        sd = sogdot[k] if np.isfinite(sogdot[k]) else 0.0
        an0 = sd * c - sog[k] * wr * s
        an1 = sd * s + sog[k] * wr * c
        ax -= R[0, 0] * an0 + R[1, 0] * an1
        ay -= R[0, 1] * an0 + R[1, 1] * an1
        az -= R[0, 2] * an0 + R[1, 2] * an1
    na = np.sqrt(ax * ax + ay * ay + az * az)
    dev_a = abs(na - g)
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
    return ax, ay, az, na, dev_a, rej, force


@njit(fastmath=_FASTMATH, error_model="numpy", inline="always")
def accel_feed(st, prm, R, RI, ax, ay, az, acc_ok, rej, force, dt, gap, use_lp, ext_meas, keep_f, f_out, k):
    """Feed an accepted sample (m/s², body) to the tilt check's window and to the quasi-inertial Butterworth
    low-pass with its lag companion W; a skipped row still ages W. Returns whether RI = R(q_I) was computed."""
    ri_now = False  # RI = R(q_I) computed for this sample
    fed = False  # this sample went into the accelerometer low-pass
    if acc_ok:
        if keep_f and (not rej or force):
            f_out[k, 0], f_out[k, 1], f_out[k, 2] = ax, ay, az
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
            if not gap:  # the time the window has seen (a gap restarts it, above)
                st[S_GWT] += max(dt, 0.0)
        if use_lp and not ext_meas and (not rej or force):
            # VQF's idea: low-pass the specific force in the gyro-integrated frame I, where gravity is
            # (nearly) constant and translational acceleration averages out; second-order Butterworth, delay τ.
            rmat(st[S_QI], st[S_QI + 1], st[S_QI + 2], st[S_QI + 3], RI)
            ri_now = fed = True
            i0 = RI[0, 0] * ax + RI[0, 1] * ay + RI[0, 2] * az
            i1 = RI[1, 0] * ax + RI[1, 1] * ay + RI[1, 2] * az
            i2 = RI[2, 0] * ax + RI[2, 1] * ay + RI[2, 2] * az
            if st[S_LPINIT] == 0.0:
                st[S_LPV], st[S_LPV + 1], st[S_LPV + 2] = 0.0, 0.0, 0.0
                st[S_LPY], st[S_LPY + 1], st[S_LPY + 2] = i0, i1, i2
                for m in range(18):
                    st[S_WV + m] = 0.0
            st[S_LPINIT] += 1.0
            st[S_USE_A] += 1.0
            tau = prm[P_ACC_TAU]
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
    if (
        not fed and prm[P_ACC_LAG] > 0 and use_lp and not ext_meas and st[S_LPINIT] > 0 and dt > 0 and not gap
    ):  # a row the low-pass skips (NaN, shock) still ages its content: α = 0
        rmat(st[S_QI], st[S_QI + 1], st[S_QI + 2], st[S_QI + 3], RI)
        ri_now = True
        for m in range(9):
            st[S_WY + m] += RI[m // 3, m % 3] * dt
    return ri_now


@njit(fastmath=_FASTMATH, error_model="numpy", inline="always")
def accel_update(
    st,
    P,
    prm,
    R,
    RI,
    MLAG,
    X33,
    dx,
    acc_meas,
    k,
    ax,
    ay,
    az,
    acc_ok,
    rej,
    force,
    na,
    dev_a,
    ri_now,
    dt,
    use_lp,
    ext_meas,
    update_every,
):
    """The accelerometer update (paper eq. 7–9, 11–18) when due: the low-passed direction against the vertical,
    R = (floor² + (gain·σ_w/g)²)/n, the lag term in sheared coordinates, the vertical dropped where asked.
    Returns the sample's flag bits."""
    flag = 0
    g = prm[P_GRAVITY]
    gated = acc_ok and rej and not force
    if gated:
        flag |= F_ACC_REJ
        st[S_NAREJ] += 1
        st[S_AREJ_T] += dt
    if ext_meas and acc_ok:  # the smoother's zero-lag low-pass of the same compensated force (NaN: none)
        ax, ay, az = acc_meas[k, 0], acc_meas[k, 1], acc_meas[k, 2]
        na = np.sqrt(ax * ax + ay * ay + az * az)
    if st[S_CNT_A] >= update_every and acc_ok and not gated and na > 0:
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
                    MLAG[a_, b_] = (
                        RI[0, a_] * st[S_WY + b_] + RI[1, a_] * st[S_WY + 3 + b_] + RI[2, a_] * st[S_WY + 6 + b_]
                    )
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
            flag |= F_ACC_USED
        else:  # the NIS gate turned the update away
            flag |= F_ACC_REJ
            st[S_NAREJ] += 1
            st[S_AREJ_T] += t_since
    return flag
