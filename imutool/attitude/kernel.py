"""Quaternion EKF with gyro-bias states (roll paper, eq. 1–18), made robust, plus an RTS smoother.

Frames and units: body FRD, world NED, q = [w, x, y, z] body→NED, gyro rad/s, accel m/s² (specific force:
reads −g on z at rest), mag µT (any unit: only its direction and relative norm are used), time s.

State (paper eq. 1): x = [q, b] with q the attitude and b the gyro bias (rad/s). The covariance is kept for the
*error state* δx = [δθ, δb] (6×6): q_true = q ⊗ δq(δθ), δq ≈ [1, δθ/2] (body-frame small rotation), which is
exactly the multiplicative correction of paper eq. 17. (The paper's 7×7 P over the four quaternion components
is singular along the unit-norm constraint; the 3-parameter error state is the well-posed form of the same
filter.)

- Predict (eq. 2–6), every sample, with the real time step dt_k = t_k − t_{k−1} and the rate over the step
  ω = ω_k − b (``gyro_integration="rectangular"``, default: the sample at t_k is the mean over the preceding
  interval, as in VQF; "trapezoid" = ½(ω_{k−1} + ω_k) − b, half a sample later): q ← q ⊗ exp(½ ω dt) (the
  exact exponential; paper eq. 5 is its first-order truncation). Error-state transition F = [[Φ, −I dt],
  [0, I]], Φ = exp(−[ω×] dt); Q = diag(σ_g² dt I, σ_b² dt I) (eq. 10). A step longer than ``gap_dt`` is a gap: the
  rotation is integrated over at most ``gap_dt`` and the attitude variance grows by (gap_rate_sigma·dt)², so accel/mag
  re-converge after it.
- Update (eq. 7–18) every N samples (``update_every``; default ⌊sample rate / ``update_rate_hz``⌋, 4 at 200 Hz;
  paper: every 40th at 200 Hz). The attitude is integrated every sample; P is propagated only before an update,
  with the rotation accumulated since the last one (Φ = ΔRᵀ), as in the paper's multi-rate scheme. The noise
  figures stay per sample: an update is the average of the n usable samples since the previous one of that sensor
  (accelerometer: the low-pass's output; magnetometer: the accepted samples' field direction in the world frame;
  rest: the still samples' gyro rate), R = σ²/n, and each sensor is used at its first usable sample once due (a
  sensor at half the rate, NaN rows or an interference at the update rate never alias with N). So N changes the
  speed, not the filter (BROAD, N = 1…10: the same inclination). The self-check's NIS is taken against σ², as at
  N = 1. The raw accelerometer (``accel_lp_tau`` 0) is one sample, not an average: N defaults to 1 there.
  accelerometer z = a/‖a‖, ẑ = Rᵀ(q)·[0,0,−1], H = [[ẑ×], 0] (eq. 8–12), K = PHᵀS⁻¹ (eq. 14), δx = K y
  (eq. 15), b += δb (16), q ← q ⊗ δq (17), P ← (I − KH)P (18).
  Magnetometer, ``mag_mode``: "full" = the paper's normalised 3-vector (ẑ = Rᵀ m_ref); "heading" (default) =
  the horizontal field direction only, a scalar heading innovation whose correction is projected onto the
  world vertical, so magnetic disturbance never reaches roll/pitch (Joseph-form covariance update for the
  projected gain); "off". Its σ is a density, ``mag_heading_density`` deg·√s: σ per sample = density / √dt_m
  with dt_m the magnetometer's own interval, so the heading's time constant (≈ radians(density) / σ_g ≈ 21 s) is
  the same at any rate; at least ``mag_heading_floor_deg`` per sample (one sample's own white noise, which takes
  over below ≈ 17 Hz).
- Accelerometer measurement beyond the paper (VQF's key idea, Laidig & Seel 2023, inside the EKF): the specific
  force is rotated into a quasi-inertial frame I given by the gyro-only integrated quaternion q_I, low-passed
  there (second-order Butterworth, VQF's filter, cut-off √2/τ, delay τ = ``accel_lp_tau``; a running mean for its
  first τ/10) — gravity is constant in I while translational accelerations average out — and rotated back,
  z = R(q_I)ᵀ·LP(R(q_I)·a). Its variance is
  ``accel_noise``² + (``accel_noise_gain`` · σ_w/g)² (independent error sources add in variance), with σ_w the
  accelerometer white noise learned online from second differences (E‖a_k − 2a_{k−1} + a_{k−2}‖²/18, ~10 s
  average, shocks excluded; motion cancels to second order, so fast rotation does not pass for noise), so noisy
  and quiet sensors both get a consistent R without retuning. ``accel_lp_tau = 0`` gives the paper's
  raw-accelerometer update.
- The low-passed measurement lags a gyro-bias error δb by the low-pass's delay: it sees the tilt error plus M·δb,
  M = R_Iᵀ·W with W the rotation R_I weighted by the low-pass's survival function (= τ·I when still), tracked
  as the age-weighted companion of the low-pass's state (``accel_lp_lag``). H = [[ẑ×], [ẑ×]·M]; the update is
  made in the sheared error coordinates
  δθ' = δθ + M δb (where H has the form above) and sheared back. After a data gap the low-pass restarts (its
  frame missed the gap's rotation). ``gyro_scale_noise`` adds tilt process noise ∝ the angle turned (scale-factor
  and misalignment errors), across the world vertical only.
- Robustness beyond the paper: accelerometer sample skipped (not fed to the low-pass) when | ‖a‖ − g | >
  accel_gate (a shock); update skipped when its normalised innovation squared exceeds accel_nis_gate (off by
  default; forced back in after reject_timeout s of continuous rejection);
  magnetometer skipped when its norm or dip departs from the reference; rest detection (low rate, ‖a‖ ≈ g
  for rest_time s) adds a zero-rate pseudo-measurement of the bias; GNSS velocity aiding (``_velocity_aiding``):
  between two velocity fixes ∫ R_I f dt = R_IN (Δv_s − g Δt), so the low-pass takes each interval's mean force
  less Δv_s/Δt (sway, surge and turn removed at any frequency; v_s the antenna's velocity + R (ω × r)); without
  it, the turn's kinematic acceleration a_ned = SȮG·[cos χ, sin χ, 0] + SOG·r·[−sin χ, cos χ, 0] (χ = COG, or the
  bow's direction where no heading is held; r = the world vertical rate from the gyro) is subtracted from the
  measured specific force (f = Rᵀ(a_ned − g_ned)). A low-pass longer than LP_TAU_START starts at it and lengthens
  by LP_TAU_GROWTH s per s (its lag learned while short).
- NaN rows: a NaN gyro sample is replaced by the last good one (counted); NaN accel/mag skip that update.
"""

