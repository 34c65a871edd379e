"""The magnetometer's sections of the EKF loop: its gates and disturbance level every sample (``_mag_sample``), the
update when due (``_mag_update``: heading, or the paper's full vector), the dip gate and the new-field rule (a field
the gates reject that holds while turning).

Frames and units: body FRD, world NED; the field in µT (any unit: only its direction and relative norm are used),
angles rad, rates rad/s, time s. R = R(q) body→NED is the kernel's 3×3 scratch array.
"""

from __future__ import annotations

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.jit.decorators import njit
from imutool.attitude.covariance import _propagate_pending, _reset_cov, _vertical_forms
from imutool.attitude.layout import (
    F_MAG_NEW,
    F_MAG_REJ,
    F_MAG_USED,
    FALSE,
    INLINED,
    P_GAP_DT,
    P_MAG_BIAS,
    P_MAG_BIAS_GATE,
    P_MAG_DIP_GATE,
    P_MAG_DIP_SOFT,
    P_MAG_HOLD,
    P_MAG_NEW_FIRST,
    P_MAG_NEW_RATE,
    P_MAG_NEW_TIME,
    P_MAG_NOISE,
    P_MAG_NORM_GATE,
    P_MAG_NORM_SOFT,
    P_MAG_REF_TAU,
    P_NIS_TAU,
    S_CNT_M,
    S_MCCNT,
    S_MCN,
    S_MCT,
    S_MCX,
    S_MCY,
    S_MCZ,
    S_MDIST,
    S_MDT,
    S_MNORM,
    S_MNSUM,
    S_MREF,
    S_MREF_N,
    S_MREF_T,
    S_MSUM,
    S_NIS_M,
    S_NMNEW,
    S_NMREJ,
    S_USE_M,
    TRUE,
)
from imutool.attitude.updates import _apply_correction, _heading_update, _reset_heading, _vec_update
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


@njit(**INLINED)
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


@njit(**INLINED)
def _mag_sample(st, P, prm, R, mx, my, mz, w0, w1, w2, dt, gate):
    """The magnetometer's gates and disturbance level at every finite sample m (µT, body), with the bias-free rate w
    (rad/s) and dt (s): the norm and dip gates, the peak-held deviation from the reference (S_MDIST), a new field
    where the gates reject, and the accepted sample's world-frame direction summed for the next update.
    ``gate`` = [cos gate, sin gate, reference dip (rad), dip sine bounds lo, hi] (``_dip_gate``; renewed here with a
    new field). Returns (rejected, deviation measure, flag bits F_MAG_REJ / F_MAG_NEW)."""
    flag = 0
    nm = np.sqrt(mx * mx + my * my + mz * mz)
    mw0 = R[0, 0] * mx + R[0, 1] * my + R[0, 2] * mz
    mw1 = R[1, 0] * mx + R[1, 1] * my + R[1, 2] * mz
    mw2 = R[2, 0] * mx + R[2, 1] * my + R[2, 2] * mz
    rej = nm <= 0
    have_ref = st[S_MREF_N] > 0  # none yet (a zero first sample): the first accepted samples set it
    if not rej and prm[P_MAG_NORM_GATE] > 0 and st[S_MNORM] > 0:
        rej = abs(nm / st[S_MNORM] - 1.0) > prm[P_MAG_NORM_GATE]
    if not rej and prm[P_MAG_DIP_GATE] > 0 and have_ref:
        # |asin(m_z/|m|) − dip_ref| > gate ⇔ m_z/|m| outside [sin(dip_ref − gate), sin(dip_ref + gate)]
        sz = mw2 / nm
        rej = sz < gate[3] or sz > gate[4]
    # deviation measure of the field from its reference (norm and dip, relative to their soft scales)
    dev_m = 0.0
    if nm > 0 and prm[P_MAG_NORM_SOFT] > 0 and st[S_MNORM] > 0:
        dev_m += ((nm / st[S_MNORM] - 1.0) / prm[P_MAG_NORM_SOFT]) ** 2
    if nm > 0 and prm[P_MAG_DIP_SOFT] > 0 and have_ref:
        dev_m += ((np.arcsin(min(1.0, max(-1.0, mw2 / nm))) - gate[2]) / prm[P_MAG_DIP_SOFT]) ** 2
    if prm[P_MAG_HOLD] > 0:  # peak hold with exponential decay: a disturbance is a state, not a sample
        if rej:
            dev_m = max(dev_m, 100.0)
        decay = 1.0 / (1.0 + max(dt, 0.0) / prm[P_MAG_HOLD])  # ≈ exp(−dt/hold)
        st[S_MDIST] = max(dev_m, st[S_MDIST] * decay)
        dev_m = st[S_MDIST]
    dtm = st[S_MDT]  # since the previous magnetometer sample (a slower magnetometer: several rows)
    st[S_MDT] = 0.0
    if rej and prm[P_MAG_NEW_TIME] > 0 and nm > 0 and have_ref:  # no lock-out: a new homogeneous field
        turning = w0 * w0 + w1 * w1 + w2 * w2 >= prm[P_MAG_NEW_RATE] ** 2
        hx, hy = mw0 / nm, mw1 / nm
        if _new_field(st, P, prm, nm, mw2 / nm, hx, hy, dtm, turning, R[2, 0], R[2, 1], R[2, 2], gate[0], gate[1]):
            gate[2], gate[3], gate[4] = _dip_gate(st[S_MREF + 2], gate[0], gate[1])
            flag = F_MAG_NEW
    if rej:
        flag |= F_MAG_REJ
        st[S_NMREJ] += 1
    else:  # the field's direction in the world frame, summed over the samples the update stands for
        st[S_USE_M] += 1.0
        st[S_MNSUM] += nm
        st[S_MSUM] += mw0 / nm
        st[S_MSUM + 1] += mw1 / nm
        st[S_MSUM + 2] += mw2 / nm
    return rej, dev_m, flag


