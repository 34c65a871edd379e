"""The aided filter's fixed layouts (imutool/attitude/aided.py, its smoother aided_rts.py): the error state's slots,
a smoother node's columns, and the roll/pitch/heading σ of a world-frame attitude error."""

from __future__ import annotations

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.jit.decorators import njit
from imutool.attitude.layout import INLINED

NX = 11  # error state: ψ (0-2), δv_NE (3-4), δb_g (5-7), δb_a (8-10)
IV, IBG, IBA = 3, 5, 8
# ---- a smoother node (a propagation, and the updates at its row): one row of ``nodes`` ----
N_ROW, N_START, N_DX, N_PHI, N_PP, N_PQ = 0, 1, 2, 13, 134, 255  # row; chain start; Σ corrections; Φ, P⁻, P⁺
N_COLS = 376


@njit(**INLINED)
def euler_std(R, P, std_out, k):
    """std_out[k] = the roll/pitch/heading σ (rad) of the world-frame attitude error whose covariance is P[:3, :3]:
    δ(φ,θ,ψ) = E Rᵀ ψ, E the body-rate → Euler-rate matrix."""
    sp = min(1.0, max(-1.0, -R[2, 0]))
    cp = max(np.sqrt(1 - sp * sp), 1e-6)
    hr = np.sqrt(R[2, 1] * R[2, 1] + R[2, 2] * R[2, 2])
    sr, cr = (R[2, 1] / hr, R[2, 2] / hr) if hr > 1e-12 else (0.0, 1.0)
    tp = sp / cp
    for row in range(3):
        if row == 0:
            e0, e1, e2 = 1.0, sr * tp, cr * tp
        elif row == 1:
            e0, e1, e2 = 0.0, cr, -sr
        else:
            e0, e1, e2 = 0.0, sr / cp, cr / cp
        # m = e Rᵀ (a row in world axes)
        m0 = e0 * R[0, 0] + e1 * R[0, 1] + e2 * R[0, 2]
        m1 = e0 * R[1, 0] + e1 * R[1, 1] + e2 * R[1, 2]
        m2 = e0 * R[2, 0] + e1 * R[2, 1] + e2 * R[2, 2]
        v = (
            m0 * (m0 * P[0, 0] + 2 * m1 * P[0, 1] + 2 * m2 * P[0, 2])
            + m1 * (m1 * P[1, 1] + 2 * m2 * P[1, 2])
            + m2 * m2 * P[2, 2]
        )
        std_out[k, row] = np.sqrt(max(v, 0.0))
