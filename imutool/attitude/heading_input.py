"""An external true heading (a gyrocompass: HDT/THS or a ``heading_true`` column) as a scalar heading update.

The heading of the body x axis (rad, NED) against the filter's, σ ``heading_input_noise_deg`` per fix, projected on
the world vertical like the magnetometer's (never touches roll/pitch), at most once per ``heading_input_interval``
s; a fix beyond HEADING_GATE_SIGMA σ is a glitch, skipped for at most HEADING_REJECT_MAX_S s, then taken outright.
"""

from __future__ import annotations

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.jit.decorators import njit
from imutool.attitude.covariance import _propagate_pending, _vertical_forms
from imutool.attitude.layout import (
    CALLED,
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


@njit(**CALLED)
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
