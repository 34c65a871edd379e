"""The aided filter's Rauch–Tung–Striebel pass (offline: ``filter`` on a whole recording): the accelerometer bias a
turn reveals, and the gyro bias the straight legs pin down, carried back over the whole voyage.

The forward pass (:func:`~imutool.attitude.aided.aided_kernel`) keeps one *node* per covariance propagation (each
velocity fix, and once a second without one): Φ from the previous node, P⁻ and P⁺ there, and the corrections it
applied (Σ δx). Its error state is reset after each update, so with e_j the smoothed error relative to the forward
posterior at node j,

    e_j = G_j (e_{j+1} + δx_{j+1}),  G_j = P⁺_j Φ_{j+1}ᵀ (P⁻_{j+1})⁻¹,  P^s_j = P⁺_j + G_j (P^s_{j+1} − P⁻_{j+1}) G_jᵀ,

from e = 0, P^s = P⁺ at the last node (a restart begins a new chain). Between two nodes the forward nominal runs
from node j's posterior to node j+1's prior, so the error applied to a row there is interpolated in time from e_j
to e_{j+1} + δx_{j+1}; the attitude is corrected as the forward pass does (q ← δq(ψ) ⊗ q, world-frame ψ), the
accelerometer bias by its part of e, and the σ come from P^s (interpolated likewise). Units as the forward pass:
rad, m/s, rad/s, m/s².
"""

from __future__ import annotations

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.jit.decorators import njit
from imutool.attitude.aided_layout import IBA, N_DX, N_PHI, N_PP, N_PQ, N_ROW, N_START, NX, euler_std
from imutool.attitude.layout import _FASTMATH, CALLED
from imutool.quaternion import qmul, rmat


@njit(**CALLED)
def _gain(nodes, j, G, L, FP):
    """G = P⁺_j Φ_{j+1}ᵀ (P⁻_{j+1})⁻¹ (NX × NX): Cholesky P⁻ = L Lᵀ, then P⁻ Gᵀ = Φ P⁺ column by column."""
    pq, ph, pp = N_PQ, N_PHI, N_PP
    for i in range(NX):  # FP = Φ_{j+1} P⁺_j (Φ is I but for a few blocks: its zeros skipped)
        for c in range(NX):
            FP[i, c] = 0.0
        for m in range(NX):
            a = nodes[j + 1, ph + i * NX + m]
            if a != 0.0:
                for c in range(NX):
                    FP[i, c] += a * nodes[j, pq + m * NX + c]
    for c in range(NX):
        for i in range(c, NX):
            s = nodes[j + 1, pp + i * NX + c]
            for m in range(c):
                s -= L[i, m] * L[c, m]
            if i == c:
                L[c, c] = np.sqrt(max(s, 1e-300))
            else:
                L[i, c] = s / L[c, c]
    for c in range(NX):  # column c of Gᵀ: forward then backward substitution
        for i in range(NX):
            s = FP[i, c]
            for m in range(i):
                s -= L[i, m] * G[c, m]
            G[c, i] = s / L[i, i]
        for i in range(NX - 1, -1, -1):
            s = G[c, i]
            for m in range(i + 1, NX):
                s -= L[m, i] * G[c, m]
            G[c, i] = s / L[i, i]


@njit(**CALLED)
def _backward(nodes, nn, es, Ps, G, L, FP, D):
    """The smoothed errors es (nn, NX) and covariances Ps (nn, NX, NX) at the nodes (module docstring); G, L, FP, D
    (NX, NX) scratch."""
    for j in range(nn - 1, -1, -1):
        last = j == nn - 1 or nodes[j + 1, N_START] > 0
        for i in range(NX):
            es[j, i] = 0.0
            for c in range(NX):
                Ps[j, i, c] = nodes[j, N_PQ + i * NX + c]
        if last:
            continue
        _gain(nodes, j, G, L, FP)
        for i in range(NX):
            s = 0.0
            for m in range(NX):
                s += G[i, m] * (es[j + 1, m] + nodes[j + 1, N_DX + m])
            es[j, i] = s
        for i in range(NX):  # D = G (P^s_{j+1} − P⁻_{j+1})
            for c in range(NX):
                s = 0.0
                for m in range(NX):
                    s += G[i, m] * (Ps[j + 1, m, c] - nodes[j + 1, N_PP + m * NX + c])
                D[i, c] = s
        for i in range(NX):
            for c in range(i, NX):
                s = 0.0
                for m in range(NX):
                    s += D[i, m] * G[c, m]
                v = 0.5 * (Ps[j, i, c] + Ps[j, c, i]) + s
                Ps[j, i, c] = v
                Ps[j, c, i] = v


