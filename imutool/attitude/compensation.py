"""The accelerometer's kinematic compensation: what the specific force holds besides gravity, removed before the gate
and the low-pass (beyond the paper; docs/attitude.md, "At sea" and "Velocity aiding").

Frames and units: body FRD, world NED, m/s² (force), rad/s (rates), m (arms), s. Each is called only where its
option is on (a lever arm, a GNSS speed and course, a GNSS velocity), so the default loop makes no call.

- Lever arm: the sensor at r from the centre of rotation feels ω̇ × r + ω × (ω × r) (ω low-passed, ``lever_tau``).
- The turn, from SOG/COG: a_ned = SȮG·[cos χ, sin χ, 0] + SOG·r·[−sin χ, cos χ, 0], f = Rᵀ(a_ned − g_ned).
- Velocity aiding: ∫ R_I f dt between two velocity fixes = R_IN (Δv_s − g Δt); the low-pass takes each interval's
  mean force less Δv_s/Δt (``_velocity_aiding``).
"""

from __future__ import annotations

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.jit.decorators import njit
from imutool.attitude.layout import (
    CALLED,
    P_LEVER_TAU,
    S_QI,
    S_VA_BAD,
    S_VA_HAVE,
    S_VA_IN,
    S_VA_LAST,
    S_VA_OK,
    S_VA_PREV,
    S_VA_SUM,
    S_VA_T,
    S_VA_TFIX,
    S_WDOT,
    S_WINIT,
    S_WLP,
    VA_MAX_INTERVAL,
    VA_MIN_SPACING,
)
from imutool.quaternion import rmat


@njit(**CALLED)
def _lever_arm(st, prm, lever, gk0, gk1, gk2, dt, ax, ay, az, acc_ok):
    """The specific force (m/s², body) less the lever arm's rotation terms; the rate's low-pass advanced by dt (s)."""
    if dt > 0:
        # rotation about the centre: the sensor at r feels ω̇ × r + ω × (ω × r); ω low-passed (τ = lever LP) and
        # differentiated (bias-free rate; the bias cancels in ω̇ and is negligible in ω × (ω × r))
        al = dt / (prm[P_LEVER_TAU] + dt) if prm[P_LEVER_TAU] > 0 else 1.0
        if st[S_WINIT] == 0.0:
            st[S_WLP], st[S_WLP + 1], st[S_WLP + 2] = gk0 - st[4], gk1 - st[5], gk2 - st[6]
            st[S_WINIT] = 1.0
        for i in range(3):
            wi = (gk0 if i == 0 else (gk1 if i == 1 else gk2)) - st[4 + i]
            new = st[S_WLP + i] + al * (wi - st[S_WLP + i])
            st[S_WDOT + i] = (new - st[S_WLP + i]) / dt
            st[S_WLP + i] = new
    if acc_ok:
        wx, wy, wz = st[S_WLP], st[S_WLP + 1], st[S_WLP + 2]
        ex, ey, ez = st[S_WDOT], st[S_WDOT + 1], st[S_WDOT + 2]
        rx, ry, rz = lever[0], lever[1], lever[2]
        cx, cy, cz = wy * rz - wz * ry, wz * rx - wx * rz, wx * ry - wy * rx  # ω × r
        ax -= (ey * rz - ez * ry) + (wy * cz - wz * cy)
        ay -= (ez * rx - ex * rz) + (wz * cx - wx * cz)
        az -= (ex * ry - ey * rx) + (wx * cy - wy * cx)
    return ax, ay, az


@njit(**CALLED)
def _gnss_force(st, R, gk0, gk1, gk2, sog, cog, sogdot, along_bow, ax, ay, az):
    """The specific force (m/s², body) less the GNSS kinematic acceleration (sog m/s, cog rad, sogdot m/s²) of the
    turn: along the course, or ``along_bow`` where no heading is held (the course cannot be turned into body axes
    then; the bow's direction can, whatever the heading's error)."""
    wr = R[2, 0] * (gk0 - st[4]) + R[2, 1] * (gk1 - st[5]) + R[2, 2] * (gk2 - st[6])
    if along_bow:
        hn = max(np.sqrt(R[0, 0] * R[0, 0] + R[1, 0] * R[1, 0]), 1e-9)
        c, s = R[0, 0] / hn, R[1, 0] / hn
    else:
        c, s = np.cos(cog), np.sin(cog)
    sd = sogdot if np.isfinite(sogdot) else 0.0
    an0 = sd * c - sog * wr * s
    an1 = sd * s + sog * wr * c
    ax -= R[0, 0] * an0 + R[1, 0] * an1
    ay -= R[0, 1] * an0 + R[1, 1] * an1
    az -= R[0, 2] * an0 + R[1, 2] * an1
    return ax, ay, az


