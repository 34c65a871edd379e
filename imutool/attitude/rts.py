"""The Rauch–Tung–Striebel pass over the stored EKF posteriors (:func:`rts_smooth`)."""

from __future__ import annotations

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.errors import ImutoolError
from formats.jit.decorators import njit
from imutool.attitude.covariance import _add_rrt, _propagate_cov
from imutool.attitude.layout import _FASTMATH, ATT
from imutool.attitude.params import EkfParams
from imutool.attitude.run import AttitudeResult, euler_std, nominal_dt
from imutool.quaternion import qmul, rmat, rotvec_quat, vertical_in_body


@njit(cache=True, fastmath=_FASTMATH)
def rts_kernel(
    t, gyro, q_f, b_f, p_f, gyro_noise, gyro_scale, head_scale, bias_rw, gap_dt, gap_rate, gyro_prev_w, q_s, b_s, p_s
):
    """Error-state Rauch–Tung–Striebel backward pass over a full-rate-covariance EKF run.

    With the filtered posterior (q_k, b_k, P_k) the prior at k+1 is recomputed (same prediction as the
    filter); G_k = P_k Fᵀ (P⁻_{k+1})⁻¹; δ_k = G_k (x^s_{k+1} ⊖ x⁻_{k+1}) with ⊖ = [2·vec(q⁻* ⊗ q^s), b^s − b⁻];
    x^s_k = x_k ⊕ δ_k; P^s_k = P_k + G_k (P^s_{k+1} − P⁻_{k+1}) G_kᵀ.
    """
    n = t.shape[0]
    R = np.empty((3, 3))
    phi = np.empty((3, 3))
    F = np.empty((6, 6))
    for i in range(4):
        q_s[n - 1, i] = q_f[n - 1, i]
    for i in range(3):
        b_s[n - 1, i] = b_f[n - 1, i]
    p_s[n - 1] = p_f[n - 1]
    Pp = np.empty((6, 6))
    d = np.empty(6)
    tmp6 = np.empty((6, 6))  # scratch, allocated once per call
    FP = np.empty((6, 6))
    L = np.zeros((6, 6))
    GT = np.empty((6, 6))
    GD = np.empty((6, 6))
    dxs = np.empty(6)
    for k in range(n - 2, -1, -1):
        dt = t[k + 1] - t[k]
        gap = dt > gap_dt
        dti = gap_dt if gap else dt
        w0 = gyro_prev_w * gyro[k, 0] + (1.0 - gyro_prev_w) * gyro[k + 1, 0] - b_f[k, 0]
        w1 = gyro_prev_w * gyro[k, 1] + (1.0 - gyro_prev_w) * gyro[k + 1, 1] - b_f[k, 1]
        w2 = gyro_prev_w * gyro[k, 2] + (1.0 - gyro_prev_w) * gyro[k + 1, 2] - b_f[k, 2]
        if not (np.isfinite(w0) and np.isfinite(w1) and np.isfinite(w2)):
            w0, w1, w2 = 0.0, 0.0, 0.0
        e0, e1, e2, e3 = rotvec_quat(w0 * dti, w1 * dti, w2 * dti)
        qp0, qp1, qp2, qp3 = qmul(q_f[k, 0], q_f[k, 1], q_f[k, 2], q_f[k, 3], e0, e1, e2, e3)
        rmat(e0, e1, e2, e3, R)
        for i in range(3):
            for j in range(3):
                phi[i, j] = R[j, i]
        for i in range(6):
            for j in range(6):
                Pp[i, j] = p_f[k, i, j]
        T = dt if dt > 0 else 0.0
        wn2 = w0 * w0 + w1 * w1 + w2 * w2 if not gap else 0.0
        _propagate_cov(Pp, phi, T, (gyro_noise**2 + gyro_scale**2 * wn2) * T, bias_rw**2 * T, F, tmp6)
        if (head_scale > 0 or gyro_scale > 0) and T > 0:  # the filter's scale-factor noise: tilt across the
            z0, z1, z2 = vertical_in_body(qp0, qp1, qp2, qp3)  # world vertical, heading along it
            _add_rrt(Pp, ATT, ATT, (head_scale * head_scale - gyro_scale * gyro_scale) * wn2 * T, z0, z1, z2)
        if gap:
            inc = (gap_rate * dt) ** 2
            for i in range(3):
                Pp[i, i] = min(Pp[i, i] + inc, 10.0)
        # G = P_k Fᵀ Pp⁻¹: Cholesky Pp = L Lᵀ, then Pp Gᵀ = F P_k column by column (no allocation)
        for i in range(6):
            for j in range(6):
                s = 0.0
                for m in range(6):
                    s += F[i, m] * p_f[k, m, j]
                FP[i, j] = s
        for j in range(6):
            for i in range(j, 6):
                s = Pp[i, j]
                for m in range(j):
                    s -= L[i, m] * L[j, m]
                if i == j:
                    L[j, j] = np.sqrt(max(s, 1e-300))
                else:
                    L[i, j] = s / L[j, j]
        for c in range(6):  # column c of Gᵀ
            for i in range(6):
                s = FP[i, c]
                for m in range(i):
                    s -= L[i, m] * GT[m, c]
                GT[i, c] = s / L[i, i]
            for i in range(5, -1, -1):
                s = GT[i, c]
                for m in range(i + 1, 6):
                    s -= L[m, i] * GT[m, c]
                GT[i, c] = s / L[i, i]
        # difference x^s_{k+1} ⊖ x⁻_{k+1}
        c0, c1, c2, c3 = qmul(qp0, -qp1, -qp2, -qp3, q_s[k + 1, 0], q_s[k + 1, 1], q_s[k + 1, 2], q_s[k + 1, 3])
        if c0 < 0:
            c0, c1, c2, c3 = -c0, -c1, -c2, -c3
        d[0], d[1], d[2] = 2 * c1, 2 * c2, 2 * c3
        for i in range(3):
            d[3 + i] = b_s[k + 1, i] - b_f[k, i]
        for i in range(6):  # dx = G d, G[i, m] = GT[m, i]
            s = 0.0
            for m in range(6):
                s += GT[m, i] * d[m]
            dxs[i] = s
        a0, a1, a2, a3 = qmul(q_f[k, 0], q_f[k, 1], q_f[k, 2], q_f[k, 3], 1.0, 0.5 * dxs[0], 0.5 * dxs[1], 0.5 * dxs[2])
        nq = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3)
        q_s[k, 0], q_s[k, 1], q_s[k, 2], q_s[k, 3] = a0 / nq, a1 / nq, a2 / nq, a3 / nq
        for i in range(3):
            b_s[k, i] = b_f[k, i] + dxs[3 + i]
        # P^s_k = P_k + G (P^s_{k+1} − Pp) Gᵀ
        for i in range(6):
            for j in range(6):
                s = 0.0
                for m in range(6):
                    s += GT[m, i] * (p_s[k + 1, m, j] - Pp[m, j])
                GD[i, j] = s
        for i in range(6):
            for j in range(i, 6):
                s = 0.0
                for m in range(6):
                    s += GD[i, m] * GT[m, j]
                v = 0.5 * (p_f[k, i, j] + p_f[k, j, i]) + s  # G D Gᵀ is symmetric: upper triangle mirrored
                p_s[k, i, j] = v
                p_s[k, j, i] = v


