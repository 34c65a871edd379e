"""Error statistics and time alignment shared by every evaluator (attitude, heave, INS, reports).

All functions take plain numpy arrays; NaN samples are ignored and counted.
"""

from __future__ import annotations

import numpy as np

from formats.frames import angle_diff_deg as angle_diff_deg  # the one rule for angle errors, re-exported
from formats.frames import quat_conjugate, quat_multiply


def error_stats(err: np.ndarray) -> dict[str, float]:
    """RMSE, max |e|, 95th percentile |e|, mean |e|, mean (bias), std and N of an error series (NaN ignored)."""
    e = np.asarray(err, dtype=float).ravel()
    ok = np.isfinite(e)
    n = int(ok.sum())
    if n == 0:
        nan = float("nan")
        return {"n": 0, "rmse": nan, "max_abs": nan, "p95_abs": nan, "mae": nan, "mean": nan, "std": nan}
    e = e[ok]
    a = np.abs(e)
    return {
        "n": n,
        "rmse": float(np.sqrt(np.mean(e * e))),
        "max_abs": float(a.max()),
        "p95_abs": float(np.percentile(a, 95)),
        "mae": float(a.mean()),
        "mean": float(e.mean()),
        "std": float(e.std()),
    }


def interp_to(t_target: np.ndarray, t_src: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Linear interpolation of (N,) or (N,k) values onto t_target; NaN outside the source span.

    Each column is interpolated from its own finite samples: a channel whose samples sit on rows of their own
    between NaN rows (an NMEA log's 1 Hz HDT among 10 Hz sentences) is not lost. Between two finite samples
    farther apart than :data:`BRIDGE_STEPS` × the column's median finite step (a real gap, or a NaN run in a
    regularly sampled channel) with NaN rows between them the result is NaN, as it was before."""
    v = np.asarray(values, dtype=float)
    v2 = v.reshape(len(v), -1)
    t_src = np.asarray(t_src, dtype=float)
    t_target = np.asarray(t_target, dtype=float)
    cols = []
    for j in range(v2.shape[1]):
        c = v2[:, j]
        ok = np.isfinite(c)
        if ok.all() or ok.sum() < 2:
            cols.append(np.interp(t_target, t_src, c, left=np.nan, right=np.nan))
            continue
        idx = np.flatnonzero(ok)
        ts, cs = t_src[idx], c[idx]
        r = np.interp(t_target, ts, cs, left=np.nan, right=np.nan)
        steps = np.diff(ts)
        limit = BRIDGE_STEPS * float(np.median(steps))
        k = np.clip(np.searchsorted(ts, t_target, side="right") - 1, 0, len(ts) - 2)
        missing = (steps > limit) & (np.diff(idx) > 1)  # NaN rows inside a long step: samples are missing there
        on_sample = np.isin(t_target, ts)
        r[missing[k] & ~on_sample] = np.nan
        cols.append(r)
    out = np.stack(cols, axis=1)
    return out[:, 0] if v.ndim == 1 else out


BRIDGE_STEPS = 1.5  # interp_to bridges NaN rows between finite samples at most this many median finite steps apart


MAX_LAG_STEPS = 4000  # lags tried on one grid by best_lag (each one interpolates the whole series)


def _lag_grid_min(
    t: np.ndarray, x: np.ndarray, t_ref: np.ndarray, ref: np.ndarray, lags: np.ndarray, wrap_deg: bool
) -> tuple[float, int, np.ndarray]:
    """(best lag, its index, RMS cost of every lag) over the grid ``lags`` (s)."""
    costs = np.empty(len(lags))
    for i, lag in enumerate(lags):
        r = interp_to(t - lag, t_ref, ref)
        d = angle_diff_deg(x, r) if wrap_deg else x - r
        ok = np.isfinite(d)
        costs[i] = np.sqrt(np.mean(d[ok] ** 2)) if ok.sum() > 10 else np.inf
    k = int(np.argmin(costs))
    return float(lags[k]), k, costs


def best_lag(
    t: np.ndarray,
    x: np.ndarray,
    t_ref: np.ndarray,
    ref: np.ndarray,
    max_lag_s: float,
    step_s: float | None = None,
    wrap_deg: bool = False,
) -> tuple[float, float]:
    """The constant lag L (s) in [−max, +max] minimising RMS of x(t) − ref(t − L), and that RMS.

    Positive L means x lags the reference (x at time t equals the reference at t − L).
    Coarse grid then a parabolic refinement. ``wrap_deg`` compares on the circle (differences in (−180°, 180°],
    :func:`formats.frames.angle_diff_deg`). The search never goes
    beyond the two series' combined span (a larger lag leaves nothing to compare), and a range of more than
    :data:`MAX_LAG_STEPS` steps is searched on a coarser grid first, then at ``step_s`` around its best lag.
    """
    t = np.asarray(t, float)
    x = np.asarray(x, float)
    if step_s is None:
        step_s = float(np.median(np.diff(t))) if len(t) > 1 else 0.01
    t_ref = np.asarray(t_ref, float)
    if len(t) and len(t_ref):
        span = max(float(t[-1]), float(t_ref[-1])) - min(float(t[0]), float(t_ref[0]))
        max_lag_s = min(float(max_lag_s), span)
    if step_s > 0 and 2 * max_lag_s / step_s > MAX_LAG_STEPS:
        coarse = 2 * max_lag_s / MAX_LAG_STEPS
        centre = _lag_grid_min(t, x, t_ref, ref, np.arange(-max_lag_s, max_lag_s + coarse / 2, coarse), wrap_deg)[0]
        lags = np.arange(centre - 2 * coarse, centre + 2 * coarse + step_s / 2, step_s)
    else:
        lags = np.arange(-max_lag_s, max_lag_s + step_s / 2, step_s)
    k, costs = _lag_grid_min(t, x, t_ref, ref, lags, wrap_deg)[1:]
    lag = float(lags[k])
    if 0 < k < len(lags) - 1 and np.all(np.isfinite(costs[k - 1 : k + 2])):
        c0, c1, c2 = costs[k - 1], costs[k], costs[k + 1]
        den = c0 - 2 * c1 + c2
        if den > 0:
            lag += 0.5 * step_s * (c0 - c2) / den
    return lag, float(costs[k])


# ---- attitude evaluation (added by the attitude area; the functions above are unchanged) ------------------


def snr_db(filtered: np.ndarray, raw: np.ndarray) -> float:
    """Roll paper eq. 20: SNR_dB = 10·log10(Σ s² / Σ (s − ŝ)²), s = filtered signal, ŝ = raw measured signal."""
    s = np.asarray(filtered, float)
    r = np.asarray(raw, float)
    ok = np.isfinite(s) & np.isfinite(r)
    den = float(np.sum((s[ok] - r[ok]) ** 2))
    return float(10 * np.log10(np.sum(s[ok] ** 2) / den)) if den > 0 else float("inf")


def quat_errors(q_est: np.ndarray, q_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """BROAD error angles (rad) per sample with d = q_est ⊗ q_ref* (world frame): total = 2·acos|d_w|,
    heading = 2·atan(|d_z| / |d_w|) (rotation about the vertical), inclination = 2·acos√(d_w² + d_z²)
    (angle between the two z axes)."""
    d = quat_multiply(np.asarray(q_est, float), quat_conjugate(np.asarray(q_ref, float)))
    dw, dz = np.abs(d[..., 0]), np.abs(d[..., 3])
    total = 2 * np.arccos(np.clip(dw, 0.0, 1.0))
    heading = 2 * np.arctan2(dz, dw)
    incl = 2 * np.arccos(np.clip(np.sqrt(d[..., 0] ** 2 + d[..., 3] ** 2), 0.0, 1.0))
    return total, heading, incl


def evaluate_quaternion(q_est: np.ndarray, q_ref: np.ndarray, mask: np.ndarray | None = None) -> dict:
    """BROAD metrics (deg): RMSE of total, heading and inclination error over ``mask`` rows with a valid ref."""
    ok = np.all(np.isfinite(q_ref), axis=1) & np.all(np.isfinite(q_est), axis=1)
    if mask is not None:
        ok &= np.asarray(mask, bool)
    out: dict = {"n": int(ok.sum())}
    for name, e in zip(("total", "heading", "inclination"), quat_errors(q_est[ok], q_ref[ok]), strict=True):
        st = error_stats(np.degrees(e))
        out[name] = {"rmse": st["rmse"], "max_abs": st["max_abs"], "p95_abs": st["p95_abs"], "mae": st["mae"]}
    return out


def unwrap_deg(a: np.ndarray) -> np.ndarray:
    """Unwrap an angle series in degrees (NaN kept): a roll that crosses ±180° or a heading that crosses north
    becomes continuous, so that interpolating between two samples does not cross the circle the long way. A series
    without a step beyond 180° comes back unchanged (bit for bit)."""
    a = np.asarray(a, float)
    out = a.copy()
    ok = np.isfinite(a)
    if ok.sum() < 2 or not np.any(np.abs(np.diff(a[ok])) > 180.0):
        return out
    out[ok] = np.degrees(np.unwrap(np.radians(a[ok])))
    return out


GIMBAL_PITCH_DEG = 85.0
"""|pitch| (deg) beyond which roll and heading are not compared as Euler angles: near ±90° pitch they are singular
(a tenth of a degree of tilt turns roll and heading by tens of degrees); the quaternion's inclination and total
errors cover those rows."""


def evaluate_angle(
    t: np.ndarray,
    est: np.ndarray,
    t_ref: np.ndarray,
    ref: np.ndarray,
    *,
    wrap: bool = True,
    max_lag_s: float = 0.0,
    raw: np.ndarray | None = None,
    exclude: np.ndarray | None = None,
) -> dict:
    """Error statistics (deg) of one angle against a reference interpolated onto the estimate's time.

    wrap: compare on the circle (the default, every angle: the reference unwrapped before interpolation, errors in
    (−180°, 180°], :func:`formats.frames.angle_diff_deg` — a roll near ±180° or a heading near north); False: a
    plain difference. max_lag_s > 0 adds the response time (the lag L minimising RMS of est(t) − ref(t − L),
    positive = estimate lags) and the RMSE once that lag is removed. raw: the unfiltered measured angle on ``t`` →
    SNR_dB (paper eq. 20) and, with the reference, the SNR improvement 10·log10(Σ(raw−ref)² / Σ(est−ref)²).
    exclude: rows of ``t`` left out (e.g. near gimbal lock), counted as ``excluded``.
    """
    est = np.asarray(est, float)
    if exclude is not None:
        est = np.where(np.asarray(exclude, bool), np.nan, est)
    r = interp_to(t, t_ref, unwrap_deg(ref) if wrap else ref)
    e = angle_diff_deg(est, r) if wrap else est - r
    out = error_stats(e)
    if exclude is not None:
        out["excluded"] = int(np.count_nonzero(exclude))
    if max_lag_s > 0:
        lag, rms = best_lag(
            t, unwrap_deg(est) if wrap else est, t_ref, unwrap_deg(ref) if wrap else ref, max_lag_s, wrap_deg=wrap
        )
        out["lag_s"] = lag
        out["rmse_lag_removed"] = rms
    if raw is not None:
        raw = np.asarray(raw, float)
        if wrap:
            s = unwrap_deg(est)
            rr = s + angle_diff_deg(raw, s)
        else:
            s, rr = est, raw
        out["snr_db"] = snr_db(s, rr)
        er = rr - (r if not wrap else s - e)
        ok = np.isfinite(er) & np.isfinite(e)
        if ok.any() and np.sum(e[ok] ** 2) > 0:
            out["snr_gain_db"] = float(10 * np.log10(np.sum(er[ok] ** 2) / np.sum(e[ok] ** 2)))
            out["raw_rmse"] = float(np.sqrt(np.mean(er[ok] ** 2)))
    return out


def attitude_rmse(est, ref) -> dict:
    """Roll/pitch/heading RMSE (deg) of an estimate Recording against ref_* channels of ``ref`` (same clock or
    interpolated)."""
    out = {}
    for name in ("roll", "pitch", "heading"):
        if name in est.channels and f"ref_{name}" in ref.channels:
            st = evaluate_angle(est.time, est[name], ref.time, ref[f"ref_{name}"])
            out[name] = round(st["rmse"], 4)
    return out


def heave_accuracy(
    t_est: np.ndarray,
    heave_est: np.ndarray,
    t_ref: np.ndarray,
    heave_ref: np.ndarray,
    *,
    lag_s: float = 0.0,
    mask: np.ndarray | None = None,
    floor_m: float = 0.05,
    pct: float = 5.0,
    sample_fraction: float = 0.95,
) -> dict:
    """A heave error under the three readings of "5 cm or 5 %" (heave m, any one sign convention for both).

    The estimate at t is compared with the reference at t − lag_s (``mask``: samples to use, e.g. settled).
    Hs = 4 σ of the reference over the compared samples (significant heave), significant amplitude Hs/2.

    - ``significant``: RMS error ≤ max(floor, pct % of Hs) — the reading imutool's README used;
    - ``amplitude``: RMS error ≤ max(floor, pct % of the significant amplitude Hs/2);
    - ``per_sample``: |error| ≤ max(floor, pct % of |reference heave| at that sample) for at least
      ``sample_fraction`` of the samples (95 %: IMO treats accuracy figures as 95 % bounds, MSC.1/Circ.1575).

    Vendors state "5 cm or 5 %" without saying 5 % of what (standards.md §4): report all three.
    """
    te = np.asarray(t_est, dtype=float)
    he = np.asarray(heave_est, dtype=float)
    m = np.ones(len(te), bool) if mask is None else np.asarray(mask, bool)
    r = interp_to(te - lag_s, np.asarray(t_ref, float), np.asarray(heave_ref, float))
    ok = m & np.isfinite(he) & np.isfinite(r)
    n = int(ok.sum())
    if n < 10:
        nan = float("nan")
        return {"n": n, "hs_ref_m": nan, "rmse_m": nan, "significant": None, "amplitude": None, "per_sample": None}
    e = he[ok] - r[ok]
    rmse = float(np.sqrt(np.mean(e * e)))
    hs = float(4.0 * np.std(r[ok]))
    f = pct / 100.0
    tol_s = max(floor_m, f * hs)
    tol_a = max(floor_m, f * hs / 2.0)
    within = np.abs(e) <= np.maximum(floor_m, f * np.abs(r[ok]))
    frac = float(np.mean(within))
    return {
        "n": n,
        "hs_ref_m": hs,
        "rmse_m": rmse,
        "floor_m": floor_m,
        "pct": pct,
        "significant": {
            "definition": f"RMS error <= max({floor_m:g} m, {pct:g} % of Hs = 4 sigma of the reference)",
            "tolerance_m": tol_s,
            "pass": bool(rmse <= tol_s),
        },
        "amplitude": {
            "definition": f"RMS error <= max({floor_m:g} m, {pct:g} % of the significant amplitude Hs/2)",
            "tolerance_m": tol_a,
            "pass": bool(rmse <= tol_a),
        },
        "per_sample": {
            "definition": f"|error| <= max({floor_m:g} m, {pct:g} % of |reference|) at >= "
            f"{100 * sample_fraction:g} % of samples",
            "fraction_within": frac,
            "p95_abs_m": float(np.percentile(np.abs(e), 95)),
            "pass": bool(frac >= sample_fraction),
        },
    }
