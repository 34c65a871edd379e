"""The GNSS-velocity-aided attitude filter (issue 50): a loosely coupled error-state INS that estimates roll and pitch
from the velocity fixes as Kalman measurements, with velocity and accelerometer-bias states.

Frames and units: body FRD, world NED, q = [w, x, y, z] body→NED, gyro rad/s, accel m/s² (specific force), velocity
m/s, time s. docs/attitude.md, "GNSS velocity as a measurement".

Nominal state, advanced every sample: q (the gyro less its bias b_g integrated, q ← q ⊗ exp((ω − b_g) dt)), the
sensor's horizontal velocity v = (v_N, v_E) (v ← v + [R (f − b_a)]_NE dt: gravity has no horizontal part), b_g and
b_a (rad/s, m/s²). Error state (11): δx = [ψ (3, world-frame attitude error: R_true = (I + [ψ×]) R), δv (2), δb_g
(3), δb_a (3)], with the continuous-time model

    ψ̇ = −R δb_g + n_g,   δv̇ = [−f_n× ψ − R δb_a]_NE + n_a,   δḃ_g = n_bg,   δḃ_a = n_ba     (f_n = R (f − b_a)).

Its transition over an interval is built from three sums taken every sample (cheap): A = ∫ R dt, F = ∫ f_n dt and
C = ∫ [f_n×] A dt, so Φ = I with Φ_ψ,bg = −A, Φ_v,ψ = −[F×]_NE, Φ_v,bg = C_NE, Φ_v,ba = −A_NE; the covariance is
propagated only at a fix (and at least once a second without one, so the σ keep growing in an outage).

Measurements: each new GNSS velocity fix (a row where the velocity changes, or a finite row after NaN rows; held
repeats are not counted again), moved from the antenna to the sensor by R (ω × r) (r the sensor's position from the
antenna, body FRD), z = v_gnss + [R (ω × r)]_NE − v, H = [[a×]_NE, I₂, −[R [r×]]_NE, 0] with a = R (ω × r) (the
lever term turns with the attitude error and holds the gyro bias), R_v = σ_v² + (σ_ω |r|)² (the gyro's noise on the
lever term); gated on its normalised innovation squared (skipped and counted above ``gnss_nis_gate``, taken
again after ``reject_timeout`` s of continuous rejection). The heading is the first pass's (the EKF's magnetometer
or external heading), a scalar measurement of ψ_D at most once per ``heading_input_interval``, σ twice that
filter's heading σ (its errors are correlated over tens of seconds). There is no accelerometer tilt update: with the
velocity measured, δv̇ = −g ψ_horizontal observes the tilt directly, and the accelerometer's bias with it once the
body turns (a body-fixed bias rotates in NED, a tilt error does not).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.frames import quat_multiply, quat_to_euler
from formats.jit.decorators import njit
from imutool.attitude.aided_layout import IBA, IBG, IV, N_COLS, N_DX, N_PHI, N_PP, N_PQ, N_ROW, N_START, NX, euler_std
from imutool.attitude.aided_rts import node_capacity, smooth_aided
from imutool.attitude.layout import _FASTMATH, CALLED, INLINED
from imutool.quaternion import qmul, qturn, rmat, rotvec_quat

# ---- the aided filter's state vector (carried between chunks) ----
A_Q, A_V, A_BG, A_BA, A_P = 0, 4, 6, 9, 12  # q (4), v_NE (2), b_g (3), b_a (3), P (121, row-major 11×11)
A_INT, A_F, A_C, A_T, A_TURN = 133, 142, 145, 154, 155  # sums since the last propagation: ∫R dt, ∫f_n dt, ∫[f_n×]A dt
A_TPREV, A_GPREV, A_FPREV, A_VLAST = 156, 157, 160, 163  # previous time, gyro, force; the previous row's velocity (2)
A_INIT, A_TFIX, A_THDG, A_REJT = 165, 166, 167, 168  # started; last fix time; last heading update; time rejected
A_NFIX, A_NREJ, A_NHELD, A_NHDG, A_TSTART = 169, 170, 171, 172, 173  # counts; the time the filter started
A_NIS = 174  # the velocity fixes' mean NIS per degree of freedom (running, over about NIS_FIXES fixes)
A_T0 = 175  # the time of the first row (s)
A_NRESTART = 176  # restarts after a divergence
A_NNODE = 177  # nodes recorded for the smoother in this call (its capacity exceeded: −1)
A_RW_SCALE = 178  # the gyro bias instability used, as a multiple of aided_gyro_bias_rw (widened after divergence)
A_SIZE = 179
RESTART_RATIO = 3.0  # the running innovation ratio beyond which the filter restarts from the first pass
MAX_RESTARTS = 2  # more restarts than this over a run (or a streamed chunk): its output is not used
# a pass that restarted is run again with the gyro's bias instability × WIDEN_FACTOR (at most WIDEN_TRIES times) and
# the one that restarts least kept: a gyro whose bias wanders more than stated (the commonest cause) is then followed
WIDEN_FACTOR, WIDEN_TRIES = 4.0, 2
NIS_FIXES = 30.0
# ---- its parameter vector ----
(
    Q_GYRO,
    Q_GYRO_RW,
    Q_ACC,
    Q_ACC_RW,
    Q_VEL,
    Q_GATE,
    Q_SCALE,
    Q_HDG_FLOOR,
    Q_HDG_EVERY,
    Q_REJ_TIMEOUT,
    Q_MIN_SPACING,
    Q_START_SIGMA,
    Q_BIAS_SIGMA,
    Q_GYRO_BIAS_SIGMA,
    Q_DT,
    Q_PREV_W,
    Q_START_AFTER,
) = range(17)
N_APRM = 17
PROPAGATE_EVERY_S = 1.0  # s: without a fix the covariance is propagated at least this often
START_TILT_SIGMA, START_HEADING_SIGMA = np.radians(2.0), np.radians(5.0)  # rad: the least σ the filter starts with


@njit(**CALLED)
def _propagate(ast, P, prm, PHI, TMP):
    """P ← Φ P Φᵀ + Q over the interval summed since the last propagation (module docstring); the sums restart."""
    T = ast[A_T]
    for i in range(NX):
        for j in range(NX):
            PHI[i, j] = 1.0 if i == j else 0.0
    if T <= 0.0:
        return
    F0, F1, F2 = ast[A_F], ast[A_F + 1], ast[A_F + 2]
    # −[F×] rows N, E: [F×] = [[0, −F2, F1], [F2, 0, −F0], [−F1, F0, 0]]
    PHI[IV, 1], PHI[IV, 2] = F2, -F1
    PHI[IV + 1, 0], PHI[IV + 1, 2] = -F2, F0
    for i in range(3):
        for j in range(3):
            PHI[i, IBG + j] = -ast[A_INT + 3 * i + j]
    for i in range(2):
        for j in range(3):
            PHI[IV + i, IBG + j] = ast[A_C + 3 * i + j]
            PHI[IV + i, IBA + j] = -ast[A_INT + 3 * i + j]
    for i in range(NX):  # TMP = Φ P
        for j in range(NX):
            s = 0.0
            for m in range(NX):
                s += PHI[i, m] * P[m, j]
            TMP[i, j] = s
    for i in range(NX):  # P = TMP Φᵀ
        for j in range(i, NX):
            s = 0.0
            for m in range(NX):
                s += TMP[i, m] * PHI[j, m]
            P[i, j] = s
            P[j, i] = s
    qa = prm[Q_GYRO] ** 2 * T + (prm[Q_SCALE] * ast[A_TURN]) ** 2
    for i in range(3):
        P[i, i] += qa
        P[IBG + i, IBG + i] += prm[Q_GYRO_RW] ** 2 * T
        P[IBA + i, IBA + i] += prm[Q_ACC_RW] ** 2 * T
    for i in range(2):
        P[IV + i, IV + i] += prm[Q_ACC] ** 2 * T
    for i in range(A_INT, A_TURN + 1):
        ast[i] = 0.0


@njit(**CALLED)
def _correct(ast, P, dx, K, TMP, H, nz, y0, y1, r0, r1, gate):
    """A measurement y = H δx + noise (nz = 1 or 2 rows of H (2, NX); innovations y, variances r): the gated update,
    applied to the nominal state. Returns the NIS, or −NIS where it was gated out."""
    for i in range(NX):  # TMP[:, :nz] = P Hᵀ
        for r in range(nz):
            s = 0.0
            for m in range(NX):
                s += P[i, m] * H[r, m]
            TMP[i, r] = s
    s00 = r0
    s01, s11 = 0.0, r1
    for m in range(NX):
        s00 += H[0, m] * TMP[m, 0]
        if nz == 2:
            s01 += H[0, m] * TMP[m, 1]
            s11 += H[1, m] * TMP[m, 1]
    if nz == 1:
        i00, i01, i11 = 1.0 / s00, 0.0, 0.0
        nis = y0 * y0 / s00
    else:
        det = s00 * s11 - s01 * s01
        i00, i01, i11 = s11 / det, -s01 / det, s00 / det
        nis = y0 * y0 * i00 + 2 * y0 * y1 * i01 + y1 * y1 * i11
    if gate > 0 and nis > gate:
        return -nis
    for i in range(NX):  # K = P Hᵀ S⁻¹
        a = TMP[i, 0]
        b = TMP[i, 1] if nz == 2 else 0.0
        K[i, 0] = a * i00 + b * i01
        K[i, 1] = a * i01 + b * i11
        dx[i] = K[i, 0] * y0 + K[i, 1] * y1
    # P ← P − K (H P) = P − K (P Hᵀ)ᵀ (symmetric)
    for i in range(NX):
        for j in range(i, NX):
            v = P[i, j] - K[i, 0] * TMP[j, 0] - (K[i, 1] * TMP[j, 1] if nz == 2 else 0.0)
            P[i, j] = v
            P[j, i] = v
    # the nominal state: q ← δq(ψ) ⊗ q (a world-frame error), v, b_g, b_a += their corrections
    e0, e1, e2, e3 = rotvec_quat(dx[0], dx[1], dx[2])
    q0, q1, q2, q3 = qmul(e0, e1, e2, e3, ast[A_Q], ast[A_Q + 1], ast[A_Q + 2], ast[A_Q + 3])
    nq = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    ast[A_Q], ast[A_Q + 1], ast[A_Q + 2], ast[A_Q + 3] = q0 / nq, q1 / nq, q2 / nq, q3 / nq
    for i in range(2):
        ast[A_V + i] += dx[IV + i]
    for i in range(3):
        ast[A_BG + i] += dx[IBG + i]
        ast[A_BA + i] += dx[IBA + i]
    return nis


@njit(**CALLED)
def _start(ast, P, prm, q, b, std):
    """Start the filter at a fix: attitude and gyro bias from the first pass (q, b rad/s; its roll/pitch/heading σ
    std rad); P from those σ and the parameters' priors (the caller sets the velocity)."""
    for i in range(4):
        ast[A_Q + i] = q[i]
    for i in range(3):
        ast[A_BG + i] = b[i]
    for i in range(NX * NX):
        ast[A_P + i] = 0.0
    # the first pass's σ at its start are often optimistic: at least START_TILT_SIGMA, START_HEADING_SIGMA
    st = max(2.0 * std[0], 2.0 * std[1], START_TILT_SIGMA)
    P[0, 0] = P[1, 1] = st * st
    P[2, 2] = max(2.0 * std[2], START_HEADING_SIGMA) ** 2
    P[IV, IV] = P[IV + 1, IV + 1] = prm[Q_VEL] ** 2
    for i in range(3):
        P[IBG + i, IBG + i] = prm[Q_GYRO_BIAS_SIGMA] ** 2
        P[IBA + i, IBA + i] = prm[Q_BIAS_SIGMA] ** 2
    for i in range(A_INT, A_TURN + 1):
        ast[i] = 0.0
    ast[A_INIT] = 1.0