@njit(cache=True, fastmath=_FASTMATH, nogil=True, error_model="numpy")
def aided_rts_kernel(t, nodes, nn, q, std, ba, ba_std):
    """Smooth the forward pass's rows in place: q (N,4), std (N,3) rad, ba and ba_std (N,3) m/s² (NaN rows, where
    the forward pass was not running, stay NaN); nodes (≥ nn, N_COLS) its record."""
    es, Ps = np.empty((nn, NX)), np.empty((nn, NX, NX))
    _backward(nodes, nn, es, Ps, np.empty((NX, NX)), np.zeros((NX, NX)), np.empty((NX, NX)), np.empty((NX, NX)))
    R, Pi = np.empty((3, 3)), np.empty((3, 3))
    # per interval: the smoothed ψ, δb_a (6), the ψ block (9) and δb_a σ (3) at its two ends
    e0, e1, v0, v1 = np.empty(6), np.empty(6), np.empty(12), np.empty(12)
    for j in range(nn):
        nxt = j + 1 < nn and nodes[j + 1, N_START] == 0
        k0 = int(nodes[j, N_ROW])
        k1 = int(nodes[j + 1, N_ROW]) if j + 1 < nn else t.shape[0]
        for i in range(3):
            for side in range(2):
                jj = j + side if nxt else j
                dx = side == 1 and nxt
                ee = e1 if side == 1 else e0
                vv = v1 if side == 1 else v0
                ee[i] = es[jj, i] + (nodes[jj, N_DX + i] if dx else 0.0)
                ee[3 + i] = es[jj, IBA + i] + (nodes[jj, N_DX + IBA + i] if dx else 0.0)
                for c in range(3):
                    vv[3 * i + c] = Ps[jj, i, c]
                vv[9 + i] = np.sqrt(max(Ps[jj, IBA + i, IBA + i], 0.0))  # σ, interpolated as it is
        span = t[k1] - t[k0] if nxt else 0.0
        inv = 1.0 / span if span > 0 else 0.0
        for k in range(k0, k1):
            if not np.isfinite(q[k, 0]):
                continue
            f = (t[k] - t[k0]) * inv
            g = 1.0 - f
            for i in range(3):
                for c in range(3):
                    Pi[i, c] = g * v0[3 * i + c] + f * v1[3 * i + c]
                ba_std[k, i] = g * v0[9 + i] + f * v1[9 + i]
                ba[k, i] += g * e0[3 + i] + f * e1[3 + i]
            # q ← δq(ψ) ⊗ q, δq ≈ [1, ψ/2] (|ψ| ≲ 0.01 rad: the error is of order |ψ|³), normalised
            p0, p1, p2 = g * e0[0] + f * e1[0], g * e0[1] + f * e1[1], g * e0[2] + f * e1[2]
            a0, a1, a2, a3 = qmul(1.0, 0.5 * p0, 0.5 * p1, 0.5 * p2, q[k, 0], q[k, 1], q[k, 2], q[k, 3])
            nq = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3)
            q[k, 0], q[k, 1], q[k, 2], q[k, 3] = a0 / nq, a1 / nq, a2 / nq, a3 / nq
            rmat(q[k, 0], q[k, 1], q[k, 2], q[k, 3], R)
            euler_std(R, Pi, std, k)


def node_capacity(time: np.ndarray, velocity_ne: np.ndarray) -> int:
    """An upper bound on the forward pass's nodes: every row that may be a new fix, one a second without, starts."""
    v = np.asarray(velocity_ne, dtype=np.float64)[:, 0]
    fin = np.isfinite(v)
    cand = int(fin[0]) + int(np.sum(fin[1:] & ~((v[1:] == v[:-1]) & fin[:-1])))
    span = float(time[-1] - time[0]) if len(time) else 0.0
    return cand + int(span) + 8


def smooth_aided(time: np.ndarray, nodes: np.ndarray, nn: int, result) -> bool:
    """Smooth an :class:`~imutool.attitude.aided.AidedResult` in place from its forward pass's ``nn`` nodes; False
    (nothing done) without nodes."""
    if nn < 1:
        return False
    aided_rts_kernel(time, nodes, nn, result.q, result.std, result.accel_bias, result.accel_bias_std)
    return True