def rts_smooth(
    res: AttitudeResult, gyro: np.ndarray, params: EkfParams | None = None, dt_nominal: float | None = None
) -> AttitudeResult:
    """Backward RTS pass over a filter run made with ``keep_cov=True`` (zero-lag estimates)."""
    params = params or EkfParams()
    if res.cov is None:
        raise ImutoolError("smoothing needs the filter covariances (run_ekf(..., keep_cov=True))")
    t = res.time
    if dt_nominal is None:
        dt_nominal = nominal_dt(t)
    g = _held_gyro(gyro)
    n = len(t)
    q_s = np.empty((n, 4))
    b_s = np.empty((n, 3))
    p_s = np.empty((n, 6, 6))
    rts_kernel(
        t,
        g,
        res.q,
        res.bias,
        res.cov,
        params.gyro_noise,
        params.gyro_scale_noise,
        params.heading_scale_noise,
        params.bias_rw,
        params.gap_factor * dt_nominal,
        params.gap_rate_sigma,
        params.gyro_prev_weight(),
        q_s,
        b_s,
        p_s,
    )
    std = euler_std(q_s, p_s)
    out = AttitudeResult(t, q_s, b_s, std, res.flags.copy(), dict(res.summary), None)
    out.summary["smoothed"] = True
    return out


def _held_gyro(gyro: np.ndarray) -> np.ndarray:
    """The gyro with each NaN row replaced by the last good one (the filter's rule), float64."""
    g = np.array(gyro, dtype=np.float64)
    bad = ~np.all(np.isfinite(g), axis=1)
    if bad.any():
        idx = np.where(~bad, np.arange(len(g)), 0)
        np.maximum.accumulate(idx, out=idx)
        g = g[idx]
    return g