from __future__ import annotations

import numpy as np
from numba import njit

import formats.kernel_cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from imutool.attitude.covariance import _drop_vertical, _propagate_pending, _reset_cov, _shear_cov, _vertical_forms
from imutool.attitude.layout import (
    _FASTMATH,
    F_ACC_REJ,
    F_ACC_USED,
    F_HDG_INCONSISTENT,
    F_HDG_USED,
    F_INCONSISTENT,
    F_MAG_NEW,
    F_MAG_REJ,
    F_MAG_USED,
    F_REST,
    FALSE,
    HEADING_GATE_SIGMA,
    HEADING_REJECT_MAX_S,
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
    P_GAP_DT,
    P_GAP_RATE,
    P_GRAVITY,
    P_GYRO_PREV_W,
    P_HDG_EVERY,
    P_HDG_NOISE,
    P_LEVER_TAU,
    P_MAG_BIAS,
    P_MAG_BIAS_GATE,
    P_MAG_DIP_GATE,
    P_MAG_DIP_SOFT,
    P_MAG_HOLD,
    P_MAG_NEW_FIRST,
    P_MAG_NEW_RATE,
    P_MAG_NEW_TIME,
    P_MAG_NOISE,
    P_MAG_NORM_GATE,
    P_MAG_NORM_SOFT,
    P_MAG_REF_TAU,
    P_NIS_LIMIT,
    P_NIS_TAU,
    P_REJ_TIMEOUT,
    P_REST_ACC,
    P_REST_GYRO,
    P_REST_NOISE,
    P_REST_TIME,
    P_SHOCK_MAX,
    P_TILT_LIM,
    P_TILT_WIN,
    S_AFLOOR,
    S_APREV,
    S_APREV2,
    S_AREJ_T,
    S_AVAR,
    S_BHOLD,
    S_CNT_A,
    S_CNT_M,
    S_CNT_R,
    S_DQ,
    S_GPREV,
    S_GW1,
    S_GW2,
    S_GWN,
    S_GWT,
    S_HLAST,
    S_HREJ_T,
    S_INIT,
    S_LPINIT,
    S_LPT,
    S_LPV,
    S_LPY,
    S_MCCNT,
    S_MCT,
    S_MDIST,
    S_MDT,
    S_MNORM,
    S_MNSUM,
    S_MREF,
    S_MREF_N,
    S_MREF_T,
    S_MSUM,
    S_NAREJ,
    S_NAVAR,
    S_NGAPS,
    S_NGNAN,
    S_NHINC,
    S_NHREJ,
    S_NINC,
    S_NIS_A,
    S_NIS_M,
    S_NMREJ,
    S_NREST,
    S_NTILT,
    S_NUPD,
    S_P,
    S_QI,
    S_REST_T,
    S_RSUM,
    S_SHOCK_T,
    S_TACC,
    S_TILTMAX,
    S_TPREV,
    S_USE_A,
    S_USE_M,
    S_USE_R,
    S_VA_BAD,
    S_VA_HAVE,
    S_VA_IN,
    S_VA_LAST,
    S_VA_OK,
    S_VA_PREV,
    S_VA_SUM,
    S_VA_T,
    S_VA_TFIX,
    S_WDOT,
    S_WINIT,
    S_WLP,
    S_WV,
    S_WY,
    TRUE,
    VA_MAX_INTERVAL,
    VA_MIN_SPACING,
)
from imutool.attitude.lowpass import _butterworth_gains, _butterworth_step, _low_pass_gain, _low_pass_two_stages
from imutool.attitude.magnetic import _dip_gate, _new_field
from imutool.attitude.updates import _apply_correction, _heading_update, _reset_heading, _vec_update
from imutool.quaternion import fast_atan2, qmul, rmat, rotvec_quat


