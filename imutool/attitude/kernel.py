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
  for rest_time s) adds a zero-rate pseudo-measurement of the bias; optional GNSS compensation of the
  kinematic acceleration: a_ned = SȮG·[cos χ, sin χ, 0] + SOG·r·[−sin χ, cos χ, 0] (χ = COG, r = the world
  vertical rate from the gyro) is subtracted from the measured specific force (f = Rᵀ(a_ned − g_ned)).
- NaN rows: a NaN gyro sample is replaced by the last good one (counted); NaN accel/mag skip that update.
"""

from __future__ import annotations

import numpy as np
from numba import njit

import formats.kernel_cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from imutool.attitude.accel import (
    accel_feed,
    accel_gate,
    accel_update,
    learn_accel_noise,
    lever_compensate,
    lever_rate_step,
)
from imutool.attitude.heading_input import heading_input_step
from imutool.attitude.layout import (
    _FASTMATH,
    F_INCONSISTENT,
    P_ACC_TAU,
    P_ACC_WN_GAIN,
    P_HDG_EVERY,
    P_MAG_DIP_GATE,
    P_REST_TIME,
    S_HLAST,
    S_MREF,
    S_NINC,
    S_P,
    S_USE_A,
)
from imutool.attitude.magnetic import _dip_gate, mag_gate, mag_update
from imutool.attitude.outputs import output_step
from imutool.attitude.predict import predict_step
from imutool.attitude.rest import rest_step
from imutool.quaternion import rmat


@njit(cache=True, fastmath=_FASTMATH, nogil=True, error_model="numpy")
def ekf_kernel(
    t,
    gyro,
    acc,
    mag,
    sog,
    cog,
    sogdot,
    prm,
    update_every,
    mag_mode,
    cov_every_sample,
    use_gnss,
    lever,
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

    t (N,) s; gyro/acc/mag (N,3); sog (N,) m/s, cog (N,) rad, sogdot (N,) m/s² (ignored unless use_gnss);
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
    store = p_store.shape[0] == n
    use_lp = prm[P_ACC_TAU] > 0
    RI = np.empty((3, 3))
    MLAG = np.zeros((3, 3))
    X33 = np.empty((3, 3))
    cos_gate, sin_gate = np.cos(prm[P_MAG_DIP_GATE]), np.sin(prm[P_MAG_DIP_GATE])
    dip = np.empty(3)  # the reference's dip gate: sin of the dip, its lower and upper bound
    dip[0], dip[1], dip[2] = _dip_gate(st[S_MREF + 2], cos_gate, sin_gate)
    use_lever = lever[0] != 0.0 or lever[1] != 0.0 or lever[2] != 0.0  # once per chunk, not per sample
    for k in range(n):
        # one sample, the sensors in a written order: predict, accelerometer noise, rest, accelerometer (compensation,
        # gate, low-pass, update), magnetometer (gates every sample, the update when due), external heading, outputs
        dt, gap, w0, w1, w2, gk0, gk1, gk2 = predict_step(
            st, P, prm, t[k], gyro[k, 0], gyro[k, 1], gyro[k, 2], use_lp, cov_every_sample
        )
        rmat(st[0], st[1], st[2], st[3], R)
        ax, ay, az = acc[k, 0], acc[k, 1], acc[k, 2]
        acc_ok = np.isfinite(ax) and np.isfinite(ay) and np.isfinite(az)
        if acc_ok and prm[P_ACC_WN_GAIN] > 0:
            learn_accel_noise(st, prm, ax, ay, az, dt)
        flag = 0
        if prm[P_REST_TIME] > 0 and acc_ok:
            flag |= rest_step(st, P, prm, R, dx, gk0, gk1, gk2, ax, ay, az, dt, update_every)
        rej, force, na, dev_a = False, False, 0.0, 0.0
        if use_lever and dt > 0:
            lever_rate_step(st, prm, gk0, gk1, gk2, dt)
        if acc_ok and use_lever:
            ax, ay, az = lever_compensate(st, lever, ax, ay, az)
        if acc_ok:
            ax, ay, az, na, dev_a, rej, force = accel_gate(
                st, prm, R, sog, cog, sogdot, k, use_gnss, gk0, gk1, gk2, ax, ay, az, dt
            )
        ri_now = accel_feed(st, prm, R, RI, ax, ay, az, acc_ok, rej, force, dt, gap, use_lp, ext_meas, keep_f, f_out, k)
        if ext_meas and np.isfinite(acc_meas[k, 0]):
            st[S_USE_A] += 1.0  # the smoother's zero-lag low-pass had this sample
        # fmt: off
        flag |= accel_update(st, P, prm, R, RI, MLAG, X33, dx, acc_meas, k, ax, ay, az, acc_ok, rej, force, na, dev_a,
                             ri_now, dt, use_lp, ext_meas, update_every)
        # fmt: on
        mx, my, mz = mag[k, 0], mag[k, 1], mag[k, 2]
        if mag_mode > 0 and np.isfinite(mx) and np.isfinite(my) and np.isfinite(mz):
            rej_m, dev_m, fm = mag_gate(st, P, prm, R, dip, mx, my, mz, w0, w1, w2, dt, cos_gate, sin_gate)
            flag |= fm
            flag |= mag_update(
                st, P, prm, R, dx, dip, rej_m, dev_m, w0, w1, w2, dt, mag_mode, update_every, cos_gate, sin_gate
            )
        if hdg.shape[0] > 0 and np.isfinite(hdg[k]) and t[k] - st[S_HLAST] >= prm[P_HDG_EVERY]:
            flag |= heading_input_step(st, P, prm, R, dx, t[k], hdg[k])
        if output_step(st, P, prm, q_out, b_out, std_out, k):
            flag |= F_INCONSISTENT
            st[S_NINC] += 1
        flags_out[k] = flag
        if store:
            for i in range(6):
                for j in range(6):
                    p_store[k, i, j] = P[i, j]