@njit(**CALLED)
def _velocity_aiding(st, R, RI, tk, vn_k, ve_k, w0, w1, w2, arm_sa, ax, ay, az, dt, gap, acc_ok):
    """Velocity aiding's interval sums at one row (time tk s, the antenna's north/east velocity m/s, the bias-free
    rate w rad/s, the force a m/s² body); True if RI = R(q_I) was computed for this row."""
    ri_now = False
    # velocity aiding: ∫ R_I f dt between two velocity fixes is R_I·(Δv − g Δt) whatever the translation
    # (sway, surge, turn, at any frequency), so the mean force of an interval less Δv/Δt is gravity in I;
    # the low-pass takes it, one interval late, while the fixes keep coming (docs/attitude.md)
    if gap:  # the frame I restarted: no interval across a gap
        st[S_VA_HAVE], st[S_VA_OK] = 0.0, 0.0
    elif dt > 0:
        if acc_ok:
            rmat(st[S_QI], st[S_QI + 1], st[S_QI + 2], st[S_QI + 3], RI)
            ri_now = True
            for i in range(3):
                st[S_VA_SUM + i] += (RI[i, 0] * ax + RI[i, 1] * ay + RI[i, 2] * az) * dt
        else:
            st[S_VA_BAD] = 1.0
        st[S_VA_T] += dt
    is_fix = (
        np.isfinite(vn_k)
        and np.isfinite(ve_k)
        and not (vn_k == st[S_VA_LAST] and ve_k == st[S_VA_LAST + 1])
        and not (st[S_VA_HAVE] > 0 and tk - st[S_VA_TFIX] < VA_MIN_SPACING)
    )
    st[S_VA_LAST], st[S_VA_LAST + 1] = vn_k, ve_k
    if is_fix:
        # the sensor's horizontal velocity: the antenna's plus R (ω × r), r from the antenna to the sensor
        cx = w1 * arm_sa[2] - w2 * arm_sa[1]
        cy = w2 * arm_sa[0] - w0 * arm_sa[2]
        cz = w0 * arm_sa[1] - w1 * arm_sa[0]
        vel_n = vn_k + R[0, 0] * cx + R[0, 1] * cy + R[0, 2] * cz
        vel_e = ve_k + R[1, 0] * cx + R[1, 1] * cy + R[1, 2] * cz
        span = st[S_VA_T]
        if st[S_VA_HAVE] > 0 and st[S_VA_BAD] == 0.0 and 0.0 < span <= VA_MAX_INTERVAL:
            acc_n = (vel_n - st[S_VA_PREV]) / span
            acc_e = (vel_e - st[S_VA_PREV + 1]) / span
            if not ri_now:
                rmat(st[S_QI], st[S_QI + 1], st[S_QI + 2], st[S_QI + 3], RI)
                ri_now = True
            bx = R[0, 0] * acc_n + R[1, 0] * acc_e  # body: Rᵀ (acc_n, acc_e, 0)
            by = R[0, 1] * acc_n + R[1, 1] * acc_e
            bz = R[0, 2] * acc_n + R[1, 2] * acc_e
            for i in range(3):
                st[S_VA_IN + i] = st[S_VA_SUM + i] / span - (RI[i, 0] * bx + RI[i, 1] * by + RI[i, 2] * bz)
            st[S_VA_OK] = 1.0
        else:
            st[S_VA_OK] = 0.0
        st[S_VA_PREV], st[S_VA_PREV + 1] = vel_n, vel_e
        st[S_VA_HAVE], st[S_VA_TFIX] = 1.0, tk
        st[S_VA_SUM], st[S_VA_SUM + 1], st[S_VA_SUM + 2] = 0.0, 0.0, 0.0
        st[S_VA_T], st[S_VA_BAD] = 0.0, 0.0
    elif st[S_VA_OK] > 0 and tk - st[S_VA_TFIX] > VA_MAX_INTERVAL:
        st[S_VA_OK] = 0.0  # the fixes stopped: the low-pass takes the force again
    return ri_now
