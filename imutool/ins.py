"""Strapdown INS with an error-state EKF and zero-velocity / height updates (INS paper, README §4).

Mechanisation (body→NED quaternion q, position r and velocity v in NED, origin at the alignment sample):

- attitude, paper eq. 17 (2nd order) / eq. 18 (3rd order, default), q_{k+1} = M(Ω_k, Ω_{k−1}, T) q_k with
  Ω(ω) the right-multiplication matrix of [0, ω] (q̇ = ½ Ω q, eq. 11) and ω = y_g − b̂_g. With uneven sampling
  Ω_{k−1} is the rate extrapolated back one step T_k from the slope (ω_k − ω_{k−1}) / T_{k−1};
- velocity, eq. 21: v_{k+1} = v_k + ½ (R(q_{k+1}) f_{k+1} + R(q_k) f_k) T + g T, f = y_a − b̂_a, g = [0, 0, g];
- position, eq. 22: r_{k+1} = r_k + ½ (v_{k+1} + v_k) T.

Error state δx = [δθ, δr, δv, δb_a, δb_g] (15; true = estimate ⊕ error, q = q̂ ⊗ [1, δθ/2], so δθ = 2 q̄ of the
paper) with the paper's A(t) (§3, eq. 32, 40, 42) extended by the bias states:
δθ̇ = −[ω×] δθ − δb_g − n_g,  δṙ = δv,  δv̇ = −R [f×] δθ − R δb_a − R n_a,  δḃ = n_b.
Discretised Φ = I + A T, Q = diag(σ_g² T, 0, σ_a² T, σ_ba² T, σ_bg² T) (σ = noise densities). At ZVI samples:
velocity update z = 0 − v̂ (H_v, eq. 45) and optionally the height update z = 0 − r̂_d (H_r, flat floor);
optionally a zero angular-rate update z = y_g − b̂_g (ZARU); then the error is injected into the nominal state
and reset. Alignment over a window of the first rest interval (its last ``align_window_s`` ending
``align_guard_s`` before its end): roll/pitch from the interquartile-mean specific force f̄, heading 0 (or
given), gyro bias from the interquartile-mean rate, gravity magnitude |f̄| (absorbs the accelerometer's scale
error). One compiled loop does everything.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

import formats
import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats import Recording
from formats.errors import ImutoolError
from formats.frames import euler_to_quat, quat_to_euler
from formats.jit.decorators import njit
from formats.jit.warm import Entry
from imutool.loading import input_notes
from imutool.quaternion import rmat

GYRO_NOISE_DEG = 0.3  # deg/s/√Hz: the gyro white-noise density of the process model (InsConfig.gyro_noise)
ZARU_SIGMA_DEG = 1.0  # deg/s: std of the zero angular-rate pseudo-measurement (InsConfig.zaru_sigma)
NX = 15  # error-state size: δθ 0:3, δr 3:6, δv 6:9, δb_a 9:12, δb_g 12:15


@dataclass
class InsConfig:
    """Tuning of the error-state INS (SI units; defaults tuned once, see docs/ins.md)."""

    gyro_noise: float = float(np.radians(GYRO_NOISE_DEG))  # gyro white noise density σ_g, rad/s/√Hz (process noise)
    accel_noise: float = 0.3  # accelerometer white noise density σ_a, m/s²/√Hz
    gyro_bias_rw: float = float(np.radians(0.002))  # gyro bias random walk, rad/s/√s (0 = constant)
    accel_bias_rw: float = 1e-4  # accelerometer bias random walk, m/s²/√s
    zupt_sigma: float = 0.01  # m/s, std of the zero-velocity pseudo-measurement (v_v in eq. 45)
    height_sigma: float = 0.01  # m, std of the flat-floor height pseudo-measurement (v_r in eq. 45)
    zaru: bool = False  # zero angular-rate update at ZVI samples (observes the gyro bias, incl. heading axis)
    zaru_sigma: float = float(np.radians(ZARU_SIGMA_DEG))  # rad/s, std of the zero angular-rate pseudo-measurement
    order: int = 3  # quaternion Taylor order: 2 (eq. 17) or 3 (eq. 18)
    zupt: bool = True  # velocity update at ZVI samples
    height_update: bool = False  # height update r_d = 0 at ZVI samples (flat floor)
    accel_bias_states: bool = True  # estimate δb_a
    gyro_bias_states: bool = True  # estimate δb_g
    init_gyro_bias: bool = True  # initial gyro bias = mean rate over the alignment interval
    heading_deg: float = 0.0  # initial heading (deg, clockwise from north)
    gravity: float | None = None  # m/s²; None = |mean specific force| over the alignment interval
    align_min_s: float = 0.2  # the first rest interval at least this long (s) is used for alignment
    align_window_s: float = 4.0  # s, alignment (attitude, gyro bias, gravity) over the last part of that interval
    align_guard_s: float = 1.0  # s, ... ending this long before the interval's end
    init_tilt_sigma: float = float(np.radians(1.0))  # rad, initial roll/pitch std
    init_heading_sigma: float = float(np.radians(0.1))  # rad, initial heading std (heading is by definition)
    init_vel_sigma: float = 0.01  # m/s
    init_accel_bias_sigma: float = 0.05  # m/s²
    init_gyro_bias_sigma: float = float(np.radians(0.05))  # rad/s (after the rest-interval estimate)


@dataclass
class InsResult:
    """Per-sample INS outputs (NaN before the alignment sample ``k0``)."""

    time: np.ndarray  # (N,) s
    pos: np.ndarray  # (N,3) m NED, origin at the alignment sample
    vel: np.ndarray  # (N,3) m/s NED
    q: np.ndarray  # (N,4) body→NED
    p_diag: np.ndarray  # (N,15) diagonal of the error covariance
    heading_var: np.ndarray  # (N,) rad², variance of the rotation error about down (NED)
    accel_bias: np.ndarray  # (N,3) m/s²
    gyro_bias: np.ndarray  # (N,3) rad/s
    zvi: np.ndarray  # (N,) bool, samples that got the zero-velocity update
    k0: int
    gravity: float
    p_final: np.ndarray  # (15,15) final covariance
    info: dict[str, Any] = field(default_factory=dict)

    def euler_deg(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r, p, h = quat_to_euler(self.q)
        return np.degrees(r), np.degrees(p), np.degrees(h)


# ---------------------------------------------------------------------------------------------------------------
# compiled kernel


@njit  # a helper of _ins_kernel: compiled into it and cached with it
def _quat_step(q: np.ndarray, w: np.ndarray, wp: np.ndarray, T: float, order: int) -> None:
    """In place q ← M q with the paper's eq. 17 (order 2) or eq. 18 (order 3); w = ω_k, wp = ω_{k−1}."""
    # Ω(a) q = q ⊗ [0, a]  (eq. 11); apply the terms as quaternion products to avoid building 4×4 matrices
    w0, x0, y0, z0 = q[0], q[1], q[2], q[3]
    n2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2]
    # a = 3/4 ω_k − 1/4 ω_{k−1} (times T)
    ax = (0.75 * w[0] - 0.25 * wp[0]) * T
    ay = (0.75 * w[1] - 0.25 * wp[1]) * T
    az = (0.75 * w[2] - 0.25 * wp[2]) * T
    if order == 2:
        s = 1.0 - n2 * T * T / 8.0
        bx, by, bz = ax, ay, az
    else:
        # −1/6 |ω|² T² I − 1/24 Ω_k Ω_{k−1} T² − 1/48 |ω|² Ω_k T³ ;  Ω(a)Ω(b) = Ω-form of b ⊗ a = [−a·b, b × a]
        dot = w[0] * wp[0] + w[1] * wp[1] + w[2] * wp[2]
        cx = wp[1] * w[2] - wp[2] * w[1]
        cy = wp[2] * w[0] - wp[0] * w[2]
        cz = wp[0] * w[1] - wp[1] * w[0]
        k2 = T * T / 24.0
        s = 1.0 - n2 * T * T / 6.0 + k2 * dot
        k3 = n2 * T * T * T / 48.0
        bx = ax - k2 * cx - k3 * w[0]
        by = ay - k2 * cy - k3 * w[1]
        bz = az - k2 * cz - k3 * w[2]
    # q ← s q + q ⊗ [0, b]  (the identity terms are folded into the scalar s)
    nw = s * w0 - x0 * bx - y0 * by - z0 * bz
    nx = s * x0 + w0 * bx + y0 * bz - z0 * by
    ny = s * y0 + w0 * by + z0 * bx - x0 * bz
    nz = s * z0 + w0 * bz + x0 * by - y0 * bx
    nrm = np.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
    q[0] = nw / nrm
    q[1] = nx / nrm
    q[2] = ny / nrm
    q[3] = nz / nrm