@njit(**INLINED)
def _outputs(ast, P, R, k, q_out, std_out, ba_out, ba_std, smoothed):
    """Row k: q, the roll/pitch/heading σ (rad), b_a and its σ (m/s²; the σ not where the smoother sets them)."""
    for i in range(4):
        q_out[k, i] = ast[A_Q + i]
    for i in range(3):
        ba_out[k, i] = ast[A_BA + i]
    if not smoothed:
        for i in range(3):
            ba_std[k, i] = np.sqrt(max(P[IBA + i, IBA + i], 0.0))
        euler_std(R, P, std_out, k)


@njit(**CALLED)
def _node_open(nodes, ast, k, PHI, P, start):
    """A smoother node at row k: Φ into it, P⁻ = P⁺ = P, no correction yet; its index (−1: none kept)."""
    m = int(ast[A_NNODE])
    if m < 0 or m >= nodes.shape[0]:
        if nodes.shape[0] > 0:
            ast[A_NNODE] = -1.0  # capacity exceeded: the run is not smoothed
        return -1
    nodes[m, N_ROW], nodes[m, N_START] = k, start
    for i in range(NX):
        nodes[m, N_DX + i] = 0.0
        for j in range(NX):
            nodes[m, N_PHI + i * NX + j] = PHI[i, j]
            nodes[m, N_PP + i * NX + j] = P[i, j]
            nodes[m, N_PQ + i * NX + j] = P[i, j]
    ast[A_NNODE] = m + 1
    return m