@njit(**INLINED)
def _mag_vector_update(st, P, prm, R, dx, m0, m1, m2, n_use):
    """mag_mode "full": the paper's normalised 3-vector update with the mean world-frame field (m0, m1, m2) of
    n_use samples."""
    h0 = R[0, 0] * st[S_MREF] + R[1, 0] * st[S_MREF + 1] + R[2, 0] * st[S_MREF + 2]
    h1 = R[0, 1] * st[S_MREF] + R[1, 1] * st[S_MREF + 1] + R[2, 1] * st[S_MREF + 2]
    h2 = R[0, 2] * st[S_MREF] + R[1, 2] * st[S_MREF + 1] + R[2, 2] * st[S_MREF + 2]
    nw = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)  # the mean direction, back in the body frame
    y0 = (R[0, 0] * m0 + R[1, 0] * m1 + R[2, 0] * m2) / nw - h0
    y1 = (R[0, 1] * m0 + R[1, 1] * m1 + R[2, 1] * m2) / nw - h1
    y2 = (R[0, 2] * m0 + R[1, 2] * m1 + R[2, 2] * m2) / nw - h2
    _vec_update(P, h0, h1, h2, y0, y1, y2, prm[P_MAG_NOISE] ** 2 / n_use, 0.0, TRUE, dx, FALSE, 0.0)
    _apply_correction(st, dx)
    _reset_cov(P, dx, R[2, 0], R[2, 1], R[2, 2])


@njit(**INLINED)
def _mag_update(st, P, prm, R, dx, dev_m, w0, w1, w2, dt, mag_mode, gate):
    """The magnetometer update, when due (``mag_mode`` 1: heading, 2: full): the mean world-frame direction of the
    accepted samples since the last one (R = σ²/n, σ inflated by the deviation measure ``dev_m``), the reference's
    norm and dip following the accepted field (``gate`` renewed), and the reference confirmed while the body
    turns (w rad/s). Returns the flag bits (F_MAG_USED)."""
    # σ per sample: the update is the mean direction of the accepted samples since the last one and stands
    # for them (R = σ²/n; an interference at the update rate averages out, not aliases)
    n_use = st[S_USE_M]
    m0, m1, m2 = st[S_MSUM], st[S_MSUM + 1], st[S_MSUM + 2]
    t_since = dt * st[S_CNT_M]
    _propagate_pending(st, P, prm)
    if dev_m < 1.0:  # undisturbed: a candidate new field is forgotten, and the reference's field has
        # held over the samples since the last update; while the body turns that confirms it
        st[S_MCCNT], st[S_MCT] = 0.0, 0.0
        turning = w0 * w0 + w1 * w1 + w2 * w2 >= prm[P_MAG_NEW_RATE] ** 2
        if st[S_MREF_T] < prm[P_MAG_NEW_FIRST] and turning:
            st[S_MREF_T] += min(dt, prm[P_GAP_DT]) * st[S_CNT_M]
    if prm[P_MAG_REF_TAU] > 0 and n_use > 0:
        # the reference norm and dip follow the accepted field: a running mean at start-up (one
        # noisy or disturbed first sample must not set the gates for the whole run), then τ_ref
        cnt = st[S_MREF_N] + n_use
        t_ref = min(dt, prm[P_GAP_DT]) * st[S_CNT_M]  # a gap's length is no time of accepted field
        al = min(1.0, max(n_use / cnt, t_ref / prm[P_MAG_REF_TAU]))
        st[S_MREF_N] = cnt
        st[S_MNORM] += al * (st[S_MNSUM] / n_use - st[S_MNORM])
        szr = st[S_MREF + 2] + al * (m2 / n_use - st[S_MREF + 2])
        szr = min(1.0, max(-1.0, szr))
        st[S_MREF], st[S_MREF + 1], st[S_MREF + 2] = np.sqrt(1.0 - szr * szr), 0.0, szr
        gate[2], gate[3], gate[4] = _dip_gate(szr, gate[0], gate[1])
    st[S_CNT_M], st[S_USE_M], st[S_MNSUM] = 0.0, 0.0, 0.0
    st[S_MSUM], st[S_MSUM + 1], st[S_MSUM + 2] = 0.0, 0.0, 0.0
    if mag_mode == 1:
        yh = -fast_atan2(m1, m0)  # heading error: the horizontal field should point north
        sm2 = prm[P_MAG_NOISE] ** 2 * (1.0 + dev_m)
        # a heading off by more than mag_bias_gate σ (against the undisturbed σ: the de-weighting must not
        # hide it) is the heading's error, not the gyro's: the bias does not learn from it
        nis_m = _heading_update(
            P,
            R[2, 0],
            R[2, 1],
            R[2, 2],
            yh,
            sm2 / n_use,
            dx,
            prm[P_MAG_BIAS] == 0.0,
            sm2 - sm2 / n_use,
            prm[P_MAG_BIAS_GATE] ** 2,
            prm[P_MAG_NOISE] ** 2 / n_use,
        )
        if prm[P_NIS_TAU] > 0 and dt > 0:
            st[S_NIS_M] += min(1.0, t_since / prm[P_NIS_TAU]) * (min(nis_m, 1e6) - st[S_NIS_M])
        _apply_correction(st, dx)  # dx along r: its reset is G = I
    else:
        _mag_vector_update(st, P, prm, R, dx, m0, m1, m2, n_use)
    return F_MAG_USED