@njit  # a helper of _ins_kernel: compiled into it and cached with it
def _apply_f(fth: np.ndarray, fvth: np.ndarray, fvba: np.ndarray, T: float, m: np.ndarray, out: np.ndarray) -> None:
    """out = F m for the block-sparse discrete F = A T (15×15) without forming F."""
    n = m.shape[1]
    for i in range(NX):
        for j in range(n):
            out[i, j] = 0.0
    for j in range(n):
        for i in range(3):
            acc = -T * m[12 + i, j]
            acc2 = 0.0
            for k in range(3):
                acc += fth[i, k] * m[k, j]
                acc2 += fvth[i, k] * m[k, j] + fvba[i, k] * m[9 + k, j]
            out[i, j] = acc
            out[3 + i, j] = T * m[6 + i, j]
            out[6 + i, j] = acc2


@njit  # a helper of _ins_kernel: compiled into it and cached with it
def _spd_inverse(s: np.ndarray, out: np.ndarray, m: int) -> None:
    """out[:m,:m] = inverse of the symmetric positive-definite s[:m,:m] (Gauss-Jordan; s is overwritten)."""
    for i in range(m):
        for j in range(m):
            out[i, j] = 1.0 if i == j else 0.0
    for c in range(m):
        piv = s[c, c]
        for j in range(m):
            s[c, j] /= piv
            out[c, j] /= piv
        for r in range(m):
            if r != c:
                fct = s[r, c]
                if fct != 0.0:
                    for j in range(m):
                        s[r, j] -= fct * s[c, j]
                        out[r, j] -= fct * out[c, j]


