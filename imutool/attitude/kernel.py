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
  for rest_time s) adds a zero-rate pseudo-measurement of the bias; GNSS velocity aiding (compensation.py):
  between two velocity fixes ∫ R_I f dt = R_IN (Δv_s − g Δt), so the low-pass takes each interval's mean force
  less Δv_s/Δt (sway, surge and turn removed at any frequency; v_s the antenna's velocity + R (ω × r)); without
  it, the turn's kinematic acceleration a_ned = SȮG·[cos χ, sin χ, 0] + SOG·r·[−sin χ, cos χ, 0] (χ = COG, or the
  bow's direction where no heading is held; r = the world vertical rate from the gyro) is subtracted from the
  measured specific force (f = Rᵀ(a_ned − g_ned)). A low-pass longer than LP_TAU_START starts at it and lengthens
  by LP_TAU_GROWTH s per s (its lag learned while short).
- NaN rows: a NaN gyro sample is replaced by the last good one (counted); NaN accel/mag skip that update.

Inputs not given: ``sog``, ``vel`` and ``hdg`` are None (not empty arrays) when the input has no GNSS speed, no
GNSS velocity or no external heading, and numba prunes a branch on ``x is not None`` for an argument typed None
before it types the branch: the default kernel has no GNSS turn, velocity aiding or heading input compiled in
(~1.7 s of a first run's ~20 s CPU, issue 52). A run with one of them compiles its own kernel once (its sections are
cached apart); the outputs are the same bits.
"""

from __future__ import annotations

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.jit.decorators import njit
from imutool.attitude.accel import _accel_gate, _accel_low_pass, _accel_update, _accel_white_noise, _age_low_pass
from imutool.attitude.compensation import _gnss_force, _lever_arm, _velocity_aiding
from imutool.attitude.heading_input import _heading_input
from imutool.attitude.layout import (
    _FASTMATH,
    F_ACC_REJ,
    F_HDG_INCONSISTENT,
    F_HDG_USED,
    F_INCONSISTENT,
    FALSE,
    INLINED,
    P_ACC_LAG,
    P_ACC_TAU,
    P_ACC_WN_GAIN,
    P_HDG_EVERY,
    P_MAG_DIP_GATE,
    P_NIS_LIMIT,
    P_REST_TIME,
    P_TILT_LIM,
    P_TILT_WIN,
    S_CNT_A,
    S_CNT_M,
    S_GW2,
    S_GWT,
    S_HLAST,
    S_LPINIT,
    S_MREF,
    S_NHINC,
    S_NINC,
    S_NIS_A,
    S_NIS_M,
    S_NTILT,
    S_P,
    S_TILTMAX,
    S_USE_A,
    S_VA_IN,
    S_VA_OK,
)
from imutool.attitude.magnetic import _dip_gate, _mag_sample, _mag_update
from imutool.attitude.predict import _predict
from imutool.attitude.rest import _rest
from imutool.quaternion import rmat


@njit(**INLINED)
def _outputs(st, P, k, q_out, b_out, std_out):
    """Row k of the outputs: q (body→NED), the gyro bias (rad/s) and the roll/pitch/heading σ (rad). Returns the
    roll and pitch variances (rad²) for the self-check."""
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
    return v0, v1


@njit(**INLINED)
def _self_check(st, prm, v0, v1):
    """The per-sample self-checks; v0, v1 the roll and pitch variances (rad²). The attitude's (the accelerometer's
    windowed NIS, the tilt check) and the heading's (the magnetometer's or the external heading's NIS: a magnetic
    disturbance distrusts the heading, not roll and pitch). Returns the flag bits (F_INCONSISTENT,
    F_HDG_INCONSISTENT); the spans and warnings are made from them in selfcheck.py."""
    flag = 0
    bad = prm[P_NIS_LIMIT] > 0 and st[S_NIS_A] > prm[P_NIS_LIMIT]
    if prm[P_NIS_LIMIT] > 0 and st[S_NIS_M] > prm[P_NIS_LIMIT]:
        flag = F_HDG_INCONSISTENT
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
    return flag


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
    """Run the EKF over one chunk (state ``st`` carried in place; see the module docstring): for each sample, one
    section per sensor in this order — predict, accelerometer noise level, rest, kinematic compensation,
    accelerometer gate, low-pass and update, magnetometer, external heading, outputs and self-check.

    t (N,) s; gyro/acc/mag (N,3); sog (N,) m/s or None, cog (N,) rad, sogdot (N,) m/s² (use_gnss: 0 not used, 1 the
    turn's centripetal term along the course, 2 along the bow, where no heading is held); vel (N,2) or None: the GNSS
    antenna's north/east velocity (m/s) for velocity aiding (compensation.py), arm_sa (3,) m body FRD the sensor's
    position from the antenna's; outputs q_out (N,4), b_out (N,3), std_out (N,3) roll/pitch/heading σ rad,
    flags_out (N,) bit mask, p_store (N,6,6) or empty: posterior P per sample (for the smoother); acc_meas (N,3)
    or empty: the smoother's compensated, low-passed force (m/s² body; NaN: no update) in place of the causal
    low-pass; f_out (N,3) or empty: the compensated force fed to the low-pass (NaN where none); hdg (N,) or None:
    an external true heading (rad, NED; NaN: none; heading_input.py). None leaves that input's section out of the
    compiled kernel (see the module's docstring, "Inputs not given").
    """
    n = t.shape[0]
    ext_meas, keep_f, store = acc_meas.shape[0] == n, f_out.shape[0] == n, p_store.shape[0] == n
    P = st[S_P : S_P + 36].reshape((6, 6))
    # np.empty in two shapes and zeros written in (np.zeros compiles np.empty with a dtype and a fill of its own:
    # six small functions more on a first run)
    R, RI, MLAG, X33, dx = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty(6)
    MLAG[:] = 0.0
    dx[:] = 0.0
    use_lp = prm[P_ACC_TAU] > 0
    lag = prm[P_ACC_LAG] > 0 and use_lp and not ext_meas  # the low-pass's lag term ages every row
    gate = np.empty(5)  # the magnetometer's dip gate: cos, sin of the gate; the reference dip, its bounds (magnetic.py)
    gate[0], gate[1] = np.cos(prm[P_MAG_DIP_GATE]), np.sin(prm[P_MAG_DIP_GATE])
    gate[2], gate[3], gate[4] = _dip_gate(st[S_MREF + 2], gate[0], gate[1])
    use_lever = lever[0] != 0.0 or lever[1] != 0.0 or lever[2] != 0.0  # once per chunk, not per sample
    use_va = FALSE  # not False: a literal would reach the sections as a type of its own (layout.py)
    if vel is not None:
        use_va = vel.shape[0] == n and use_lp and not ext_meas
    for k in range(n):
        gk0, gk1, gk2, dt, w0, w1, w2, gap = _predict(
            st, P, prm, t[k], gyro[k, 0], gyro[k, 1], gyro[k, 2], cov_every_sample
        )
        rmat(st[0], st[1], st[2], st[3], R)  # R(q) body→NED, predicted
        ax, ay, az = acc[k, 0], acc[k, 1], acc[k, 2]
        acc_ok = np.isfinite(ax) and np.isfinite(ay) and np.isfinite(az)
        flag = 0
        if acc_ok and prm[P_ACC_WN_GAIN] > 0:
            _accel_white_noise(st, prm, ax, ay, az, dt)
        if prm[P_REST_TIME] > 0 and acc_ok:
            flag |= _rest(st, P, prm, dx, R, gk0, gk1, gk2, ax, ay, az, dt, update_every)
        ri_now = FALSE  # RI = R(q_I) computed for this sample
        if vel is not None and use_va:  # kinematic compensation (compensation.py): velocity aiding, lever, GNSS turn
            ri_now = _velocity_aiding(
                st, R, RI, t[k], vel[k, 0], vel[k, 1], w0, w1, w2, arm_sa, ax, ay, az, dt, gap, acc_ok
            )
        if use_lever:
            ax, ay, az = _lever_arm(st, prm, lever, gk0, gk1, gk2, dt, ax, ay, az, acc_ok)
        if sog is not None and acc_ok and use_gnss > 0 and not use_va:
            if np.isfinite(sog[k]) and (use_gnss == 2 or np.isfinite(cog[k])):
                ax, ay, az = _gnss_force(st, R, gk0, gk1, gk2, sog[k], cog[k], sogdot[k], use_gnss == 2, ax, ay, az)
        rej, force, na, dev_a, fed = False, False, 0.0, 0.0, False
        if acc_ok:  # the accelerometer (accel.py): gate and tilt window, quasi-inertial low-pass, update
            rej, force, na, dev_a = _accel_gate(st, prm, R, ax, ay, az, dt, gap)
            if keep_f and (not rej or force):
                f_out[k, 0], f_out[k, 1], f_out[k, 2] = ax, ay, az
            aided = use_va and st[S_VA_OK] > 0  # the last interval's force less the GNSS velocity's change
            if use_lp and not ext_meas and (aided or not rej or force):
                _accel_low_pass(st, prm, RI, ax, ay, az, dt, aided, ri_now)
                ri_now = fed = True
                if aided and keep_f:  # the force the low-pass took, in the body (the smoother and gyro check read it)
                    for i in range(3):
                        f_out[k, i] = RI[0, i] * st[S_VA_IN] + RI[1, i] * st[S_VA_IN + 1] + RI[2, i] * st[S_VA_IN + 2]
        if not fed and lag and st[S_LPINIT] > 0 and dt > 0 and not gap:
            _age_low_pass(st, RI, dt)
            ri_now = True
        if ext_meas:  # the smoother's zero-lag low-pass of the same compensated force (NaN: none)
            if np.isfinite(acc_meas[k, 0]):
                st[S_USE_A] += 1.0
            if acc_ok:
                ax, ay, az = acc_meas[k, 0], acc_meas[k, 1], acc_meas[k, 2]
                na = np.sqrt(ax * ax + ay * ay + az * az)
        if acc_ok and rej and not force:  # a shock: a due update waits for the next sample
            flag |= F_ACC_REJ
        elif acc_ok and st[S_CNT_A] >= update_every and na > 0:
            flag |= _accel_update(st, P, prm, R, RI, MLAG, X33, dx, ax, ay, az, na, dev_a, dt, force, ri_now, ext_meas)
        mx, my, mz = mag[k, 0], mag[k, 1], mag[k, 2]  # the magnetometer (magnetic.py): gates, update when due
        if mag_mode > 0 and np.isfinite(mx) and np.isfinite(my) and np.isfinite(mz):
            rej_m, dev_m, flag_m = _mag_sample(st, P, prm, R, mx, my, mz, w0, w1, w2, dt, gate)
            flag |= flag_m
            if not rej_m and st[S_CNT_M] >= update_every:
                flag |= _mag_update(st, P, prm, R, dx, dev_m, w0, w1, w2, dt, mag_mode, gate)
        if hdg is not None and hdg.shape[0] > 0 and np.isfinite(hdg[k]) and t[k] - st[S_HLAST] >= prm[P_HDG_EVERY]:
            if _heading_input(st, P, prm, R, dx, t[k], hdg[k]):
                flag |= F_HDG_USED
        v0, v1 = _outputs(st, P, k, q_out, b_out, std_out)  # outputs, then the per-sample self-check
        flags_out[k] = flag | _self_check(st, prm, v0, v1)
        if store:
            for i in range(6):
                for j in range(6):
                    p_store[k, i, j] = P[i, j]