@njit(**CALLED)
def _node_update(nodes, m, P, dx, add):
    """Node m after an update: the correction dx added (if ``add``), P⁺ = P."""
    if m < 0:
        return
    for i in range(NX):
        if add:
            nodes[m, N_DX + i] += dx[i]
        for j in range(NX):
            nodes[m, N_PQ + i * NX + j] = P[i, j]


@njit(**CALLED)
def _at_fix(ast, P, prm, PHI, TMP, K, dx, H, R, arm, rv, w0, w1, w2, vn, ve, tk, qe, hstd, nodes, k):
    """A new velocity fix (vn, ve m/s, the antenna's) at row k, time tk, with the bias-free rate w (rad/s) and the
    first pass's q and heading σ (qe, hstd rad): propagate, update (gated), the heading now and then, a node."""
    _propagate(ast, P, prm, PHI, TMP)
    m = _node_open(nodes, ast, k, PHI, P, 0.0)
    # the sensor's velocity: the antenna's plus R (ω × r)
    c0, c1, c2 = w1 * arm[2] - w2 * arm[1], w2 * arm[0] - w0 * arm[2], w0 * arm[1] - w1 * arm[0]
    y0 = vn + R[0, 0] * c0 + R[0, 1] * c1 + R[0, 2] * c2 - ast[A_V]
    y1 = ve + R[1, 0] * c0 + R[1, 1] * c1 + R[1, 2] * c2 - ast[A_V + 1]
    gate = prm[Q_GATE] if ast[A_REJT] < prm[Q_REJ_TIMEOUT] else 0.0
    # the self-check: a velocity whose errors are not white (a track-smoothed SOG/COG, a receiver worse
    # than stated) or a gyro worse than the parameters say shows as a mean innovation ratio above 1
    # H: δv, and the lever term's gyro bias: the computed sensor velocity holds R (δb_g × r) = −R [r×] δb_g
    a0, a1, a2 = y0 + ast[A_V] - vn, y1 + ast[A_V + 1] - ve, R[2, 0] * c0 + R[2, 1] * c1 + R[2, 2] * c2  # R (ω × r)
    for i in range(2):
        for j in range(NX):
            H[i, j] = 0.0
        H[i, IV + i] = 1.0
    # the lever term's attitude error: R_true (ω × r) = R (ω × r) − [R (ω × r)×] ψ, so z holds +[a×] ψ (a = R (ω × r))
    H[0, 1], H[0, 2] = -a2, a1
    H[1, 0], H[1, 2] = a2, -a0
    for i in range(2):
        H[i, IBG] = R[i, 2] * arm[1] - R[i, 1] * arm[2]  # (−R [r×])[i, :]
        H[i, IBG + 1] = R[i, 0] * arm[2] - R[i, 2] * arm[0]
        H[i, IBG + 2] = R[i, 1] * arm[0] - R[i, 0] * arm[1]
    ratio = (y0 * y0 + y1 * y1) / (P[IV, IV] + P[IV + 1, IV + 1] + 2.0 * rv)
    nis = _correct(ast, P, dx, K, TMP, H, 2, y0, y1, rv, rv, gate)
    ast[A_NIS] += (min(ratio, 100.0) - ast[A_NIS]) / NIS_FIXES
    if ast[A_NIS] > RESTART_RATIO:  # diverged (a start from an unsettled first pass): start again from it
        ast[A_INIT], ast[A_NIS] = 0.0, 1.0
        ast[A_NRESTART] += 1
    _node_update(nodes, m, P, dx, nis >= 0)
    if nis < 0:
        ast[A_NREJ] += 1
        ast[A_REJT] += tk - ast[A_TFIX]
    else:
        ast[A_NFIX] += 1
        ast[A_REJT] = 0.0
    ast[A_TFIX] = tk
    if tk - ast[A_THDG] >= prm[Q_HDG_EVERY] and np.isfinite(qe[0]):
        _node_update(nodes, m, P, dx, _heading(ast, P, prm, dx, K, TMP, H, R, qe, hstd))
        ast[A_THDG] = tk


