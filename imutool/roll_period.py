"""Roll period about the mean heel: the detection series of :mod:`imutool.roll` and three independent estimates.

Real sea roll is small, irregular and biased (a list, a wind heel, swell on top). Counting cycles as crossings of
a fixed ±0.5° band around 0° (the method before issue 48) misses the small cycles and, on a listing ship, most of
the crossings of the far side: two or three cycles count as one and the period comes out ~2× too long. Here the
period is measured on the **detection series**:

1. **centre**: the mean heel over ``centre_window_s`` (default 120 s): a centred moving average cuts the first
   cycles, then the mean over whole cycles (:func:`cycle_mean_centre`: a window that is not a whole number of
   periods would leak the roll into the centre, the amplitudes and the crossings); ``centre="zero"`` keeps a
   level ship's 0°, e.g. a motion table;
2. **detrended roll** r = heel − centre;
3. **spectral peak period** Tp of r: Welch (Hann segments, 50 % overlap, zero-padded ×8, parabolic interpolation
   of the peak) on r resampled to its median sample interval; a segment spans 32 periods of the whole window's
   periodogram peak (the whole window when shorter: one periodogram); periods longer than ``max_period_s`` are not
   searched;
4. **smoothing**: a centred moving average of r over ``smooth_frac`` × Tp (default 1/8: the roll peak keeps 97 %
   of its amplitude; sensor noise and ripples above ~2.5 × the peak frequency are damped); skipped when it would
   span fewer than 3 samples;
5. **hysteresis scaled to the roll**: ``hysteresis_frac`` × the running RMS of the smoothed r over the centre
   window (default 0.1 × RMS), at least ``hysteresis_min_deg`` (0.05°); a fixed ``hysteresis_deg`` overrides it.
   At 0.1 × RMS a narrow-band (Rayleigh) roll loses the half-cycles with an amplitude below 0.1 σ (0.5 % of them);
   at 0.5 × RMS 12 %, and each one lost merges two cycles into one.

Three period estimates are then compared (:func:`period_estimates`): the **peak-to-peak** period (the method: mean
time between successive maxima on the same side, MSC.363(92) §3, both sides pooled; periods over 3 × their median
span a calm stretch or a gap and are left out of the means, here and in Tz), the **zero-up-crossing**
period Tz (mean time between up-crossings of the mean heel, counted on the smoothed r with a dead band of
``hysteresis_min_deg``: every cycle, however small) and the spectral peak period Tp. When the largest is more than
``disagree_frac`` (15 %) above the smallest, a warning names the three: the roll is broad-band or bimodal (swell
and wind sea), too short, or too noisy for a single period to describe it.

Minimum window: a same-side period needs two maxima on that side with one opposite excursion between them, i.e.
about 2 roll periods of samples (the first excursion is dropped when the window starts inside it); the estimates
and their cross-check need at least ``MIN_CYCLES`` (3) zero-up-crossing intervals, about 4 roll periods. Give a
trailing window of ≥ 10 roll periods (2 min for a 12 s roll) for a stable mean: the centre and the scaled
hysteresis come from the same window.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.jit.decorators import njit

MIN_CYCLES = 3
NFFT_MAX = 2**20  # zero-padding stops here (a day at 50 Hz is 4.3 M samples)
"""Zero-up-crossing intervals (and same-side periods) needed before a period estimate is reported."""


# the roll statistics' kernel with the types a command calls it with (formats.jit.warm: a second process compiles it
# on a cold cache, for `report inclinometer`)
ROLL_KERNEL = ("imutool.roll_period", "excursions", "float64[::1], float64[::1]")


@njit(cache=True)
def excursions(v: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Schmitt-trigger excursions of v (heel − centre, deg) with hysteresis h (deg, per sample).

    Returns side (+1 stbd / −1 port), start index, end index (first sample past the opposite threshold),
    index of the extreme sample, and a 0/1 flag "genuine start" (entered from inside the ±h band).
    """
    n = v.shape[0]
    side = np.zeros(n, np.int64)
    i0 = np.zeros(n, np.int64)
    i1 = np.zeros(n, np.int64)
    ie = np.zeros(n, np.int64)
    genuine = np.zeros(n, np.int64)
    k = 0
    s = 0
    start = 0
    ext = 0
    best = 0.0
    prev_in_band = False
    gen = 0
    for i in range(n):
        x = v[i]
        if np.isnan(x):
            continue
        hi = h[i]
        if s == 0:
            if x > hi:
                s = 1
            elif x < -hi:
                s = -1
            else:
                prev_in_band = True
                continue
            start = i
            ext = i
            best = x * s
            gen = 1 if prev_in_band else 0
            continue
        if x * s > best:
            best = x * s
            ext = i
        if x * s < -hi:
            side[k] = s
            i0[k] = start
            i1[k] = i
            ie[k] = ext
            genuine[k] = gen
            k += 1
            s = -s
            start = i
            ext = i
            best = x * s
            gen = 1
    return side[:k], i0[:k], i1[:k], ie[:k], genuine[:k]