@njit(cache=True, fastmath=_FASTMATH, nogil=True, error_model="numpy")
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


@njit(cache=True, fastmath=_FASTMATH, nogil=True, error_model="numpy")
def _lever_arm(st, prm, lever, gk0, gk1, gk2, dt, ax, ay, az, acc_ok):
    """The specific force (m/s², body) less the lever arm's rotation terms; the rate's low-pass advanced by dt (s)."""
    if dt > 0:
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
    if acc_ok:
        wx, wy, wz = st[S_WLP], st[S_WLP + 1], st[S_WLP + 2]
        ex, ey, ez = st[S_WDOT], st[S_WDOT + 1], st[S_WDOT + 2]
        rx, ry, rz = lever[0], lever[1], lever[2]
        cx, cy, cz = wy * rz - wz * ry, wz * rx - wx * rz, wx * ry - wy * rx  # ω × r
        ax -= (ey * rz - ez * ry) + (wy * cz - wz * cy)
        ay -= (ez * rx - ex * rz) + (wz * cx - wx * cz)
        az -= (ex * ry - ey * rx) + (wx * cy - wy * cx)
    return ax, ay, az


@njit(cache=True, fastmath=_FASTMATH, nogil=True, error_model="numpy")
def _gnss_force(st, R, gk0, gk1, gk2, sog, cog, sogdot, along_bow, ax, ay, az):
    """The specific force (m/s², body) less the GNSS kinematic acceleration (sog m/s, cog rad, sogdot m/s²) of the
    turn: along the course, or ``along_bow`` where no heading is held (the course cannot be turned into body axes
    then; the bow's direction can, whatever the heading's error)."""
    wr = R[2, 0] * (gk0 - st[4]) + R[2, 1] * (gk1 - st[5]) + R[2, 2] * (gk2 - st[6])
    if along_bow:
        hn = max(np.sqrt(R[0, 0] * R[0, 0] + R[1, 0] * R[1, 0]), 1e-9)
        c, s = R[0, 0] / hn, R[1, 0] / hn
    else:
        c, s = np.cos(cog), np.sin(cog)
    sd = sogdot if np.isfinite(sogdot) else 0.0
    an0 = sd * c - sog * wr * s
    an1 = sd * s + sog * wr * c
    ax -= R[0, 0] * an0 + R[1, 0] * an1
    ay -= R[0, 1] * an0 + R[1, 1] * an1
    az -= R[0, 2] * an0 + R[1, 2] * an1
    return ax, ay, az


@njit(cache=True, fastmath=_FASTMATH, nogil=True, error_model="numpy")
def _heading_input(st, P, prm, R, dx, tk, hk):
    """An external true heading hk (rad, NED) at time tk (s): a scalar update, a glitch skipped, or taken outright
    after a long glitch; True if it was used. R is refreshed."""
    dth = tk - st[S_HLAST] if np.isfinite(st[S_HLAST]) else 0.0
    st[S_HLAST] = tk
    _propagate_pending(st, P, prm)
    rmat(st[0], st[1], st[2], st[3], R)
    yh = hk - fast_atan2(R[1, 0], R[0, 0])  # measured − estimated heading of the body x axis
    yh -= 2.0 * np.pi * np.floor((yh + np.pi) / (2.0 * np.pi))
    s2h = prm[P_HDG_NOISE] ** 2
    # a glitched fix is skipped, for a bounded time: a heading that stays away that long is the
    # gyrocompass's, and the filter's own is the one to give way
    vh = _vertical_forms(P, R[2, 0], R[2, 1], R[2, 2])[0]
    glitch = yh * yh > HEADING_GATE_SIGMA**2 * (vh + s2h)
    if glitch and st[S_HREJ_T] < HEADING_REJECT_MAX_S:
        st[S_HREJ_T] += dth
        st[S_NHREJ] += 1
        return False
    st[S_HREJ_T] = 0.0
    if glitch:  # away for HEADING_REJECT_MAX_S: the gyrocompass's heading is taken outright
        _reset_heading(st, P, R[2, 0], R[2, 1], R[2, 2], yh, s2h)
    else:
        _heading_update(P, R[2, 0], R[2, 1], R[2, 2], yh, s2h, dx, FALSE, 0.0, 0.0, 0.0)
        _apply_correction(st, dx)  # dx along r: its reset is G = I
    return True