@njit(cache=True)
def _ins_kernel(t, gyro, accel, zvi, k0, q0, bg0, ba0, prm, opt, pos, vel, qout, pdiag, hvar, bias):
    """The strapdown + error-state EKF loop from sample k0 (see module doc). prm/opt: see _pack()."""
    n = t.shape[0]
    g, sg2, sa2, sbg2, sba2, rz, rh = (
        prm[0],
        prm[1] ** 2,
        prm[2] ** 2,
        prm[3] ** 2,
        prm[4] ** 2,
        prm[5] ** 2,
        prm[6] ** 2,
    )
    order, use_zupt, use_h, use_zaru = opt[0], opt[1], opt[2], opt[3]
    rw = prm[12] ** 2
    q = q0.copy()
    bg = bg0.copy()
    ba = ba0.copy()
    v = np.zeros(3)
    r = np.zeros(3)
    P = np.zeros((NX, NX))
    for i in range(2):
        P[i, i] = prm[7] ** 2
    P[2, 2] = prm[8] ** 2
    for i in range(3):
        P[6 + i, 6 + i] = prm[9] ** 2
        P[9 + i, 9 + i] = prm[10] ** 2
        P[12 + i, 12 + i] = prm[11] ** 2
    R = np.zeros((3, 3))
    fth = np.zeros((3, 3))
    fvth = np.zeros((3, 3))
    fvba = np.zeros((3, 3))
    FP = np.zeros((NX, NX))
    FPF = np.zeros((NX, NX))
    FPt = np.zeros((NX, NX))
    w = np.zeros(3)
    wp = np.zeros(3)
    wprev = np.zeros(3)
    f = np.zeros(3)
    fn = np.zeros(3)
    an = np.zeros(3)
    idx = np.zeros(7, dtype=np.int64)
    S = np.zeros((7, 7))
    Si = np.zeros((7, 7))
    z = np.zeros(7)
    K = np.zeros((NX, 7))
    HP = np.zeros((7, NX))
    dx = np.zeros(NX)
    rmat(q[0], q[1], q[2], q[3], R)
    for i in range(3):
        f[i] = accel[k0, i] - ba[i]
        wprev[i] = gyro[k0, i] - bg[i]
    tprev = 0.0
    for k in range(k0, n):
        if k > k0:
            T = t[k] - t[k - 1]
            # ---- mechanisation from k−1 to k (eq. 17/18, 21, 22)
            for i in range(3):
                w[i] = gyro[k - 1, i] - bg[i]
                if tprev > 0.0:
                    wp[i] = w[i] - (w[i] - wprev[i]) * T / tprev
                else:
                    wp[i] = w[i]
            for i in range(3):
                an[i] = R[i, 0] * f[0] + R[i, 1] * f[1] + R[i, 2] * f[2]
            # F blocks at k−1 (before the attitude step)
            fth[0, 0] = 0.0
            fth[0, 1] = w[2] * T
            fth[0, 2] = -w[1] * T
            fth[1, 0] = -w[2] * T
            fth[1, 1] = 0.0
            fth[1, 2] = w[0] * T
            fth[2, 0] = w[1] * T
            fth[2, 1] = -w[0] * T
            fth[2, 2] = 0.0
            for i in range(3):
                # −R [f×] : column j of [f×] is f × e_j
                fvth[i, 0] = -(R[i, 1] * f[2] - R[i, 2] * f[1]) * T
                fvth[i, 1] = -(R[i, 2] * f[0] - R[i, 0] * f[2]) * T
                fvth[i, 2] = -(R[i, 0] * f[1] - R[i, 1] * f[0]) * T
                for j in range(3):
                    fvba[i, j] = -R[i, j] * T
            _quat_step(q, w, wp, T, order)
            rmat(q[0], q[1], q[2], q[3], R)
            for i in range(3):
                f[i] = accel[k, i] - ba[i]
            for i in range(3):
                fn[i] = R[i, 0] * f[0] + R[i, 1] * f[1] + R[i, 2] * f[2]
            for i in range(3):
                vi = v[i] + 0.5 * (fn[i] + an[i]) * T
                if i == 2:
                    vi += g * T
                r[i] += 0.5 * (vi + v[i]) * T
                v[i] = vi
            # ---- covariance: P ← P + FP + (FP)ᵀ + F (FP)ᵀ + Q
            _apply_f(fth, fvth, fvba, T, P, FP)
            for i in range(NX):
                for j in range(NX):
                    FPt[i, j] = FP[j, i]
            _apply_f(fth, fvth, fvba, T, FPt, FPF)
            for i in range(NX):
                for j in range(NX):
                    P[i, j] += FP[i, j] + FP[j, i] + FPF[i, j]
            for i in range(3):
                P[i, i] += sg2 * T
                P[6 + i, 6 + i] += sa2 * T
                P[9 + i, 9 + i] += sba2 * T
                P[12 + i, 12 + i] += sbg2 * T
            for i in range(3):
                wprev[i] = w[i]
            tprev = T
        # ---- zero-velocity (and height) update, eq. 44–45
        if zvi[k] and (use_zupt or use_h or use_zaru):
            m = 0
            if use_zupt:
                for i in range(3):
                    idx[m] = 6 + i
                    m += 1
            if use_h:
                idx[m] = 5
                m += 1
            if use_zaru:
                for i in range(3):
                    idx[m] = 12 + i
                    m += 1
            for a in range(m):
                for b in range(m):
                    S[a, b] = P[idx[a], idx[b]]
                j = idx[a]
                if j == 5:  # height: z = 0 − r̂_d
                    S[a, a] += rh
                    z[a] = -r[2]
                elif j < 9:  # velocity: z = 0 − v̂
                    S[a, a] += rz
                    z[a] = -v[j - 6]
                else:  # angular rate: z = y_g − b̂_g (ω = 0 at rest)
                    S[a, a] += rw
                    z[a] = gyro[k, j - 12] - bg[j - 12]
            _spd_inverse(S, Si, m)
            for i in range(NX):
                for b in range(m):
                    acc = 0.0
                    for a in range(m):
                        acc += P[i, idx[a]] * Si[a, b]
                    K[i, b] = acc
            for i in range(NX):
                acc = 0.0
                for a in range(m):
                    acc += K[i, a] * z[a]
                dx[i] = acc
            # P ← P − K H P, symmetrised
            for a in range(m):
                for j in range(NX):
                    HP[a, j] = P[idx[a], j]
            for i in range(NX):
                for j in range(NX):
                    acc = 0.0
                    for a in range(m):
                        acc += K[i, a] * HP[a, j]
                    P[i, j] -= acc
            for i in range(NX):
                for j in range(i + 1, NX):
                    s = 0.5 * (P[i, j] + P[j, i])
                    P[i, j] = s
                    P[j, i] = s
            # inject: q ← q ⊗ [1, δθ/2], r, v, biases; reset δx
            hx, hy, hz = 0.5 * dx[0], 0.5 * dx[1], 0.5 * dx[2]
            q0_, q1, q2, q3 = q[0], q[1], q[2], q[3]
            nw = q0_ - q1 * hx - q2 * hy - q3 * hz
            nx = q1 + q0_ * hx + q2 * hz - q3 * hy
            ny = q2 + q0_ * hy + q3 * hx - q1 * hz
            nz = q3 + q0_ * hz + q1 * hy - q2 * hx
            nrm = np.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
            q[0], q[1], q[2], q[3] = nw / nrm, nx / nrm, ny / nrm, nz / nrm
            rmat(q[0], q[1], q[2], q[3], R)
            for i in range(3):
                r[i] += dx[3 + i]
                v[i] += dx[6 + i]
                ba[i] += dx[9 + i]
                bg[i] += dx[12 + i]
            for i in range(3):
                f[i] = accel[k, i] - ba[i]
        # ---- outputs
        for i in range(3):
            pos[k, i] = r[i]
            vel[k, i] = v[i]
            bias[k, i] = ba[i]
            bias[k, 3 + i] = bg[i]
        for i in range(4):
            qout[k, i] = q[i]
        for i in range(NX):
            pdiag[k, i] = P[i, i]
        # heading variance: (R Pθ Rᵀ)[2,2]
        acc = 0.0
        for a in range(3):
            for b in range(3):
                acc += R[2, a] * P[a, b] * R[2, b]
        hvar[k] = acc
    return P


