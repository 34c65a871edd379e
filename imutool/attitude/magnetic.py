"""The magnetometer's dip gate and the new-field rule (a field the gates reject that holds while turning)."""

from __future__ import annotations

import numpy as np
from numba import njit

import formats.kernel_cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from imutool.attitude.covariance import _propagate_pending, _vertical_forms
from imutool.attitude.layout import (
    P_MAG_DIP_GATE,
    P_MAG_NEW_FIRST,
    P_MAG_NEW_TIME,
    P_MAG_NORM_GATE,
    S_MCCNT,
    S_MCN,
    S_MCT,
    S_MCX,
    S_MCY,
    S_MCZ,
    S_MDIST,
    S_MNORM,
    S_MREF,
    S_MREF_N,
    S_MREF_T,
    S_NMNEW,
)
from imutool.attitude.updates import _reset_heading
from imutool.quaternion import fast_atan2


@njit(inline="always")  # small and on the per-sample path: compiled into each caller
def _dip_gate(sin_dip, cos_gate, sin_gate):
    """The reference dip (rad) from its sine, and the magnetometer's dip gate as bounds on the sine of a sample's
    dip: |asin(m_z/|m|) − dip| > gate ⇔ m_z/|m| outside [lo, hi] = sin(dip ∓ gate) (±2 where dip ∓ gate passes a
    pole; sin(dip ∓ gate) = sin dip cos gate ∓ cos dip sin gate, cos dip ≥ 0)."""
    s = min(1.0, max(-1.0, sin_dip))
    c = np.sqrt(1.0 - s * s)
    lo = s * cos_gate - c * sin_gate if s > -cos_gate else -2.0
    hi = s * cos_gate + c * sin_gate if s < cos_gate else 2.0
    return np.arcsin(s), lo, hi


@njit(cache=True)
def _new_field(st, P, prm, nm, sz, hx, hy, dt, turning, r0, r1, r2, cos_gate, sin_gate):
    """No lock-out of the magnetometer (VQF's new-field acceptance, Laidig & Seel 2023, Sec. IV-C). Called for a sample
    the gates reject, of norm ``nm`` (µT), dip sine ``sz`` and horizontal direction ``hx``, ``hy`` (north and east
    components of the unit field, world frame by the filter's attitude), ``dt`` (s) after the previous magnetometer
    sample (gaps counted at gap_dt), ``turning`` when the body turns faster than mag_new_min_rate; r0..r2 the world
    vertical in body axes. Until the reference's own field has held for mag_new_first_time s of turning (S_MREF_T,
    counted at the magnetometer updates) a candidate needs that long, after it mag_new_time. The rejected samples that
    agree with one another within the same gates (norm within mag_norm_gate of their mean, dip within mag_dip_gate_deg)
    form a candidate field; a sample that does not starts a new one. Once the candidate has held for that time of
    turning (a magnet riding with the sensor changes the norm and dip as the body turns; the earth's field in a new
    place does not), it becomes the reference and True is returned. The heading was held to the old reference: its
    variance becomes at least its disagreement with the new field (the candidate's mean horizontal direction) and its
    covariance with the bias goes, so it converges to the new field without teaching the bias. Inlined: as a call in
    the kernel's loop, even one never made, it cost 4 % of the kernel's speed. Reads and writes S_MCN, S_MCZ, S_MCX,
    S_MCY, S_MCCNT, S_MCT; on a new field also S_MNORM, S_MREF, S_MREF_N, S_MREF_T, S_MDIST, S_NMNEW and P."""
    confirmed = st[S_MREF_T] >= prm[P_MAG_NEW_FIRST]
    new_time = prm[P_MAG_NEW_TIME] if confirmed else prm[P_MAG_NEW_FIRST]
    norm_gate = prm[P_MAG_NORM_GATE]
    c = st[S_MCCNT]
    agree = c > 0
    if agree and norm_gate > 0:
        agree = abs(nm / st[S_MCN] - 1.0) <= norm_gate
    if agree and prm[P_MAG_DIP_GATE] > 0:
        _, lo, hi = _dip_gate(st[S_MCZ], cos_gate, sin_gate)
        agree = lo <= sz <= hi
    if not agree:
        st[S_MCN], st[S_MCZ], st[S_MCX], st[S_MCY], st[S_MCCNT], st[S_MCT] = nm, sz, hx, hy, 1.0, 0.0
        return False
    c += 1.0
    st[S_MCCNT] = c
    st[S_MCN] += (nm - st[S_MCN]) / c
    st[S_MCZ] += (sz - st[S_MCZ]) / c
    st[S_MCX] += (hx - st[S_MCX]) / c
    st[S_MCY] += (hy - st[S_MCY]) / c
    if turning:
        st[S_MCT] += dt
    if st[S_MCT] < new_time:
        return False
    szr = min(1.0, max(-1.0, st[S_MCZ]))
    st[S_MNORM] = st[S_MCN]
    st[S_MREF], st[S_MREF + 1], st[S_MREF + 2] = np.sqrt(1.0 - szr * szr), 0.0, szr
    st[S_MREF_N] = c  # the reference goes on as the running mean of the candidate's samples
    st[S_MREF_T] = max(st[S_MREF_T], st[S_MCT])  # it held while the body turned: confirmed
    st[S_MCCNT], st[S_MCT] = 0.0, 0.0
    st[S_NMNEW] += 1.0
    st[S_MDIST] = 0.0  # the disturbance it held was measured against the old reference
    _propagate_pending(st, P, prm)
    yc = fast_atan2(st[S_MCY], st[S_MCX])
    _reset_heading(st, P, r0, r1, r2, 0.0, max(_vertical_forms(P, r0, r1, r2)[0], yc * yc))
    return True