@njit(cache=True, fastmath=_FASTMATH, nogil=True, error_model="numpy")
def _mag_vector_update(st, P, prm, R, dx, m0, m1, m2, n_use):
    """mag_mode "full": the paper's normalised 3-vector update with the mean world-frame field (m0, m1, m2) of
    n_use samples."""
    h0 = R[0, 0] * st[S_MREF] + R[1, 0] * st[S_MREF + 1] + R[2, 0] * st[S_MREF + 2]
    h1 = R[0, 1] * st[S_MREF] + R[1, 1] * st[S_MREF + 1] + R[2, 1] * st[S_MREF + 2]
    h2 = R[0, 2] * st[S_MREF] + R[1, 2] * st[S_MREF + 1] + R[2, 2] * st[S_MREF + 2]
    nw = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)  # the mean direction, back in the body frame
    y0 = (R[0, 0] * m0 + R[1, 0] * m1 + R[2, 0] * m2) / nw - h0
    y1 = (R[0, 1] * m0 + R[1, 1] * m1 + R[2, 1] * m2) / nw - h1
    y2 = (R[0, 2] * m0 + R[1, 2] * m1 + R[2, 2] * m2) / nw - h2
    _vec_update(P, h0, h1, h2, y0, y1, y2, prm[P_MAG_NOISE] ** 2 / n_use, 0.0, TRUE, dx, FALSE, 0.0)
    _apply_correction(st, dx)
    _reset_cov(P, dx, R[2, 0], R[2, 1], R[2, 2])


@njit(cache=True, fastmath=_FASTMATH, nogil=True, error_model="numpy")
def _velocity_aiding(st, R, RI, tk, vn_k, ve_k, w0, w1, w2, arm_sa, ax, ay, az, dt, gap, acc_ok):
    """Velocity aiding's interval sums at one row (time tk s, the antenna's north/east velocity m/s, the bias-free
    rate w rad/s, the force a m/s² body); True if RI = R(q_I) was computed for this row."""
    ri_now = False
    # velocity aiding: ∫ R_I f dt between two velocity fixes is R_I·(Δv − g Δt) whatever the translation
    # (sway, surge, turn, at any frequency), so the mean force of an interval less Δv/Δt is gravity in I;
    # the low-pass takes it, one interval late, while the fixes keep coming (docs/attitude.md)
    if gap:  # the frame I restarted: no interval across a gap
        st[S_VA_HAVE], st[S_VA_OK] = 0.0, 0.0
    elif dt > 0:
        if acc_ok:
            rmat(st[S_QI], st[S_QI + 1], st[S_QI + 2], st[S_QI + 3], RI)
            ri_now = True
            for i in range(3):
                st[S_VA_SUM + i] += (RI[i, 0] * ax + RI[i, 1] * ay + RI[i, 2] * az) * dt
        else:
            st[S_VA_BAD] = 1.0
        st[S_VA_T] += dt
    is_fix = (
        np.isfinite(vn_k)
        and np.isfinite(ve_k)
        and not (vn_k == st[S_VA_LAST] and ve_k == st[S_VA_LAST + 1])
        and not (st[S_VA_HAVE] > 0 and tk - st[S_VA_TFIX] < VA_MIN_SPACING)
    )
    st[S_VA_LAST], st[S_VA_LAST + 1] = vn_k, ve_k
    if is_fix:
        # the sensor's horizontal velocity: the antenna's plus R (ω × r), r from the antenna to the sensor
        cx = w1 * arm_sa[2] - w2 * arm_sa[1]
        cy = w2 * arm_sa[0] - w0 * arm_sa[2]
        cz = w0 * arm_sa[1] - w1 * arm_sa[0]
        vel_n = vn_k + R[0, 0] * cx + R[0, 1] * cy + R[0, 2] * cz
        vel_e = ve_k + R[1, 0] * cx + R[1, 1] * cy + R[1, 2] * cz
        span = st[S_VA_T]
        if st[S_VA_HAVE] > 0 and st[S_VA_BAD] == 0.0 and 0.0 < span <= VA_MAX_INTERVAL:
            acc_n = (vel_n - st[S_VA_PREV]) / span
            acc_e = (vel_e - st[S_VA_PREV + 1]) / span
            if not ri_now:
                rmat(st[S_QI], st[S_QI + 1], st[S_QI + 2], st[S_QI + 3], RI)
                ri_now = True
            bx = R[0, 0] * acc_n + R[1, 0] * acc_e  # body: Rᵀ (acc_n, acc_e, 0)
            by = R[0, 1] * acc_n + R[1, 1] * acc_e
            bz = R[0, 2] * acc_n + R[1, 2] * acc_e
            for i in range(3):
                st[S_VA_IN + i] = st[S_VA_SUM + i] / span - (RI[i, 0] * bx + RI[i, 1] * by + RI[i, 2] * bz)
            st[S_VA_OK] = 1.0
        else:
            st[S_VA_OK] = 0.0
        st[S_VA_PREV], st[S_VA_PREV + 1] = vel_n, vel_e
        st[S_VA_HAVE], st[S_VA_TFIX] = 1.0, tk
        st[S_VA_SUM], st[S_VA_SUM + 1], st[S_VA_SUM + 2] = 0.0, 0.0, 0.0
        st[S_VA_T], st[S_VA_BAD] = 0.0, 0.0
    elif st[S_VA_OK] > 0 and tk - st[S_VA_TFIX] > VA_MAX_INTERVAL:
        st[S_VA_OK] = 0.0  # the fixes stopped: the low-pass takes the force again
    return ri_now