# ---------------------------------------------------------------------------------------------------------------
# python side


def align(accel_mean: np.ndarray, heading_deg: float = 0.0) -> np.ndarray:
    """Body→NED quaternion from the mean specific force at rest (FRD reads −g on z): roll, pitch from f̄.

    roll = atan2(−f_y, −f_z), pitch = atan2(f_x, √(f_y² + f_z²)), heading as given (deg).
    """
    f = np.asarray(accel_mean, dtype=float)
    roll = np.arctan2(-f[1], -f[2])
    pitch = np.arctan2(f[0], np.hypot(f[1], f[2]))
    return euler_to_quat(roll, pitch, np.radians(heading_deg))


def alignment_interval(time: np.ndarray, zvi: np.ndarray, min_s: float) -> tuple[int, int]:
    """[start, stop) sample indices of the first ZVI lasting at least ``min_s`` seconds."""
    from imutool.zvi import interval_indices

    for a, b in interval_indices(zvi):
        if time[b - 1] - time[a] >= min_s:
            return int(a), int(b)
    raise ImutoolError(
        f"INS alignment needs a rest interval of at least {min_s} s; none detected "
        f"(check the ZVI detector or its thresholds)"
    )


def alignment_window(
    time: np.ndarray, i0: int, i1: int, window_s: float, guard_s: float, min_s: float
) -> tuple[int, int]:
    """[start, stop) of the alignment window: the last ``window_s`` seconds of the rest interval [i0, i1) ending
    ``guard_s`` before its end (the foot starts moving before a detector notices). The whole interval when it
    is too short for that (window shorter than ``min_s``)."""
    t_end = time[i1 - 1] - guard_s
    t_start = max(time[i0], t_end - window_s)
    if t_end - t_start < min_s:
        return i0, i1
    a = int(np.searchsorted(time, t_start, side="left"))
    b = int(np.searchsorted(time, t_end, side="right"))
    return max(a, i0), min(b, i1)