@njit(cache=True, fastmath=_FASTMATH, nogil=True, error_model="numpy")
def aided_kernel(t, gyro, acc, vel, ekf_q, ekf_b, ekf_std, arm, prm, ast, q_out, std_out, ba_out, ba_std, nodes):
    """Run the aided filter over one chunk (state ``ast`` carried in place; module docstring). t (N,) s; gyro (N,3)
    rad/s; acc (N,3) m/s²; vel (N,2) the GNSS north/east velocity (m/s; held, or NaN between fixes); ekf_q (N,4),
    ekf_b (N,3) rad/s, ekf_std (N,3) rad: the first pass's attitude, gyro bias and σ (the start, the heading); arm
    (3,) m body FRD the sensor's position from the antenna. Outputs q_out (N,4) (NaN before the start), std_out (N,3)
    roll/pitch/heading σ rad, ba_out/ba_std (N,3) m/s²; nodes (M, N_COLS) the smoother's record (M = 0: none)."""
    n = t.shape[0]
    ast[A_NNODE] = 0.0
    P = ast[A_P : A_P + NX * NX].reshape((NX, NX))
    R, PHI, TMP, K, dx = np.empty((3, 3)), np.empty((NX, NX)), np.empty((NX, NX)), np.zeros((NX, 2)), np.zeros(NX)
    H = np.zeros((2, NX))
    arm2 = arm[0] * arm[0] + arm[1] * arm[1] + arm[2] * arm[2]
    rv = prm[Q_VEL] ** 2 + prm[Q_GYRO] ** 2 / prm[Q_DT] * arm2  # the fix's variance, the lever term's noise in it
    for k in range(n):
        tk = t[k]
        g0, g1, g2 = gyro[k, 0], gyro[k, 1], gyro[k, 2]
        if not (np.isfinite(g0) and np.isfinite(g1) and np.isfinite(g2)):
            g0, g1, g2 = ast[A_GPREV], ast[A_GPREV + 1], ast[A_GPREV + 2]
        f0, f1, f2 = acc[k, 0], acc[k, 1], acc[k, 2]
        if not (np.isfinite(f0) and np.isfinite(f1) and np.isfinite(f2)):
            f0, f1, f2 = ast[A_FPREV], ast[A_FPREV + 1], ast[A_FPREV + 2]
        ast[A_FPREV], ast[A_FPREV + 1], ast[A_FPREV + 2] = f0, f1, f2
        w0, w1, w2 = g0 - ast[A_BG], g1 - ast[A_BG + 1], g2 - ast[A_BG + 2]
        # the rate over the step: ω_k, or ½(ω_{k−1} + ω_k) (gyro_integration; the force likewise)
        h = prm[Q_PREV_W]
        u0 = (1 - h) * w0 + h * (ast[A_GPREV] - ast[A_BG])
        u1 = (1 - h) * w1 + h * (ast[A_GPREV + 1] - ast[A_BG + 1])
        u2 = (1 - h) * w2 + h * (ast[A_GPREV + 2] - ast[A_BG + 2])
        ast[A_GPREV], ast[A_GPREV + 1], ast[A_GPREV + 2] = g0, g1, g2
        started = ast[A_INIT] > 0
        dt = tk - ast[A_TPREV]
        ast[A_TPREV] = tk
        if started and dt > 0:
            q0, q1, q2, q3 = qturn(ast[A_Q], ast[A_Q + 1], ast[A_Q + 2], ast[A_Q + 3], u0 * dt, u1 * dt, u2 * dt)
            ast[A_Q], ast[A_Q + 1], ast[A_Q + 2], ast[A_Q + 3] = q0, q1, q2, q3
            rmat(q0, q1, q2, q3, R)
            f0, f1, f2 = f0 - ast[A_BA], f1 - ast[A_BA + 1], f2 - ast[A_BA + 2]
            n0 = R[0, 0] * f0 + R[0, 1] * f1 + R[0, 2] * f2
            n1 = R[1, 0] * f0 + R[1, 1] * f1 + R[1, 2] * f2
            n2 = R[2, 0] * f0 + R[2, 1] * f1 + R[2, 2] * f2
            ast[A_V] += n0 * dt
            ast[A_V + 1] += n1 * dt
            ast[A_F] += n0 * dt
            ast[A_F + 1] += n1 * dt
            ast[A_F + 2] += n2 * dt
            for j in range(3):  # A += R dt, then C += [f_n×] A dt (rows N, E)
                ast[A_INT + j] += R[0, j] * dt
                ast[A_INT + 3 + j] += R[1, j] * dt
                ast[A_INT + 6 + j] += R[2, j] * dt
                a0, a1, a2 = ast[A_INT + j], ast[A_INT + 3 + j], ast[A_INT + 6 + j]
                ast[A_C + j] += (n1 * a2 - n2 * a1) * dt
                ast[A_C + 3 + j] += (n2 * a0 - n0 * a2) * dt
            ast[A_T] += dt
            ast[A_TURN] += np.sqrt(u0 * u0 + u1 * u1 + u2 * u2) * dt
        elif started:
            rmat(ast[A_Q], ast[A_Q + 1], ast[A_Q + 2], ast[A_Q + 3], R)
        vn, ve = vel[k, 0], vel[k, 1]
        fix = np.isfinite(vn) and np.isfinite(ve) and not (vn == ast[A_VLAST] and ve == ast[A_VLAST + 1])
        if np.isfinite(vn) and not fix:
            ast[A_NHELD] += 1
        ast[A_VLAST], ast[A_VLAST + 1] = vn, ve
        if fix and started and tk - ast[A_TFIX] < prm[Q_MIN_SPACING]:
            fix = False
        if not started and not np.isfinite(ast[A_T0]):
            ast[A_T0] = tk
        settled = tk - ast[A_T0] >= prm[Q_START_AFTER] and max(ekf_std[k, 0], ekf_std[k, 1]) <= prm[Q_START_SIGMA]
        if fix and not started and settled:
            _start(ast, P, prm, ekf_q[k], ekf_b[k], ekf_std[k])
            rmat(ast[A_Q], ast[A_Q + 1], ast[A_Q + 2], ast[A_Q + 3], R)
            w0, w1, w2 = g0 - ast[A_BG], g1 - ast[A_BG + 1], g2 - ast[A_BG + 2]
            c0, c1, c2 = w1 * arm[2] - w2 * arm[1], w2 * arm[0] - w0 * arm[2], w0 * arm[1] - w1 * arm[0]
            ast[A_V] = vn + R[0, 0] * c0 + R[0, 1] * c1 + R[0, 2] * c2  # the sensor's: the antenna's + R (ω × r)
            ast[A_V + 1] = ve + R[1, 0] * c0 + R[1, 1] * c1 + R[1, 2] * c2
            ast[A_TFIX], ast[A_THDG], ast[A_TSTART] = tk, tk, tk
            _node_open(nodes, ast, k, PHI, P, 1.0)
            started = True
        elif fix and started:
            _at_fix(
                ast, P, prm, PHI, TMP, K, dx, H, R, arm, rv, w0, w1, w2, vn, ve, tk, ekf_q[k], ekf_std[k, 2], nodes, k
            )
            rmat(ast[A_Q], ast[A_Q + 1], ast[A_Q + 2], ast[A_Q + 3], R)
        elif started and ast[A_T] >= PROPAGATE_EVERY_S:
            _propagate(ast, P, prm, PHI, TMP)
            _node_update(nodes, _node_open(nodes, ast, k, PHI, P, 0.0), P, dx, False)
        if started:
            _outputs(ast, P, R, k, q_out, std_out, ba_out, ba_std, nodes.shape[0] > 0 and ast[A_NNODE] >= 0)
        else:
            for i in range(4):
                q_out[k, i] = np.nan
            for i in range(3):
                std_out[k, i], ba_out[k, i], ba_std[k, i] = np.nan, np.nan, np.nan


