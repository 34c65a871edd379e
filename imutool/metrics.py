"""Error statistics and time alignment shared by every evaluator (attitude, heave, INS, reports).

All functions take plain numpy arrays; NaN samples are ignored and counted.
"""

from __future__ import annotations

import numpy as np


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
    """Linear interpolation of (N,) or (N,k) values onto t_target; NaN outside the source span."""
    v = np.asarray(values, dtype=float)
    v2 = v.reshape(len(v), -1)
    out = np.stack([np.interp(t_target, t_src, v2[:, j], left=np.nan, right=np.nan) for j in range(v2.shape[1])],
                   axis=1)
    return out[:, 0] if v.ndim == 1 else out


def best_lag(t: np.ndarray, x: np.ndarray, t_ref: np.ndarray, ref: np.ndarray, max_lag_s: float,
             step_s: float | None = None, wrap_deg: bool = False) -> tuple[float, float]:
    """The constant lag L (s) in [−max, +max] minimising RMS of x(t) − ref(t − L), and that RMS.

    Positive L means x lags the reference (x at time t equals the reference at t − L).
    Coarse grid then a parabolic refinement. ``wrap_deg`` wraps differences to ±180°.
    """
    t = np.asarray(t, float)
    x = np.asarray(x, float)
    if step_s is None:
        step_s = float(np.median(np.diff(t))) if len(t) > 1 else 0.01
    lags = np.arange(-max_lag_s, max_lag_s + step_s / 2, step_s)
    costs = np.empty(len(lags))
    for i, lag in enumerate(lags):
        r = interp_to(t - lag, t_ref, ref)
        d = x - r
        if wrap_deg:
            d = (d + 180.0) % 360.0 - 180.0
        ok = np.isfinite(d)
        costs[i] = np.sqrt(np.mean(d[ok] ** 2)) if ok.sum() > 10 else np.inf
    k = int(np.argmin(costs))
    lag = float(lags[k])
    if 0 < k < len(lags) - 1 and np.all(np.isfinite(costs[k - 1:k + 2])):
        c0, c1, c2 = costs[k - 1], costs[k], costs[k + 1]
        den = c0 - 2 * c1 + c2
        if den > 0:
            lag += 0.5 * step_s * (c0 - c2) / den
    return lag, float(costs[k])