# the INS kernel as run_ins calls it, for the second process of a cold run (formats.jit.warm; the argument types in
# numba's signature syntax, checked against a real cold compile by tests/test_kernel_warm.py)
INS_KERNEL: Entry = (
    "imutool.ins",
    "_ins_kernel",
    "float64[::1], float64[:, ::1], float64[:, ::1], boolean[::1], int64, float64[::1], float64[::1], float64[::1], "
    "float64[::1], int64[::1], float64[:, ::1], float64[:, ::1], float64[:, ::1], float64[:, ::1], float64[::1], "
    "float64[:, ::1]",
)


def interquartile_mean(x: np.ndarray) -> np.ndarray:
    """The mean of each column of ``x`` (N, k) over its middle half: the lowest and highest ⌊N/4⌋ values left out
    (the 25 % trimmed mean; NaN for N = 0). The values kept are found by a partial sort (np.partition), as scipy's
    ``trim_mean`` does, without importing scipy.stats (~1.2 s of a first ``ins``)."""
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0]
    if n == 0:
        return np.full(x.shape[1:], np.nan)
    lo = int(0.25 * n)
    hi = n - lo
    return np.mean(np.partition(x, (lo, hi - 1), axis=0)[lo:hi], axis=0)


def run_ins(
    time: np.ndarray, gyro: np.ndarray, accel: np.ndarray, zvi: np.ndarray, config: InsConfig | None = None
) -> InsResult:
    """Run the INS. time (N,) s strictly increasing, gyro (N,3) rad/s, accel (N,3) m/s² (specific force, any
    right-handed body frame), zvi (N,) bool. Returns :class:`InsResult` (NaN before the alignment sample)."""
    c = config or InsConfig()
    t = np.ascontiguousarray(time, dtype=np.float64)
    g_ = np.ascontiguousarray(gyro, dtype=np.float64)
    a_ = np.ascontiguousarray(accel, dtype=np.float64)
    z_ = np.ascontiguousarray(np.asarray(zvi) > 0.5)
    n = len(t)
    if g_.shape != (n, 3) or a_.shape != (n, 3) or z_.shape != (n,):
        raise ImutoolError(
            f"INS needs time (N,), gyro/accel (N,3), zvi (N,); got {t.shape}, {g_.shape}, {a_.shape}, {z_.shape}"
        )
    if n < 3 or np.any(np.diff(t) <= 0):
        raise ImutoolError("INS needs at least 3 samples with strictly increasing time (validate duplicates first)")
    if not (np.all(np.isfinite(g_)) and np.all(np.isfinite(a_))):
        raise ImutoolError("INS: gyro/accel contain NaN or inf samples")
    if c.order not in (2, 3):
        raise ImutoolError(f"INS: quaternion integration order must be 2 or 3; got {c.order}")
    i0, i1 = alignment_interval(t, z_, c.align_min_s)
    a0, a1 = alignment_window(t, i0, i1, c.align_window_s, c.align_guard_s, c.align_min_s)
    # interquartile means: robust to a brief shuffle of the foot, and not snapped to the quantum like a median
    fbar = interquartile_mean(a_[a0:a1])
    gravity = float(np.linalg.norm(fbar)) if c.gravity is None else float(c.gravity)
    q0 = align(fbar, c.heading_deg)
    bg0 = interquartile_mean(g_[a0:a1]) if c.init_gyro_bias else np.zeros(3)
    ba0 = np.zeros(3)
    bg_sigma = c.init_gyro_bias_sigma if c.gyro_bias_states else 0.0
    ba_sigma = c.init_accel_bias_sigma if c.accel_bias_states else 0.0
    prm = np.array(
        [
            gravity,
            c.gyro_noise,
            c.accel_noise,
            c.gyro_bias_rw if c.gyro_bias_states else 0.0,
            c.accel_bias_rw if c.accel_bias_states else 0.0,
            c.zupt_sigma,
            c.height_sigma,
            c.init_tilt_sigma,
            c.init_heading_sigma,
            c.init_vel_sigma,
            ba_sigma,
            bg_sigma,
            c.zaru_sigma,
        ],
        dtype=np.float64,
    )
    opt = np.array([c.order, int(c.zupt), int(c.height_update), int(c.zaru and c.gyro_bias_states)], dtype=np.int64)
    pos = np.full((n, 3), np.nan)
    vel = np.full((n, 3), np.nan)
    q = np.full((n, 4), np.nan)
    pdiag = np.full((n, NX), np.nan)
    hvar = np.full(n, np.nan)
    bias = np.full((n, 6), np.nan)
    p_final = _ins_kernel(t, g_, a_, z_, a0, q0, bg0, ba0, prm, opt, pos, vel, q, pdiag, hvar, bias)
    # samples of the rest interval before the alignment window: at rest at the origin with the aligned attitude
    pos[i0:a0] = 0.0
    vel[i0:a0] = 0.0
    q[i0:a0] = q0
    pdiag[i0:a0] = pdiag[a0]
    hvar[i0:a0] = hvar[a0]
    bias[i0:a0] = bias[a0]
    a0 = i0
    info = {
        "alignment_start_s": float(t[a0]),
        "alignment_end_s": float(t[a1 - 1]),
        "gravity_m_s2": gravity,
        "initial_gyro_bias_deg_s": np.degrees(bg0).round(4).tolist(),
    }
    return InsResult(
        t, pos, vel, q, pdiag, hvar, bias[:, :3], bias[:, 3:], z_ & (np.arange(n) >= a0), a0, gravity, p_final, info
    )