@njit(**CALLED)
def _heading(ast, P, prm, dx, K, TMP, H, R, qe, hstd):
    """The first pass's heading (its q, its heading σ rad) as a measurement of ψ_D, σ twice that filter's."""
    he = np.arctan2(2 * (qe[0] * qe[3] + qe[1] * qe[2]), 1 - 2 * (qe[2] * qe[2] + qe[3] * qe[3]))
    h = np.arctan2(R[1, 0], R[0, 0])
    y = (he - h + np.pi) % (2 * np.pi) - np.pi
    # the first pass's heading σ is optimistic while its magnetometer settles (~ its heading time constant): at
    # least HEADING_START_SIGMA then, falling off with HEADING_SETTLE_S
    early = HEADING_START_SIGMA * np.exp(-(ast[A_TPREV] - ast[A_TSTART]) / HEADING_SETTLE_S)
    r = max(2.0 * hstd, prm[Q_HDG_FLOOR], early) ** 2
    for j in range(NX):
        H[0, j] = 0.0
    H[0, 2] = 1.0
    if _correct(ast, P, dx, K, TMP, H, 1, y, 0.0, r, r, 0.0) >= 0:
        ast[A_NHDG] += 1
        return True
    return False


HEADING_FLOOR = np.radians(0.5)  # rad: the first pass's heading is never taken as better than this
HEADING_START_SIGMA, HEADING_SETTLE_S = np.radians(10.0), 20.0  # ... nor, at the start, than this, for ~ this long
AIDED_TRAPEZOID = True
# the filter starts from the first pass once that has run this long (s; its gyro bias learned to about
# START_GYRO_BIAS_SIGMA rad/s) and its roll and pitch σ are below aided_start_sigma_deg
START_AFTER_S, START_GYRO_BIAS_SIGMA = 0.0, 0.002