def running_mean(t: np.ndarray, x: np.ndarray, window_s: float) -> np.ndarray:
    """Centred moving average of x over window_s seconds (NaN ignored; the window is cut at the ends)."""
    ok = np.isfinite(x)
    cs = np.concatenate([[0.0], np.cumsum(np.where(ok, x, 0.0))])
    cn = np.concatenate([[0], np.cumsum(ok)])
    lo = np.searchsorted(t, t - window_s / 2, side="left")
    hi = np.searchsorted(t, t + window_s / 2, side="right")
    n = cn[hi] - cn[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, (cs[hi] - cs[lo]) / np.maximum(n, 1), np.nan)


def _uniform(t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, float]:
    """Finite samples of x linearly resampled at their median interval → (series, rate Hz)."""
    ok = np.isfinite(x) & np.isfinite(t)
    tt, xx = t[ok], x[ok]
    if tt.size < 8:
        return np.zeros(0), 0.0
    dt = float(np.median(np.diff(tt)))
    if not dt > 0:
        return np.zeros(0), 0.0
    grid = np.arange(tt[0], tt[-1] + 0.5 * dt, dt)
    return np.interp(grid, tt, xx), 1.0 / dt


def _peak(f: np.ndarray, p: np.ndarray, fmin: float) -> float:
    """Frequency of the largest PSD value above fmin, refined by a parabola through log PSD of its neighbours."""
    k0 = int(np.searchsorted(f, fmin, side="left"))
    k0 = max(k0, 1)
    if k0 >= f.size - 1:
        return float("nan")
    k = k0 + int(np.argmax(p[k0:]))
    if k0 < k < f.size - 1 and np.all(p[k - 1 : k + 2] > 0):
        a, b, c = np.log(p[k - 1 : k + 2])
        den = a - 2 * b + c
        d = 0.5 * (a - c) / den if den < 0 else 0.0
        return float(f[k] + np.clip(d, -0.5, 0.5) * (f[1] - f[0]))
    return float(f[k])