def ins(
    rec: Recording,
    zvi: np.ndarray | None = None,
    detector: str = "shoe",
    detector_params: dict[str, float] | None = None,
    config: InsConfig | None = None,
) -> tuple[Recording, InsResult]:
    """Run the INS over a recording (``gyro`` rad/s, ``accel`` m/s²). ZVI flags: given, or detected with
    ``detector``. Returns the output recording (pos, vel m/s, roll/pitch/heading deg, q, *_std, zvi, biases;
    ``ref_*`` columns of the input are carried over) and the raw :class:`InsResult`."""
    from imutool.zvi import detect

    for name in ("gyro", "accel"):
        if name not in rec.channels:
            raise ImutoolError(f"INS needs channel {name!r}; has {', '.join(rec.channels) or 'none'}")
    gyro = rec.get("gyro", "rad/s")
    accel = rec.get("accel", "m/s^2")
    if zvi is None:
        zvi = detect(rec, detector, **(detector_params or {})).flags
    res = run_ins(rec.time, gyro, accel, zvi, config)
    out = Recording(
        rec.time.copy(),
        meta={**{k: v for k, v in rec.meta.items() if k in ("source", "sensor", "frame")}, **input_notes(rec.meta)},
    )
    out.add("pos", res.pos, "m")
    out.add("vel", res.vel, "m/s")
    roll, pitch, heading = res.euler_deg()
    out.add("roll", roll, "deg")
    out.add("pitch", pitch, "deg")
    out.add("heading", heading, "deg")
    out.add("q", res.q, "1")
    out.add("pos_std", np.sqrt(np.maximum(res.p_diag[:, 3:6], 0)), "m")
    out.add("vel_std", np.sqrt(np.maximum(res.p_diag[:, 6:9], 0)), "m/s")
    out.add("roll_std", np.degrees(np.sqrt(np.maximum(res.p_diag[:, 0], 0))), "deg")
    out.add("pitch_std", np.degrees(np.sqrt(np.maximum(res.p_diag[:, 1], 0))), "deg")
    out.add("heading_std", np.degrees(np.sqrt(np.maximum(res.heading_var, 0))), "deg")
    out.add("zvi", res.zvi.astype(float), "1")
    out.add("gyro_bias", res.gyro_bias, "rad/s")
    out.add("accel_bias", res.accel_bias, "m/s^2")
    for name in rec.channels:
        if name.startswith("ref_"):
            out.add(name, rec.channels[name], rec.units.get(name), rec.columns.get(name))
    out.meta.update({"ins_" + k: (str(v) if isinstance(v, list) else v) for k, v in res.info.items()})
    out.meta["ins_frame"] = "pos/vel NED (m, m/s), origin at the alignment sample; heading by definition"
    return out, res