@njit(cache=True, fastmath=_FASTMATH, nogil=True, error_model="numpy")
def ekf_kernel(
    t,
    gyro,
    acc,
    mag,
    sog,
    cog,
    sogdot,
    vel,
    prm,
    update_every,
    mag_mode,
    cov_every_sample,
    use_gnss,
    lever,
    arm_sa,
    st,
    q_out,
    b_out,
    std_out,
    flags_out,
    p_store,
    acc_meas,
    f_out,
    hdg,
):
    """Run the EKF over one chunk (state ``st`` carried in place; see the module docstring).

    t (N,) s; gyro/acc/mag (N,3); sog (N,) m/s, cog (N,) rad, sogdot (N,) m/s² (use_gnss: 0 not used, 1 the turn's
    centripetal term along the course, 2 along the bow, where no heading is held);
    vel (N,2), when it has N rows: the GNSS antenna's north/east velocity (m/s; held between fixes, NaN between
    fixes, or interpolated) for velocity aiding: a fix is a row where it changes, at most one per VA_MIN_SPACING
    s (a held value is the velocity of its first row only); arm_sa (3,) m body FRD: the sensor's position from
    the antenna's;
    outputs: q_out (N,4), b_out (N,3), std_out (N,3) roll/pitch/heading σ rad, flags_out (N,) bit mask,
    p_store (N,6,6) posterior P per sample when it has N rows (for the smoother), else unused.
    acc_meas (N,3), when it has N rows: the accelerometer measurement (m/s², body), already compensated and
    low-passed (the zero-lag smoother's), used in place of the filter's own causal low-pass; NaN: no update.
    f_out (N,3), when it has N rows: the compensated specific force each sample fed to the low-pass (m/s², body;
    NaN where none: a NaN row or a shock).
    hdg (N,), when it has N rows: an external true heading of the body x axis (rad, NED; NaN: none), a scalar
    heading update of σ ``heading_input_noise_deg`` projected on the world vertical, like the magnetometer's.
    """
    n = t.shape[0]
    ext_meas = acc_meas.shape[0] == n
    keep_f = f_out.shape[0] == n
    P = st[S_P : S_P + 36].reshape((6, 6))
    R = np.empty((3, 3))
    dx = np.zeros(6)
    g = prm[P_GRAVITY]
    store = p_store.shape[0] == n
    use_lp = prm[P_ACC_TAU] > 0
    wp = prm[P_GYRO_PREV_W]  # weight of the previous gyro sample over the step (0.5: trapezoid, 0: rectangular)
    wc = 1.0 - wp
    RI = np.empty((3, 3))
    MLAG = np.zeros((3, 3))
    X33 = np.empty((3, 3))
    cos_gate, sin_gate = np.cos(prm[P_MAG_DIP_GATE]), np.sin(prm[P_MAG_DIP_GATE])
    dip_ref, dip_lo, dip_hi = _dip_gate(st[S_MREF + 2], cos_gate, sin_gate)
    use_lever = lever[0] != 0.0 or lever[1] != 0.0 or lever[2] != 0.0  # once per chunk, not per sample
    use_va = vel.shape[0] == n and use_lp and not ext_meas
    for k in range(n):
        flag = 0
        gk0, gk1, gk2 = gyro[k, 0], gyro[k, 1], gyro[k, 2]
        if not (np.isfinite(gk0) and np.isfinite(gk1) and np.isfinite(gk2)):
            gk0, gk1, gk2 = st[S_GPREV], st[S_GPREV + 1], st[S_GPREV + 2]
            st[S_NGNAN] += 1
        if st[S_INIT] == 0.0:
            st[S_TPREV] = t[k]
            st[S_GPREV], st[S_GPREV + 1], st[S_GPREV + 2] = gk0, gk1, gk2
        dt = t[k] - st[S_TPREV]
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
        st[S_TPREV] = t[k]
        st[S_GPREV], st[S_GPREV + 1], st[S_GPREV + 2] = gk0, gk1, gk2
        # multi-rate: each sensor is used every N samples, at its first usable sample once due; P is propagated
        # only before an update (and every sample when the smoother stores it)
        st[S_CNT_A] += 1.0
        st[S_CNT_M] += 1.0
        st[S_CNT_R] += 1.0
        if cov_every_sample:
            _propagate_pending(st, P, prm)
        st[S_INIT] = 1.0
        rmat(st[0], st[1], st[2], st[3], R)
        ax, ay, az = acc[k, 0], acc[k, 1], acc[k, 2]
        acc_ok = np.isfinite(ax) and np.isfinite(ay) and np.isfinite(az)
        if acc_ok and prm[P_ACC_WN_GAIN] > 0:
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
        # ---------------- rest detection → zero-rate bias pseudo-measurement ----------------
        if prm[P_REST_TIME] > 0 and acc_ok:
            still = (
                abs(gk0 - st[4]) < prm[P_REST_GYRO]
                and abs(gk1 - st[5]) < prm[P_REST_GYRO]
                and abs(gk2 - st[6]) < prm[P_REST_GYRO]
                and abs(np.sqrt(ax * ax + ay * ay + az * az) - g) < prm[P_REST_ACC]
            )
            st[S_REST_T] = st[S_REST_T] + dt if still else 0.0
            if st[S_REST_T] >= prm[P_REST_TIME]:
                flag |= F_REST
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
        # ---------------- accelerometer: kinematic compensation, gate, quasi-inertial low-pass ----------------
        rej = False
        force = False
        na = 0.0
        dev_a = 0.0
        ri_now = False  # RI = R(q_I) computed for this sample
        fed = False  # this sample went into the accelerometer low-pass
        if use_va:
            ri_now = _velocity_aiding(
                st, R, RI, t[k], vel[k, 0], vel[k, 1], w0, w1, w2, arm_sa, ax, ay, az, dt, gap, acc_ok
            )
        if use_lever:
            ax, ay, az = _lever_arm(st, prm, lever, gk0, gk1, gk2, dt, ax, ay, az, acc_ok)
        if acc_ok:
            if use_gnss > 0 and not use_va and np.isfinite(sog[k]) and (use_gnss == 2 or np.isfinite(cog[k])):
                # the turn alone: along the course (1), or along the bow (2: no heading is held)
                ax, ay, az = _gnss_force(st, R, gk0, gk1, gk2, sog[k], cog[k], sogdot[k], use_gnss == 2, ax, ay, az)
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
            aided = use_va and st[S_VA_OK] > 0  # the last interval's force less the GNSS velocity's change
            if use_lp and not ext_meas and (aided or not rej or force):
                # VQF's idea: low-pass the specific force in the gyro-integrated frame I, where gravity is
                # (nearly) constant and translational acceleration averages out; second-order Butterworth, delay τ.
                if not ri_now:
                    rmat(st[S_QI], st[S_QI + 1], st[S_QI + 2], st[S_QI + 3], RI)
                ri_now = fed = True
                if aided:
                    i0, i1, i2 = st[S_VA_IN], st[S_VA_IN + 1], st[S_VA_IN + 2]
                    if keep_f:  # the compensated force the smoother and the gyro check read: this one, in the body
                        f_out[k, 0] = RI[0, 0] * i0 + RI[1, 0] * i1 + RI[2, 0] * i2
                        f_out[k, 1] = RI[0, 1] * i0 + RI[1, 1] * i1 + RI[2, 1] * i2
                        f_out[k, 2] = RI[0, 2] * i0 + RI[1, 2] * i1 + RI[2, 2] * i2
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
        if (
            not fed and prm[P_ACC_LAG] > 0 and use_lp and not ext_meas and st[S_LPINIT] > 0 and dt > 0 and not gap
        ):  # a row the low-pass skips (NaN, shock) still ages its content: α = 0
            rmat(st[S_QI], st[S_QI + 1], st[S_QI + 2], st[S_QI + 3], RI)
            ri_now = True
            for m in range(9):
                st[S_WY + m] += RI[m // 3, m % 3] * dt
        if ext_meas and np.isfinite(acc_meas[k, 0]):
            st[S_USE_A] += 1.0  # the smoother's zero-lag low-pass had this sample
        # ---------------- accelerometer update (eq. 7–9, 11–18) ----------------
        # a sample the gate turns away (a shock) is flagged as rejected, and a due update waits for the next one
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
        # ---------------- magnetometer: gates and disturbance level every sample, the update when due -------------
        mx, my, mz = mag[k, 0], mag[k, 1], mag[k, 2]
        if mag_mode > 0 and np.isfinite(mx) and np.isfinite(my) and np.isfinite(mz):
            nm = np.sqrt(mx * mx + my * my + mz * mz)
            mw0 = R[0, 0] * mx + R[0, 1] * my + R[0, 2] * mz
            mw1 = R[1, 0] * mx + R[1, 1] * my + R[1, 2] * mz
            mw2 = R[2, 0] * mx + R[2, 1] * my + R[2, 2] * mz
            rej = nm <= 0
            have_ref = st[S_MREF_N] > 0  # none yet (a zero first sample): the first accepted samples set it
            if not rej and prm[P_MAG_NORM_GATE] > 0 and st[S_MNORM] > 0:
                rej = abs(nm / st[S_MNORM] - 1.0) > prm[P_MAG_NORM_GATE]
            if not rej and prm[P_MAG_DIP_GATE] > 0 and have_ref:
                # |asin(m_z/|m|) − dip_ref| > gate ⇔ m_z/|m| outside [sin(dip_ref − gate), sin(dip_ref + gate)]
                sz = mw2 / nm
                rej = sz < dip_lo or sz > dip_hi
            # deviation measure of the field from its reference (norm and dip, relative to their soft scales)
            dev_m = 0.0
            if nm > 0 and prm[P_MAG_NORM_SOFT] > 0 and st[S_MNORM] > 0:
                dev_m += ((nm / st[S_MNORM] - 1.0) / prm[P_MAG_NORM_SOFT]) ** 2
            if nm > 0 and prm[P_MAG_DIP_SOFT] > 0 and have_ref:
                dev_m += ((np.arcsin(min(1.0, max(-1.0, mw2 / nm))) - dip_ref) / prm[P_MAG_DIP_SOFT]) ** 2
            if prm[P_MAG_HOLD] > 0:  # peak hold with exponential decay: a disturbance is a state, not a sample
                if rej:
                    dev_m = max(dev_m, 100.0)
                decay = 1.0 / (1.0 + max(dt, 0.0) / prm[P_MAG_HOLD])  # ≈ exp(−dt/hold)
                st[S_MDIST] = max(dev_m, st[S_MDIST] * decay)
                dev_m = st[S_MDIST]
            dtm = st[S_MDT]  # since the previous magnetometer sample (a slower magnetometer: several rows)
            st[S_MDT] = 0.0
            if rej and prm[P_MAG_NEW_TIME] > 0 and nm > 0 and have_ref:  # no lock-out: a new homogeneous field
                if _new_field(
                    st,
                    P,
                    prm,
                    nm,
                    mw2 / nm,
                    mw0 / nm,
                    mw1 / nm,
                    dtm,
                    w0 * w0 + w1 * w1 + w2 * w2 >= prm[P_MAG_NEW_RATE] ** 2,
                    R[2, 0],
                    R[2, 1],
                    R[2, 2],
                    cos_gate,
                    sin_gate,
                ):
                    dip_ref, dip_lo, dip_hi = _dip_gate(st[S_MREF + 2], cos_gate, sin_gate)
                    flag |= F_MAG_NEW
            if rej:
                flag |= F_MAG_REJ
                st[S_NMREJ] += 1
            else:  # the field's direction in the world frame, summed over the samples the update stands for
                st[S_USE_M] += 1.0
                st[S_MNSUM] += nm
                st[S_MSUM] += mw0 / nm
                st[S_MSUM + 1] += mw1 / nm
                st[S_MSUM + 2] += mw2 / nm
            due = not rej and st[S_CNT_M] >= update_every
            # σ per sample: the update is the mean direction of the accepted samples since the last one and stands
            # for them (R = σ²/n; an interference at the update rate averages out, not aliases)
            n_use = st[S_USE_M]
            m0, m1, m2 = st[S_MSUM], st[S_MSUM + 1], st[S_MSUM + 2]
            t_since = dt * st[S_CNT_M]
            if due:
                _propagate_pending(st, P, prm)
                if dev_m < 1.0:  # undisturbed: a candidate new field is forgotten, and the reference's field has
                    # held over the samples since the last update; while the body turns that confirms it
                    st[S_MCCNT], st[S_MCT] = 0.0, 0.0
                    turning = w0 * w0 + w1 * w1 + w2 * w2 >= prm[P_MAG_NEW_RATE] ** 2
                    if st[S_MREF_T] < prm[P_MAG_NEW_FIRST] and turning:
                        st[S_MREF_T] += min(dt, prm[P_GAP_DT]) * st[S_CNT_M]
                if prm[P_MAG_REF_TAU] > 0 and n_use > 0:
                    # the reference norm and dip follow the accepted field: a running mean at start-up (one
                    # noisy or disturbed first sample must not set the gates for the whole run), then τ_ref
                    cnt = st[S_MREF_N] + n_use
                    t_ref = min(dt, prm[P_GAP_DT]) * st[S_CNT_M]  # a gap's length is no time of accepted field
                    al = min(1.0, max(n_use / cnt, t_ref / prm[P_MAG_REF_TAU]))
                    st[S_MREF_N] = cnt
                    st[S_MNORM] += al * (st[S_MNSUM] / n_use - st[S_MNORM])
                    szr = st[S_MREF + 2] + al * (m2 / n_use - st[S_MREF + 2])
                    szr = min(1.0, max(-1.0, szr))
                    st[S_MREF], st[S_MREF + 1], st[S_MREF + 2] = np.sqrt(1.0 - szr * szr), 0.0, szr
                    dip_ref, dip_lo, dip_hi = _dip_gate(szr, cos_gate, sin_gate)
                st[S_CNT_M], st[S_USE_M], st[S_MNSUM] = 0.0, 0.0, 0.0
                st[S_MSUM], st[S_MSUM + 1], st[S_MSUM + 2] = 0.0, 0.0, 0.0
            if due and mag_mode == 1:
                yh = -fast_atan2(m1, m0)  # heading error: the horizontal field should point north
                sm2 = prm[P_MAG_NOISE] ** 2 * (1.0 + dev_m)
                # a heading off by more than mag_bias_gate σ (against the undisturbed σ: the de-weighting must not
                # hide it) is the heading's error, not the gyro's: the bias does not learn from it
                nis_m = _heading_update(
                    P,
                    R[2, 0],
                    R[2, 1],
                    R[2, 2],
                    yh,
                    sm2 / n_use,
                    dx,
                    prm[P_MAG_BIAS] == 0.0,
                    sm2 - sm2 / n_use,
                    prm[P_MAG_BIAS_GATE] ** 2,
                    prm[P_MAG_NOISE] ** 2 / n_use,
                )
                if prm[P_NIS_TAU] > 0 and dt > 0:
                    st[S_NIS_M] += min(1.0, t_since / prm[P_NIS_TAU]) * (min(nis_m, 1e6) - st[S_NIS_M])
                _apply_correction(st, dx)  # dx along r: its reset is G = I
                flag |= F_MAG_USED
            elif due:
                _mag_vector_update(st, P, prm, R, dx, m0, m1, m2, n_use)
                flag |= F_MAG_USED
        # ---------------- external heading (gyrocompass) ----------------
        if hdg.shape[0] > 0 and np.isfinite(hdg[k]) and t[k] - st[S_HLAST] >= prm[P_HDG_EVERY]:
            if _heading_input(st, P, prm, R, dx, t[k], hdg[k]):
                flag |= F_HDG_USED
        # ---------------- outputs ----------------
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
        # the attitude's check (the accelerometer's NIS, the tilt check) and the heading's (the magnetometer's or the
        # external heading's NIS: a magnetic disturbance distrusts the heading, not roll and pitch)
        bad = prm[P_NIS_LIMIT] > 0 and st[S_NIS_A] > prm[P_NIS_LIMIT]
        if prm[P_NIS_LIMIT] > 0 and st[S_NIS_M] > prm[P_NIS_LIMIT]:
            flag |= F_HDG_INCONSISTENT
            st[S_NHINC] += 1
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
        if bad:
            flag |= F_INCONSISTENT
            st[S_NINC] += 1
        flags_out[k] = flag
        if store:
            for i in range(6):
                for j in range(6):
                    p_store[k, i, j] = P[i, j]