def _welch_hann(x: np.ndarray, fs: float, nseg: int) -> tuple[np.ndarray, np.ndarray]:
    """One-sided Welch PSD (Hann segments of ``nseg`` samples, 50 % overlap, each zero-padded ×8 up to NFFT_MAX,
    its mean removed): :func:`scipy.signal.welch`'s density, computed with one real FFT per segment and no
    set-up (the live roll statistics call it once a second). A segment of the whole series is the periodogram."""
    from scipy.fft import rfft
    from scipy.signal import get_window

    nfft = max(nseg, min(8 * nseg, NFFT_MAX))
    win = get_window("hann", nseg)
    step = nseg - nseg // 2
    starts = range(0, x.size - nseg + 1, step)
    p = np.zeros(nfft // 2 + 1)
    for a in starts:
        seg = x[a : a + nseg]
        z = rfft((seg - seg.mean()) * win, n=nfft)
        p += z.real * z.real + z.imag * z.imag
    p *= 1.0 / (fs * float(np.sum(win * win)) * len(starts))
    p[1 : -1 if nfft % 2 == 0 else None] *= 2.0
    return np.fft.rfftfreq(nfft, 1.0 / fs), p


def spectral_peak_period(t: np.ndarray, r: np.ndarray, max_period_s: float = 60.0) -> float:
    """Peak period (s) of the spectrum of the detrended roll r (deg) by Welch's method (module doc, step 3).

    NaN when fewer than 8 finite samples or no peak below ``max_period_s``."""
    x, fs = _uniform(np.asarray(t, float), np.asarray(r, float))
    if x.size < 8:
        return float("nan")
    x = x - x.mean()
    fmin = 1.0 / max_period_s
    f, p = _welch_hann(x, fs, x.size)  # the periodogram of the whole window
    f0 = _peak(f, p, fmin)
    if not f0 > 0:
        return float("nan")
    nseg = int(min(x.size, round(32.0 / f0 * fs)))
    if nseg != x.size:  # a window shorter than 32 periods: its one segment is the periodogram already made
        f, p = _welch_hann(x, fs, nseg)
    fp = _peak(f, p, fmin)
    return 1.0 / fp if fp > 0 else float("nan")


@dataclass
class Detection:
    """The series the roll cycles are cut from (see the module doc), per sample of the input.

    centre (deg): the mean heel (0 for ``centre='zero'``); v (deg): heel − centre, smoothed; h (deg): the
    hysteresis per sample; spectral_period_s: Tp of heel − centre; smooth_s: the smoothing window (0 = none);
    settings: what was used (JSON-ready).
    """

    centre: np.ndarray
    v: np.ndarray
    h: np.ndarray
    spectral_period_s: float
    smooth_s: float
    settings: dict[str, Any]


def _series(
    t: np.ndarray,
    x: np.ndarray,
    c: np.ndarray,
    tp: float,
    hysteresis_deg: float | None,
    centre_window_s: float,
    hysteresis_frac: float,
    hysteresis_min_deg: float,
    smooth_frac: float,
) -> tuple[np.ndarray, np.ndarray, float]:
    """(v, h, smoothing window s) of heel x about centre c: steps 4 and 5 of the module doc."""
    r = x - c
    ok = np.isfinite(r)
    dt = float(np.median(np.diff(t[ok]))) if ok.sum() > 1 else 0.0
    w = smooth_frac * tp if np.isfinite(tp) else 0.0
    if dt > 0 and w >= 3 * dt:
        v = np.where(ok, running_mean(t, r, w), np.nan)
    else:
        v, w = r, 0.0
    if hysteresis_deg is None:
        rms = np.sqrt(running_mean(t, v * v, centre_window_s))
        h = np.maximum(hysteresis_frac * np.nan_to_num(rms), hysteresis_min_deg)
    else:
        h = np.full(x.shape, float(hysteresis_deg))
    return v, h, float(w)


def cycle_mean_centre(t: np.ndarray, x: np.ndarray, v: np.ndarray, h: np.ndarray, window_s: float) -> np.ndarray | None:
    """The mean heel over whole roll cycles: each cycle (up-crossing to up-crossing of v with hysteresis h) has the
    mean of its samples of x; the centre at a time is the duration-weighted mean of the cycles whose middle lies
    within ±window_s/2 (the nearest cycle's where none does). A moving average over a window that is not a whole
    number of periods leaks the roll into the centre (up to amplitude × period / (π × window), more at the ends of
    the record where the window is cut): whole cycles do not. None with fewer than 2 cycles."""
    ok = np.isfinite(x) & np.isfinite(v)
    idx = np.flatnonzero(ok)
    side, i0, _i1, _ie, _g = excursions(np.ascontiguousarray(v[idx]), np.ascontiguousarray(h[idx]))
    up = idx[i0[side == 1]]
    if up.size < 3:
        return None
    cs = np.concatenate([[0.0], np.cumsum(np.where(ok, x, 0.0))])
    cn = np.concatenate([[0], np.cumsum(ok)])
    a, b = up[:-1], up[1:]
    mean = (cs[b] - cs[a]) / np.maximum(cn[b] - cn[a], 1)
    dur = t[b] - t[a]
    mid = 0.5 * (t[a] + t[b])
    wsum = np.concatenate([[0.0], np.cumsum(dur)])
    msum = np.concatenate([[0.0], np.cumsum(dur * mean)])
    lo = np.searchsorted(mid, t - window_s / 2, side="left")
    hi = np.searchsorted(mid, t + window_s / 2, side="right")
    near = np.clip(np.searchsorted(mid, t), 0, mid.size - 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(hi > lo, (msum[hi] - msum[lo]) / (wsum[hi] - wsum[lo]), mean[near])


def detection(
    t: np.ndarray,
    heel_deg: np.ndarray,
    hysteresis_deg: float | None,
    centre: str,
    centre_window_s: float,
    max_period_s: float,
    hysteresis_frac: float,
    hysteresis_min_deg: float,
    smooth_frac: float,
) -> Detection:
    """Centre, smoothed detrended roll and hysteresis of a heel series (t s, heel deg) — steps 1–5 of the module
    doc. ``centre`` is 'running' (mean heel) or 'zero'; the caller validates it. The running centre is found in
    two passes: a moving average cuts the first cycles, whose whole-cycle means (:func:`cycle_mean_centre`) are
    the centre the cycles are then cut about."""
    x = np.asarray(heel_deg, float)
    c = running_mean(t, x, centre_window_s) if centre == "running" else np.zeros_like(x)
    tp = spectral_peak_period(t, x - c, max_period_s)
    args = (hysteresis_deg, centre_window_s, hysteresis_frac, hysteresis_min_deg, smooth_frac)
    v, h, w = _series(t, x, c, tp, *args)
    if centre == "running":
        c2 = cycle_mean_centre(t, x, v, h, centre_window_s)
        if c2 is not None:
            c = c2
            v, h, w = _series(t, x, c, tp, *args)
    ok = np.isfinite(x)
    settings = {
        "hysteresis": "auto" if hysteresis_deg is None else "fixed",
        "hysteresis_median_deg": round(float(np.median(h)), 4) if h.size else None,
        "smoothing_s": round(w, 4),
        "mean_heel_deg": round(float(np.nanmean(c[ok])), 4) if ok.any() else None,
    }
    return Detection(c, v, h, float(tp), w, settings)


def typical(d: np.ndarray, max_period_s: float = 60.0) -> np.ndarray:
    """The periods (s) that are roll cycles: finite, ≤ max_period_s and ≤ 3 × their median (a longer one spans a
    calm stretch or a gap: a flume before its waves arrive, a ship alongside), for the mean periods."""
    d = d[np.isfinite(d) & (d <= max_period_s)]
    return d[d <= 3.0 * np.median(d)] if d.size else d


def zero_up_crossing_period(
    t: np.ndarray, v: np.ndarray, deadband_deg: float, max_period_s: float = 60.0
) -> tuple[float, int]:
    """Mean zero-up-crossing period (s) of v (deg, about its mean) and the number of intervals averaged.

    An up-crossing is v passing from below −deadband to above +deadband; its time is where v crosses +deadband
    (linear between the samples: the mean interval is the same as between the zero crossings). Intervals over
    ``max_period_s`` or 3 × the median interval (gaps, calm stretches: :func:`typical`) are left out. (NaN, 0)
    with fewer than 2 crossings."""
    ok = np.isfinite(v)  # the heel's own samples (a log of several streams has other streams' rows between)
    t, v = np.asarray(t, float)[ok], np.ascontiguousarray(v[ok])
    side, i0, _i1, _ie, _gen = excursions(v, np.full(v.shape, float(deadband_deg)))
    up = i0[side == 1]
    up = up[up > 0]
    if up.size < 2:
        return float("nan"), 0
    a, b = v[up - 1], v[up]
    frac = np.where(b != a, (deadband_deg - a) / np.where(b != a, b - a, 1.0), 1.0)
    tc = t[up - 1] + np.clip(frac, 0.0, 1.0) * (t[up] - t[up - 1])
    d = typical(np.diff(tc), max_period_s)
    return (float(d.mean()), int(d.size)) if d.size else (float("nan"), 0)


def period_estimates(
    cycle_periods: np.ndarray,
    t: np.ndarray,
    det: Detection,
    deadband_deg: float,
    max_period_s: float = 60.0,
    disagree_frac: float = 0.15,
) -> tuple[dict[str, Any], list[str]]:
    """The three period estimates side by side and the warnings of their cross-check (module doc).

    cycle_periods: the same-side periods (s) of the cycle table (NaN where none). Returns (estimates, warnings):
    ``peak_to_peak_s`` (the method: mean of the same-side periods), ``zero_up_crossing_s``, ``spectral_peak_s``
    (each None when not measurable: fewer than MIN_CYCLES periods or crossings), counts and ``spread``
    (max/min − 1 of the three, None unless all three are known)."""
    per = typical(np.asarray(cycle_periods, float), max_period_s)
    p2p = float(per.mean()) if per.size >= MIN_CYCLES else None
    tz, nz = zero_up_crossing_period(t, det.v, deadband_deg, max_period_s)
    tz_ = tz if nz >= MIN_CYCLES else None
    tp = det.spectral_period_s if np.isfinite(det.spectral_period_s) and nz >= MIN_CYCLES else None
    vals = {"peak-to-peak": p2p, "zero-up-crossing": tz_, "spectral peak": tp}
    known = [v for v in vals.values() if v is not None]
    spread = max(known) / min(known) - 1.0 if len(known) == 3 else None
    est = {
        "peak_to_peak_s": _r(p2p),
        "zero_up_crossing_s": _r(tz_),
        "spectral_peak_s": _r(tp),
        "same_side_periods": int(per.size),
        "zero_up_crossings": nz + 1 if nz else 0,
        "spread": None if spread is None else round(spread, 4),
        "disagree_frac": disagree_frac,
        "definitions": (
            "peak-to-peak: mean time between successive maxima on the same side (MSC.363(92) §3), both sides; "
            "zero-up-crossing: mean time between up-crossings of the mean heel; spectral peak: Welch PSD peak of "
            "heel − mean heel"
        ),
    }
    warns = []
    if spread is not None and spread > disagree_frac:
        txt = ", ".join(f"{k} {v:.2f} s" for k, v in vals.items())
        warns.append(
            f"roll period estimates disagree by {100 * spread:.0f} % (> {100 * disagree_frac:.0f} %): {txt}; the "
            "roll is broad-band or bimodal (swell and sea), too short or too noisy for one period"
        )
    return est, warns


def _r(x: float | None) -> float | None:
    return None if x is None else round(float(x), 4)
