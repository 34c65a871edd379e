"""Zero-velocity interval (ZVI) detection for foot-mounted (or any resting) IMUs.

Detectors (all work on gyro rad/s and specific force m/s², any right-handed body frame):

- ``paper`` — the INS paper's eq. 43: sample m is a ZVI sample when |y_g,i| ≤ B_g for every i with
  |i − m| ≤ N_g/2 AND |y_a,i − y_a,i−1| ≤ B_a for every i with |i − m| ≤ N_a/2. Windows are given in
  seconds (N = round(window·fs), made odd) so one set of defaults serves 100 Hz and 400 Hz logs.
- ``shoe`` — SHOE / GLRT (Skog et al. 2010, eq. 7): T = 1/W Σ_k ( |y_a,k − g·ȳ_a/|ȳ_a||² / σ_a² + |y_g,k|² / σ_g² ).
- ``are`` — angular-rate energy: T = 1/W Σ_k |y_g,k|² / σ_g².
- ``mv`` — acceleration moving variance: T = 1/W Σ_k |y_a,k − ȳ_a|² / σ_a².
- ``mag`` — acceleration magnitude: T = 1/W Σ_k (|y_a,k| − g)² / σ_a².

For the Skog detectors a sample is stationary when T < γ (window centred on the sample). The paper detector's
statistic is reported normalised, max(max|y_g|/B_g, max|Δy_a|/B_a), stationary when ≤ 1. Every detector then
drops intervals shorter than ``min_duration_s``. Window sums use cumulative sums (vectorised, O(N)).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from formats import Recording
from formats.errors import ImutoolError

GRAVITY = 9.80665  # m/s², magnitude used by SHOE and MAG

DETECTORS = ("paper", "shoe", "are", "mv", "mag")

# Named parameters and defaults (SI units). Tuned once on the simulator's `walk` (400 Hz and 100 Hz) and on the
# x-io NGIMU foot walks; see docs/ins.md.
DEFAULTS: dict[str, dict[str, float]] = {
    # B_g rad/s, B_a m/s² (per-sample accel difference), windows in s
    "paper": {"b_g": 0.6, "b_a": 2.0, "window_g_s": 0.05, "window_a_s": 0.05, "min_duration_s": 0.05},
    # sigma_a m/s², sigma_g rad/s (Skog's 0.01 m/s² and 0.1 deg/s), gamma dimensionless
    "shoe": {
        "gamma": 1e5,
        "sigma_a": 0.01,
        "sigma_g": float(np.radians(0.1)),
        "window_s": 0.05,
        "min_duration_s": 0.05,
    },
    "are": {"gamma": 1e5, "sigma_g": float(np.radians(0.1)), "window_s": 0.05, "min_duration_s": 0.05},
    "mv": {"gamma": 1.5e4, "sigma_a": 0.01, "window_s": 0.05, "min_duration_s": 0.05},
    "mag": {"gamma": 1.5e4, "sigma_a": 0.01, "window_s": 0.05, "min_duration_s": 0.05},
}

PARAM_HELP: dict[str, str] = {
    "b_g": "paper: gyro magnitude bound B_g (rad/s)",
    "b_a": "paper: accel first-difference bound B_a (m/s² per sample)",
    "window_g_s": "paper: gyro window N_g (s)",
    "window_a_s": "paper: accel-difference window N_a (s)",
    "gamma": "Skog detectors: threshold γ on the test statistic (stationary when T < γ)",
    "sigma_a": "accelerometer white-noise std σ_a (m/s²) normalising the statistic",
    "sigma_g": "gyro white-noise std σ_g (rad/s) normalising the statistic",
    "window_s": "Skog detectors: window W (s), centred on the sample",
    "min_duration_s": "intervals shorter than this (s) are dropped",
}


@dataclass
class ZviResult:
    """Per-sample ZVI flags, the detector statistic and the threshold it was compared with."""

    time: np.ndarray  # (N,) s
    flags: np.ndarray  # (N,) bool, True = zero velocity
    statistic: np.ndarray  # (N,) detector statistic (dimensionless)
    threshold: float  # stationary when statistic < threshold (paper: ≤ 1)
    detector: str
    params: dict[str, float]
    parts: dict[str, np.ndarray] = field(default_factory=dict)  # extra statistics (paper: gyro/accel parts)

    @property
    def intervals(self) -> np.ndarray:
        """(k, 2) array of [start, end] times (s) of each interval (first and last flagged sample)."""
        idx = interval_indices(self.flags)
        if len(idx) == 0:
            return np.zeros((0, 2))
        return np.column_stack([self.time[idx[:, 0]], self.time[idx[:, 1] - 1]])

    def table(self) -> list[dict[str, float]]:
        """Interval table rows: start_s, end_s, duration_s."""
        return [{"start_s": float(a), "end_s": float(b), "duration_s": float(b - a)} for a, b in self.intervals]

    def summary(self) -> dict[str, Any]:
        iv = self.intervals
        dur = iv[:, 1] - iv[:, 0] if len(iv) else np.zeros(0)
        return {
            "detector": self.detector,
            "params": {k: float(v) for k, v in self.params.items()},
            "samples": int(len(self.flags)),
            "zvi_fraction": round(float(np.mean(self.flags)) if len(self.flags) else 0.0, 4),
            "intervals": int(len(iv)),
            "mean_duration_s": round(float(dur.mean()), 4) if len(dur) else None,
        }


def interval_indices(flags: np.ndarray) -> np.ndarray:
    """(k, 2) int array of [start, stop) sample indices of the runs of True in ``flags``."""
    f = np.asarray(flags, dtype=bool).astype(np.int8)
    d = np.diff(np.concatenate([[0], f, [0]]))
    starts = np.flatnonzero(d == 1)
    stops = np.flatnonzero(d == -1)
    return np.column_stack([starts, stops]).astype(np.int64)


def drop_short(time: np.ndarray, flags: np.ndarray, min_duration_s: float) -> np.ndarray:
    """Flags with intervals shorter than ``min_duration_s`` (first to last sample) removed."""
    out = np.asarray(flags, dtype=bool).copy()
    if min_duration_s <= 0:
        return out
    for a, b in interval_indices(out):
        if time[b - 1] - time[a] < min_duration_s:
            out[a:b] = False
    return out


def _window_samples(window_s: float, fs: float) -> int:
    n = max(1, int(round(window_s * fs)))
    return n if n % 2 == 1 else n + 1


def _window_sum(x: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Centred window sums of x (N,) or (N,k) over w (odd) samples, shrunk at the ends; also the counts."""
    n = x.shape[0]
    h = w // 2
    c = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0)])
    lo = np.clip(np.arange(n) - h, 0, n)
    hi = np.clip(np.arange(n) + h + 1, 0, n)
    return c[hi] - c[lo], (hi - lo).astype(float)


