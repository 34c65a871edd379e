"""Low-passes of the EKF: the accelerometer's second-order Butterworth (delay τ) and first-order stages."""

from __future__ import annotations

from formats.jit.decorators import njit
from imutool.attitude.layout import LP_MEAN_MAX, LP_MEAN_START


@njit(inline="always")  # small and on the per-sample path: compiled into each caller
def _low_pass_gain(dt, half_tau, count):
    """Gain of one first-order stage of time constant ``half_tau`` (s) over a step dt (s): dt / (τ/2 + dt), and
    at least 1/count, so that a low-pass that has seen ``count`` samples starts as their running mean."""
    return max(dt / (half_tau + dt) if dt > 0 else 0.0, 1.0 / count)


@njit(inline="always")  # small and on the per-sample path: compiled into each caller
def _low_pass_two_stages(st, s1, s2, x0, x1, x2, al):
    """Two first-order low-pass stages of one 3-vector, in place in an array (the filter state, or a local
    buffer): st[s1:s1+3] follows x with the gain al (:func:`_low_pass_gain`), st[s2:s2+3] follows st[s1:s1+3]
    with the same gain."""
    st[s1] += al * (x0 - st[s1])
    st[s1 + 1] += al * (x1 - st[s1 + 1])
    st[s1 + 2] += al * (x2 - st[s1 + 2])
    st[s2] += al * (st[s1] - st[s2])
    st[s2 + 1] += al * (st[s1 + 1] - st[s2 + 1])
    st[s2 + 2] += al * (st[s1 + 2] - st[s2 + 2])


@njit(inline="always")  # small and on the per-sample path: compiled into each caller
def _butterworth_gains(dt, tau, count):
    """Gains of one step dt (s) of the accelerometer's low-pass: second order, Butterworth (VQF's; cut-off
    ω_c = √2/τ, damping ζ = 1/√2), so that its delay at low frequency is τ (s) and it attenuates translational
    acceleration between 0.2 and 1 Hz up to 2× more than two first-order stages of τ/2 of the same delay (the two
    cross near 0.12 Hz). Discretised by backward Euler (stable at any step, DC gain exactly 1). Returns (m, a, e):
    while the low-pass has seen less than ≈ min(LP_MEAN_START·τ, LP_MEAN_MAX) s (``count`` samples; also at
    dt = 0) it is their running mean, m = 1/count; after, m = 0, e = 1/(1 + 2ζω_c·dt + ω_c²·dt²) and
    a = ω_c²·dt·e (see :func:`_butterworth_step`)."""
    if dt > 0 and 1.0 / count <= dt / (min(LP_MEAN_START * tau, LP_MEAN_MAX) + dt):
        k2dt = 2.0 * dt / (tau * tau)
        e = 1.0 / (1.0 + 2.0 * dt / tau + k2dt * dt)
        return 0.0, k2dt * e, e
    return 1.0 / count, 0.0, 1.0


@njit(inline="always")  # small and on the per-sample path: compiled into each caller
def _butterworth_step(v, y, x, m, a, e, dt):
    """One element of the low-pass of :func:`_butterworth_gains`: its output y follows the input x, v is y's rate
    (per s). Returns the new (v, y): v ← e·v + a·(x − y), y ← y + dt·v."""
    if m > 0:
        return v, y + m * (x - y)
    v = e * v + a * (x - y)
    return v, y + dt * v