# ---------------------------------------------------------------------------------------------------------------
# strides and evaluation


def strides(
    time: np.ndarray, pos: np.ndarray, zvi: np.ndarray, min_swing_s: float = 0.2, max_stance_s: float = 1.5
) -> dict[str, Any]:
    """Stride segmentation from ZVIs: one stride per swing between two stance intervals.

    Motion gaps shorter than ``min_swing_s`` (s) do not count as swings (a stance split by a foot roll).
    Length = horizontal distance (m) between the mean positions of consecutive stances; swing_s = toe-off to
    heel-strike; duration = time (s) between the starts of consecutive stances (NaN after a rest longer than
    ``max_stance_s``, where the previous heel-strike is not a step).
    Returns count, mean/total length, mean duration and the table.
    """
    from imutool.zvi import interval_indices

    iv = interval_indices(zvi)
    if len(iv) > 1:
        keep = [iv[0].copy()]
        for a, b in iv[1:]:
            if time[a] - time[keep[-1][1] - 1] < min_swing_s:
                keep[-1][1] = b
            else:
                keep.append(np.array([a, b]))
        iv = np.array(keep)
    rows = []
    ok = np.all(np.isfinite(pos), axis=1)
    for (a0, b0), (a1, b1) in zip(iv[:-1], iv[1:], strict=False):
        m0 = ok[a0:b0]
        m1 = ok[a1:b1]
        if not m0.any() or not m1.any():
            continue
        p0 = pos[a0:b0][m0].mean(axis=0)
        p1 = pos[a1:b1][m1].mean(axis=0)
        rows.append(
            {
                "start_s": float(time[b0 - 1]),
                "end_s": float(time[a1]),
                "length_m": float(np.hypot(*(p1 - p0)[:2])),
                "height_change_m": float(-(p1 - p0)[2]),
                "swing_s": float(time[a1] - time[b0 - 1]),
                "duration_s": float(time[a1] - time[a0]) if time[b0 - 1] - time[a0] <= max_stance_s else float("nan"),
            }
        )
    lengths = np.array([r["length_m"] for r in rows])
    durs = np.array([r["duration_s"] for r in rows])
    durs = durs[np.isfinite(durs)]
    return {
        "count": len(rows),
        "total_length_m": float(lengths.sum()) if rows else 0.0,
        "mean_length_m": float(lengths.mean()) if rows else None,
        "mean_duration_s": float(durs.mean()) if len(durs) else None,
        "table": rows,
    }


def path_length(time: np.ndarray, pos: np.ndarray, step_s: float = 0.1) -> float:
    """Horizontal path length (m) of a track resampled every ``step_s`` seconds (NaN samples skipped)."""
    ok = np.all(np.isfinite(pos[:, :2]), axis=1)
    if ok.sum() < 2:
        return 0.0
    t, p = time[ok], pos[ok, :2]
    tg = np.arange(t[0], t[-1], step_s)
    tg = np.append(tg, t[-1])
    pg = np.column_stack([np.interp(tg, t, p[:, 0]), np.interp(tg, t, p[:, 1])])
    return float(np.sum(np.linalg.norm(np.diff(pg, axis=0), axis=1)))


def _position_of(rec: Recording, prefer_ref: bool) -> np.ndarray | None:
    names = ("ref_pos", "pos") if prefer_ref else ("pos",)
    for n in names:
        if n in rec.channels and rec.channels[n].ndim == 2 and rec.channels[n].shape[1] == 3:
            return rec.get(n, "m") if rec.units.get(n) else rec.channels[n]
    return None


LOOP_GAP_M = 5.0  # m: a walk whose end is within max(LOOP_GAP_M, LOOP_GAP_SHARE of its path) of its start …
LOOP_GAP_SHARE = 0.05
LOOP_MAX_SHARE = 0.25  # … and within this share of its path (a short straight walk is no loop) is taken for a loop