def _window_max(x: np.ndarray, w: int) -> np.ndarray:
    from scipy.ndimage import maximum_filter1d

    return maximum_filter1d(x, size=w, mode="nearest")


def _check_inputs(time: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> tuple[np.ndarray, ...]:
    t = np.asarray(time, dtype=float)
    g = np.asarray(gyro, dtype=float)
    a = np.asarray(accel, dtype=float)
    if g.shape != (len(t), 3) or a.shape != (len(t), 3):
        raise ImutoolError(f"ZVI detection needs gyro and accel of shape ({len(t)}, 3); got {g.shape}, {a.shape}")
    if len(t) < 3:
        raise ImutoolError(f"ZVI detection needs at least 3 samples; got {len(t)}")
    if not (np.all(np.isfinite(g)) and np.all(np.isfinite(a))):
        raise ImutoolError("ZVI detection: gyro/accel contain NaN or inf samples (clean or interpolate first)")
    return t, g, a


def resolve_params(detector: str, **params: float | None) -> dict[str, float]:
    """The detector's defaults overridden by the given (non-None) parameters; unknown names are an error."""
    if detector not in DEFAULTS:
        raise ImutoolError(f"unknown ZVI detector {detector!r}; known: {', '.join(DETECTORS)}")
    p = dict(DEFAULTS[detector])
    for k, v in params.items():
        if v is None:
            continue
        if k not in p:
            raise ImutoolError(f"detector {detector!r} has no parameter {k!r} (has: {', '.join(p)})")
        if not np.isfinite(v) or v < 0:
            raise ImutoolError(f"detector {detector!r}: parameter {k}={v} must be a finite number ≥ 0")
        p[k] = float(v)
    return p


def detect_zvi(
    time: np.ndarray, gyro: np.ndarray, accel: np.ndarray, detector: str = "shoe", **params: float | None
) -> ZviResult:
    """Detect zero-velocity samples. time (N,) s, gyro (N,3) rad/s, accel (N,3) m/s² specific force.

    ``params`` override :data:`DEFAULTS` for the detector (see :data:`PARAM_HELP`).
    """
    t, g, a = _check_inputs(time, gyro, accel)
    p = resolve_params(detector, **params)
    d = np.diff(t)
    d = d[d > 0]
    fs = 1.0 / float(np.median(d)) if d.size else 1.0
    parts: dict[str, np.ndarray] = {}
    if detector == "paper":
        ng = _window_samples(p["window_g_s"], fs)
        na = _window_samples(p["window_a_s"], fs)
        gmag = np.linalg.norm(g, axis=1)
        da = np.zeros(len(t))
        da[1:] = np.linalg.norm(np.diff(a, axis=0), axis=1)
        da[0] = da[1]
        gmax = _window_max(gmag, ng)
        amax = _window_max(da, na)
        parts = {"gyro_max": gmax / max(p["b_g"], 1e-300), "accel_diff_max": amax / max(p["b_a"], 1e-300)}
        stat = np.maximum(parts["gyro_max"], parts["accel_diff_max"])
        threshold = 1.0
        raw = stat <= threshold
    else:
        w = _window_samples(p["window_s"], fs)
        if detector in ("shoe", "are"):
            sg, cnt = _window_sum(np.einsum("ij,ij->i", g, g), w)
            tg = sg / (p["sigma_g"] ** 2)
        if detector in ("shoe", "mv"):
            s1, cnt = _window_sum(a, w)
            s2, _ = _window_sum(np.einsum("ij,ij->i", a, a), w)
            mean_norm = np.linalg.norm(s1, axis=1) / cnt
        if detector == "shoe":
            # Σ|y − g u|² with u = ȳ/|ȳ|  =  Σ|y|² − 2 g W |ȳ| + W g²
            ta = np.maximum(s2 - 2.0 * GRAVITY * cnt * mean_norm + cnt * GRAVITY**2, 0.0) / p["sigma_a"] ** 2
            stat = (ta + tg) / cnt
            parts = {"accel_part": ta / cnt, "gyro_part": tg / cnt}
        elif detector == "are":
            stat = tg / cnt
        elif detector == "mv":
            stat = np.maximum(s2 - cnt * mean_norm**2, 0.0) / p["sigma_a"] ** 2 / cnt
        else:  # mag
            sm, cnt = _window_sum((np.linalg.norm(a, axis=1) - GRAVITY) ** 2, w)
            stat = sm / p["sigma_a"] ** 2 / cnt
        threshold = p["gamma"]
        raw = stat < threshold
    flags = drop_short(t, raw, p["min_duration_s"])
    return ZviResult(t, flags, stat, float(threshold), detector, p, parts)


def detect(rec: Recording, detector: str = "shoe", **params: float | None) -> ZviResult:
    """:func:`detect_zvi` on a recording's ``gyro`` (rad/s) and ``accel`` (m/s²) channels."""
    for name in ("gyro", "accel"):
        if name not in rec.channels:
            raise ImutoolError(f"ZVI detection needs channel {name!r}; has {', '.join(rec.channels) or 'none'}")
    return detect_zvi(rec.time, rec.get("gyro", "rad/s"), rec.get("accel", "m/s^2"), detector, **params)


def flag_scores(flags: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """Precision, recall, F1 and accuracy of per-sample ZVI flags against truth flags (True = stationary)."""
    f = np.asarray(flags, dtype=bool)
    r = np.asarray(truth) > 0.5
    tp = float(np.sum(f & r))
    fp = float(np.sum(f & ~r))
    fn = float(np.sum(~f & r))
    precision = tp / (tp + fp) if tp + fp > 0 else 0.0
    recall = tp / (tp + fn) if tp + fn > 0 else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    return {"precision": precision, "recall": recall, "f1": f1, "accuracy": float(np.mean(f == r))}


def pick_threshold(
    time: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    truth: np.ndarray,
    detector: str = "shoe",
    param: str | None = None,
    grid: np.ndarray | None = None,
    **params: float | None,
) -> dict[str, Any]:
    """Grid search of one detector parameter maximising F1 against labelled flags.

    ``param`` defaults to ``gamma`` (``b_g`` for the paper detector); ``grid`` defaults to 61 log-spaced values
    from 1/30 to 30 times the default. Returns {param, value, f1, precision, recall, grid, f1_grid}.
    """
    p = resolve_params(detector, **params)
    if param is None:
        param = "b_g" if detector == "paper" else "gamma"
    if param not in p:
        raise ImutoolError(f"detector {detector!r} has no parameter {param!r}")
    if grid is None:
        grid = p[param] * np.logspace(np.log10(1 / 30), np.log10(30), 61)
    grid = np.asarray(grid, dtype=float)
    truth = np.asarray(truth)
    if truth.shape != (len(time),):
        raise ImutoolError(f"labels have shape {truth.shape}; expected ({len(time)},)")
    scores = []
    for v in grid:
        res = detect_zvi(time, gyro, accel, detector, **{**p, param: float(v)})
        scores.append(flag_scores(res.flags, truth))
    f1 = np.array([s["f1"] for s in scores])
    k = int(np.argmax(f1))
    return {
        "param": param,
        "value": float(grid[k]),
        "f1": float(f1[k]),
        "precision": scores[k]["precision"],
        "recall": scores[k]["recall"],
        "grid": grid,
        "f1_grid": f1,
    }
