"""The EKF's external true heading update (a gyrocompass's HDT/THS; rad, NED)."""

from __future__ import annotations

import numpy as np
from numba import njit

from imutool.attitude.covariance import _propagate_pending, _vertical_forms
from imutool.attitude.layout import (
    _FASTMATH,
    F_HDG_USED,
    FALSE,
    HEADING_GATE_SIGMA,
    HEADING_REJECT_MAX_S,
    P_HDG_NOISE,
    S_HLAST,
    S_HREJ_T,
    S_NHREJ,
)
from imutool.attitude.updates import _apply_correction, _heading_update, _reset_heading
from imutool.quaternion import fast_atan2, rmat


@njit(fastmath=_FASTMATH, error_model="numpy", inline="always")
def heading_input_step(st, P, prm, R, dx, tk, hk):
    """An external true heading ``hk`` (rad, NED) at ``tk`` (s): a scalar update about the world vertical, a glitch
    skipped for at most HEADING_REJECT_MAX_S, then taken outright. Returns the sample's flag bits."""
    flag = 0
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
    elif glitch:  # away for HEADING_REJECT_MAX_S: the gyrocompass's heading is taken outright
        st[S_HREJ_T] = 0.0
        _reset_heading(st, P, R[2, 0], R[2, 1], R[2, 2], yh, s2h)
        flag |= F_HDG_USED
    else:
        st[S_HREJ_T] = 0.0
        _heading_update(P, R[2, 0], R[2, 1], R[2, 2], yh, s2h, dx, FALSE, 0.0, 0.0, 0.0)
        _apply_correction(st, dx)  # dx along r: its reset is G = I
        flag |= F_HDG_USED
    return flag