def looks_like_loop(gap_m: float, distance_m: float) -> bool:
    """Whether a walk whose end is ``gap_m`` (m) from its start after ``distance_m`` (m) of path is a closed loop:
    gap ≤ max(LOOP_GAP_M, LOOP_GAP_SHARE·distance) and ≤ LOOP_MAX_SHARE·distance."""
    return gap_m <= max(LOOP_GAP_M, LOOP_GAP_SHARE * distance_m) and gap_m <= LOOP_MAX_SHARE * distance_m


def evaluate_position(est: Recording, ref: Recording | None = None, loop: bool | None = None) -> dict[str, Any]:
    """Position accuracy of an INS track (``pos``, m NED) against a reference (``ref_pos`` or ``pos``).

    The reference is interpolated to the estimate's times and both are referred to their first common sample.
    Returns final-position error (3D and horizontal, m), position RMSE (3D, per axis, and the paper's "total"
    = sum of the axis RMSEs), horizontal path lengths (0.1 s resampling) and the distance error (m and % of the
    reference distance). Without a reference (or when it has no position) the start-to-end distance is returned
    (``start_to_end_m``), and it is a closed-loop error (``final_error_m``, mode "closed-loop") only for a loop:
    ``loop`` True (the user says so), False (not a loop), None (:func:`looks_like_loop` decides).
    """
    from imutool.metrics import interp_to

    p = _position_of(est, prefer_ref=False)
    if p is None:
        raise ImutoolError("position evaluation needs channel 'pos' (pos_n,pos_e,pos_d) in the estimate")
    t = est.time
    ok = np.all(np.isfinite(p), axis=1)
    if ok.sum() < 2:
        raise ImutoolError("position evaluation: the estimate has fewer than 2 valid positions")
    rp = None if ref is None else _position_of(ref, prefer_ref=True)
    if ref is not None and rp is None:
        raise ImutoolError("position evaluation: the reference has no 'ref_pos' or 'pos' channel")
    dist_est = path_length(t, p)
    if rp is None:
        pv = p[ok]
        e = pv[-1] - pv[0]
        gap = float(np.linalg.norm(e))
        is_loop = looks_like_loop(gap, dist_est) if loop is None else bool(loop)
        out: dict[str, Any] = {
            "mode": "closed-loop" if is_loop else "start-to-end",
            "loop": is_loop,
            "loop_decided": "auto" if loop is None else "given",
            "start_to_end_m": gap,
            "start_to_end_ned_m": e.tolist(),
            "distance_m": dist_est,
            "start_to_end_percent_of_distance": 100 * gap / dist_est if dist_est > 0 else None,
        }
        if is_loop:  # the foot came back to where it started: the gap is the dead reckoning's error
            out.update(
                {
                    "final_error_m": gap,
                    "final_error_horizontal_m": float(np.hypot(e[0], e[1])),
                    "final_error_ned_m": e.tolist(),
                    "final_error_percent_of_distance": out["start_to_end_percent_of_distance"],
                }
            )
        return out
    r = interp_to(t, ref.time, rp)
    both = ok & np.all(np.isfinite(r), axis=1)
    if both.sum() < 2:
        raise ImutoolError("position evaluation: estimate and reference do not overlap in time")
    i0 = int(np.flatnonzero(both)[0])
    pe = p[both] - p[i0]
    pr = r[both] - r[i0]
    e = pe - pr
    rmse_axis = np.sqrt(np.mean(e**2, axis=0))
    fin = e[-1]
    dist_ref = path_length(t[both], pr)
    dist_e = path_length(t[both], pe)
    return {
        "mode": "reference",
        "n": int(both.sum()),
        "final_error_m": float(np.linalg.norm(fin)),
        "final_error_horizontal_m": float(np.hypot(fin[0], fin[1])),
        "rmse_m": float(np.sqrt(np.mean(np.sum(e**2, axis=1)))),
        "rmse_axis_m": rmse_axis.tolist(),
        "rmse_sum_axes_m": float(rmse_axis.sum()),
        "max_error_m": float(np.max(np.linalg.norm(e, axis=1))),
        "distance_m": dist_e,
        "reference_distance_m": dist_ref,
        "distance_error_m": dist_e - dist_ref,
        "distance_error_percent": 100 * (dist_e - dist_ref) / dist_ref if dist_ref > 0 else None,
    }


# ---------------------------------------------------------------------------------------------------------------
# the route behind `imutool ins`

STRIDE_COLUMNS = ("start_s", "end_s", "length_m", "height_change_m", "swing_s", "duration_s")