@dataclass
class AidedResult:
    """The aided filter's per-sample output (SI: q body→NED, NaN rows before its start; σ rad; b_a m/s²) and its
    counts."""

    q: np.ndarray
    std: np.ndarray
    accel_bias: np.ndarray
    accel_bias_std: np.ndarray
    summary: dict = field(default_factory=dict)

    def euler_deg(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r, p, h = quat_to_euler(self.q)
        return np.degrees(r), np.degrees(p), np.degrees(h)


def aided_vector(params, dt_nominal: float) -> np.ndarray:
    """The aided kernel's parameter vector from :class:`~imutool.attitude.params.EkfParams` (SI)."""
    prm = np.zeros(N_APRM)
    prm[Q_GYRO] = params.aided_gyro_noise
    prm[Q_GYRO_RW] = params.aided_gyro_bias_rw
    prm[Q_ACC] = params.aided_accel_noise
    prm[Q_ACC_RW] = params.accel_bias_rw
    prm[Q_VEL] = params.gnss_velocity_noise
    prm[Q_GATE] = params.gnss_nis_gate
    prm[Q_SCALE] = params.aided_gyro_scale_noise
    prm[Q_HDG_FLOOR] = HEADING_FLOOR
    prm[Q_HDG_EVERY] = params.heading_input_interval
    prm[Q_REJ_TIMEOUT] = params.reject_timeout
    prm[Q_MIN_SPACING] = params.gnss_min_interval
    prm[Q_START_SIGMA] = np.radians(params.aided_start_sigma_deg)
    prm[Q_BIAS_SIGMA] = params.accel_bias_sigma
    prm[Q_GYRO_BIAS_SIGMA] = START_GYRO_BIAS_SIGMA
    prm[Q_DT] = dt_nominal
    prm[Q_START_AFTER] = START_AFTER_S
    prm[Q_PREV_W] = 0.5 if AIDED_TRAPEZOID else params.gyro_prev_weight()
    return prm


def aided_initial_state(params) -> np.ndarray:
    """The aided filter's state before its start (it starts at the first fix where the first pass is settled)."""
    ast = np.zeros(A_SIZE)
    ast[A_Q] = 1.0
    ast[A_BA : A_BA + 3] = params.init_accel_bias
    ast[A_VLAST : A_VLAST + 2] = np.nan
    ast[A_TFIX] = ast[A_THDG] = ast[A_TSTART] = -np.inf
    ast[A_NIS] = 1.0
    ast[A_T0] = np.nan
    ast[A_RW_SCALE] = 1.0
    return ast


def run_aided(
    time: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    velocity_ne: np.ndarray,
    ekf_q: np.ndarray,
    ekf_bias: np.ndarray,
    ekf_std: np.ndarray,
    params,
    arm_sa: np.ndarray | None = None,
    dt_nominal: float | None = None,
    state: np.ndarray | None = None,
    smooth: bool = False,
) -> tuple[AidedResult, np.ndarray]:
    """The GNSS-velocity-aided filter over arrays (module docstring); returns (result, state for the next chunk).

    time (N,) s; gyro (N,3) rad/s; accel (N,3) m/s² (NaN: a missing or clipped sample); velocity_ne (N,2) m/s the
    antenna's north/east velocity (held between fixes or NaN); ekf_q/ekf_bias/ekf_std the first pass's
    (:func:`~imutool.attitude.run.run_ekf`) attitude, gyro bias (rad/s) and roll/pitch/heading σ (rad); arm_sa (3,)
    m body FRD the sensor's position from the antenna; ``params`` an :class:`~imutool.attitude.params.EkfParams`;
    ``smooth``: a whole recording (no state in or out), smoothed backward (:mod:`imutool.attitude.aided_rts`)."""

    t = np.ascontiguousarray(time, dtype=np.float64)
    n = len(t)
    if dt_nominal is None:
        d = np.diff(t[: min(n, 200_001)])
        d = d[d > 0]
        dt_nominal = float(np.median(d)) if d.size else 0.01
    ast = aided_initial_state(params) if state is None else np.array(state, dtype=np.float64)
    arm = np.zeros(3) if arm_sa is None else np.ascontiguousarray(arm_sa, dtype=np.float64)
    q, std, ba, bas = np.empty((n, 4)), np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
    nodes = np.empty((node_capacity(t, velocity_ne) if smooth and n else 0, N_COLS))

    def c(x: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(x, dtype=np.float64)

    start = ast.copy()
    inputs = (t, c(gyro), c(accel), c(velocity_ne), c(ekf_q), c(ekf_bias), c(ekf_std), arm)
    prm = aided_vector(params, dt_nominal)
    prm[Q_GYRO_RW] *= ast[A_RW_SCALE]  # widened after a divergence (aided_result); 1 otherwise
    aided_kernel(*inputs, prm, ast, q, std, ba, bas, nodes)
    if ast[A_NNODE] < 0:  # more nodes than the bound allowed (never expected): the forward pass, unsmoothed
        ast, nodes = start, nodes[:0]
        aided_kernel(*inputs, prm, ast, q, std, ba, bas, nodes)
    summary = {
        "started_s": None if not np.isfinite(ast[A_TSTART]) else round(float(ast[A_TSTART] - ast[A_T0]), 3),
        "velocity_fixes": int(ast[A_NFIX]),
        "velocity_rejected": int(ast[A_NREJ]),
        "held_rows_skipped": int(ast[A_NHELD]),
        "heading_updates": int(ast[A_NHDG]),
        "accel_bias_m_s2": [round(float(x), 5) for x in ast[A_BA : A_BA + 3]],
        "accel_bias_std_m_s2": [round(float(np.sqrt(ast[A_P + (IBA + i) * (NX + 1)])), 5) for i in range(3)],
        "gnss_velocity_noise_m_s": params.gnss_velocity_noise,
        # ≈ 1 when the velocity's and the gyro's noise are as stated; well above: the σ are under-stated
        "velocity_innovation_ratio": round(float(ast[A_NIS]), 3),
        "restarts": int(ast[A_NRESTART]),
    }
    if ast[A_RW_SCALE] != 1.0:  # widened after a divergence (aided_result)
        summary["gyro_bias_rw_used"] = float(params.aided_gyro_bias_rw * ast[A_RW_SCALE])
    result = AidedResult(q, std, ba, bas, summary)
    if smooth:
        summary["smoothed"] = smooth_aided(t, nodes, int(ast[A_NNODE]) if len(nodes) else 0, result)
    return result, ast


def velocity_is_fixes(velocity_ne: np.ndarray) -> bool:
    """Whether a velocity column holds fixes (held between them, or NaN between them) rather than an interpolation
    that changes on most rows (``--gnss`` interpolates a file's fixes onto the IMU rows): the aided filter takes
    fixes only; an interpolation is left to the EKF's velocity aiding."""
    v = np.asarray(velocity_ne, dtype=np.float64)[:, 0]
    both = np.isfinite(v[1:]) & np.isfinite(v[:-1])
    return not (both.sum() > 10 and np.mean(v[1:][both] != v[:-1][both]) > 0.5)


def aided_result(
    time: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    velocity_ne: np.ndarray,
    res,
    params,
    lever_arm: np.ndarray | None,
    antenna_arm: np.ndarray | None,
    dt_nominal: float | None = None,
    state: np.ndarray | None = None,
    smooth: bool = False,
) -> tuple[object, AidedResult, np.ndarray]:
    """(the EKF's result with the aided filter's attitude and σ where it is running and no less certain, the aided
    result, its state for the next chunk): the second pass of :func:`~imutool.attitude.recording.ekf_recording`
    (and of a streamed run, chunk by chunk) with a GNSS velocity. ``res`` an
    :class:`~imutool.attitude.run.AttitudeResult`; the arms (3,) m body FRD from the centre of rotation (None: 0)."""
    lever = np.zeros(3) if lever_arm is None else np.asarray(lever_arm, dtype=np.float64)
    ant = np.zeros(3) if antenna_arm is None else np.asarray(antenna_arm, dtype=np.float64)
    state = aided_initial_state(params) if state is None else np.array(state, dtype=np.float64)
    before = state[A_NRESTART]
    best = None
    for _ in range(WIDEN_TRIES + 1):
        aided, ast = run_aided(
            time, gyro, accel, velocity_ne, res.q, res.bias, res.std, params, lever - ant, dt_nominal, state, smooth
        )
        restarts = ast[A_NRESTART] - before
        if best is None or restarts < best[0]:  # the widest that is needed: fewer restarts than a narrower one
            best = (restarts, aided, ast)
        if restarts == 0 or state[A_RW_SCALE] >= WIDEN_FACTOR**WIDEN_TRIES:
            break  # (a streamed run carries the width: widened at most WIDEN_TRIES times over the whole run)
        # restarted: the same input, the width × 4 (a smoothed track diverges at any width: left to the EKF below)
        state[A_RW_SCALE] *= WIDEN_FACTOR  # (run_aided copies the state)
    restarts, aided, ast = best
    va = aided.std[:, 0] ** 2 + aided.std[:, 1] ** 2
    # the EKF's σ leaves out the accelerometer's bias (its tilt, b/g per axis): compared with it added
    vb = 2.0 * (params.accel_bias_sigma / params.gravity) ** 2
    use = np.isfinite(aided.q[:, 0]) & (va <= res.std[:, 0] ** 2 + res.std[:, 1] ** 2 + vb)
    if aided.summary["restarts"] > MAX_RESTARTS:  # the velocity is not the hull's (a smoothed track) or the gyro
        use[:] = False  # is worse than stated: the EKF's velocity aiding is the safer estimate
        wider = f", also with the gyro bias instability × {ast[A_RW_SCALE]:g}" if ast[A_RW_SCALE] != 1.0 else ""
        aided.summary["not_used"] = f"diverged {aided.summary['restarts']} times{wider}: the EKF's estimate is output"
    elif "gyro_bias_rw_used" in aided.summary:  # widened, and used
        used, told = aided.summary["gyro_bias_rw_used"], params.aided_gyro_bias_rw
        aided.summary["note"] = (
            f"the aided pass restarted with aided_gyro_bias_rw {told:g} and ran with {used:g} rad/s/√s (a gyro whose"
            " bias wanders more than stated is the commonest cause): state the gyro's figure"
        )
    q, std = res.q.copy(), res.std.copy()
    # the aided pass's attitude turned about the world's down axis onto the EKF's heading (the one that holds the
    # magnetometer or the gyrocompass: the aided pass takes it as a measurement and lags it after a start or a
    # jump); a turn about down keeps the aided gravity direction exactly, also near pitch ±90°
    _, _, ha = quat_to_euler(aided.q[use])
    _, _, he = quat_to_euler(res.q[use])
    half = 0.5 * np.angle(np.exp(1j * (he - ha)))  # half the heading difference, wrapped to (−π, π]
    turn = np.stack([np.cos(half), np.zeros_like(half), np.zeros_like(half), np.sin(half)], axis=1)
    q[use] = quat_multiply(turn, aided.q[use])
    std[use, :2] = aided.std[use, :2]
    aided.summary["rows_used"] = int(use.sum())
    return type(res)(res.time, q, res.bias, std, res.flags, res.summary, res.cov, res.force), aided, ast
