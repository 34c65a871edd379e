"""Heave from a GNSS height: an RTK receiver's antenna height, detrended — where no accelerometer exists, and as
a reference for the heave from acceleration.

An RTK fix (GGA quality 4, or 5 float) gives the antenna's height to 1–3 cm; a ship's heave is its wave-band part.
What is not heave (tide, squat, loading, the receiver's slow height wander, the datum) changes over minutes to
hours and is removed as a trend:

1. **Fix quality.** Rows whose ``gnss_fix_quality`` is not accepted (``fix``: ``rtk`` = 4 fixed and 5 float, the
   default; ``fixed`` = 4 only; ``any`` = every fix but 0) are excluded: no heave there, and they do not enter
   the trend. Without a quality channel every height is used (said in the summary).
2. **Lever arm.** With the roll and pitch of the recording (channels ``roll``/``pitch`` in degrees, or ``q``),
   the antenna's height becomes the monitoring point's: h_p = h_a − (R·l)_down with l the monitoring point
   relative to the antenna (m, body FRD; a mast 12 m above the point: l = (0, 0, 12)) and
   (R·l)_down = −sin θ·l_x + sin φ cos θ·l_y + cos φ cos θ·l_z. Roll and pitch are interpolated onto the height's
   own times from their own samples (they may arrive in other sentences).
3. **Detrend.** The trend at each sample is a local straight line fitted over a centred window of ``window_s``
   seconds with tent weights (1 at the sample, 0 at ±window/2): a zero-phase high-pass that passes a linear trend
   exactly. For uniform samples in the middle of the record its response is 1 − sinc²(f·W/2), so a wave of period
   T loses at most (T/(π·W/2))² of its amplitude to the trend: 0.4 % at W = 10 T. Default window: 10 × the
   dominant period of a first pass (with 60 s), at least 60 s and at most 600 s. Samples closer than window/2 to
   either end of the record (or of a gap longer than the window) have a one-sided window: ``settled`` = 0 there.

heave = h_p − trend (m, + up). The output is offline (a centred window: latency window/2). Times in s.
"""

from __future__ import annotations

from typing import Any

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats import Recording
from formats.errors import ImutoolError
from formats.jit.decorators import njit
from formats.timing import stream_timing
from imutool.metrics import interp_to

DEFAULT_WINDOW_S = 60.0  # s: the first pass, and the least window
WINDOW_PERIODS = 10.0  # the default window in dominant wave periods
MAX_WINDOW_S = 600.0  # s
FIX_FILTERS: dict[str, tuple[int, ...]] = {"rtk": (4, 5), "fixed": (4,), "any": (1, 2, 3, 4, 5, 6, 7, 8)}
GGA_QUALITY = {
    0: "no fix",
    1: "GNSS",
    2: "DGNSS",
    3: "PPS",
    4: "RTK fixed",
    5: "RTK float",
    6: "dead reckoning",
    7: "manual",
    8: "simulator",
}


@njit(cache=True)
def _tent_trend(t, h, half):  # pragma: no cover - numba
    """Local linear fit with tent weights over [t_i − half, t_i + half] at every sample: (trend, coverage), the
    coverage being the fraction of the window's weight that has samples on both sides (1 inside the record)."""
    n = t.shape[0]
    trend = np.full(n, np.nan)
    cover = np.zeros(n)
    lo = 0
    hi = 0
    for i in range(n):
        while t[lo] < t[i] - half:
            lo += 1
        while hi + 1 < n and t[hi + 1] <= t[i] + half:
            hi += 1
        s0 = s1 = s2 = y0 = y1 = 0.0
        for j in range(lo, hi + 1):
            x = t[j] - t[i]
            w = 1.0 - abs(x) / half
            if w <= 0.0:
                continue
            s0 += w
            s1 += w * x
            s2 += w * x * x
            y0 += w * h[j]
            y1 += w * x * h[j]
        det = s0 * s2 - s1 * s1
        if s0 > 0.0 and det > 1e-12 * s0 * s0 * half * half:
            trend[i] = (s2 * y0 - s1 * y1) / det
        elif s0 > 0.0:
            trend[i] = y0 / s0
        left = min(half, t[i] - t[lo])
        right = min(half, t[hi] - t[i])
        cover[i] = min(left, right) / half
    return trend, cover


def detrend_height(t: np.ndarray, h: np.ndarray, window_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(heave m, settled flag) of heights ``h`` (m) at times ``t`` (s, increasing, finite): h − the tent-weighted
    local linear trend over a centred window of ``window_s`` s. ``settled`` is 1 where the window has samples
    out to (nearly) both its ends: 0 within window/2 of the record's ends or of a gap."""
    if not (window_s > 0 and np.isfinite(window_s)):
        raise ImutoolError(f"height window must be a positive number of seconds, not {window_s!r}")
    t = np.ascontiguousarray(t, dtype=float)
    h = np.ascontiguousarray(h, dtype=float)
    if len(t) < 3:
        raise ImutoolError(f"heave from GNSS height needs at least 3 usable heights, has {len(t)}")
    trend, cover = _tent_trend(t, h, 0.5 * float(window_s))
    step = float(np.median(np.diff(t)))
    settled = (cover >= 1.0 - 2.0 * step / (0.5 * window_s)).astype(float)
    return h - trend, settled


def dominant_period(t: np.ndarray, x: np.ndarray, fmin: float = 1.0 / 30.0, fmax: float = 1.0) -> float | None:
    """The period (s) of the highest peak of the spectrum of ``x`` (detrended heights) between ``fmin`` and
    ``fmax`` Hz (and below the Nyquist of the median step), or None when there is no clear one."""
    if len(t) < 16:
        return None
    step = float(np.median(np.diff(t)))
    grid = np.arange(t[0], t[-1], step)
    if len(grid) < 16:
        return None
    y = np.interp(grid, t, x)
    y = (y - y.mean()) * np.hanning(len(y))
    f = np.fft.rfftfreq(len(y), step)
    p = np.abs(np.fft.rfft(y)) ** 2
    band = (f >= fmin) & (f <= min(fmax, 0.45 / step))
    if not band.any() or p[band].max() <= 0:
        return None
    return float(1.0 / f[band][np.argmax(p[band])])


def _attitude_at(rec: Recording, t: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Roll and pitch (rad) at times ``t`` from the recording's roll/pitch (deg) or q, each from its own samples."""
    if "roll" in rec.channels and "pitch" in rec.channels:
        r = np.radians(np.asarray(rec.get("roll", "deg"), float))
        p = np.radians(np.asarray(rec.get("pitch", "deg"), float))
        return interp_to(t, rec.time, r), interp_to(t, rec.time, p)
    if "q" in rec.channels and np.ndim(rec["q"]) == 2:
        q = interp_to(t, rec.time, np.asarray(rec["q"], float))
        w, x, y, z = q.T
        roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
        pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
        return roll, pitch
    return None


def lever_arm_down(roll: np.ndarray, pitch: np.ndarray, lever: np.ndarray) -> np.ndarray:
    """(R·l)_down (m): the NED down component of the body vector ``lever`` (FRD, m) at roll/pitch (rad)."""
    lx, ly, lz = (float(v) for v in np.asarray(lever, float).reshape(3))
    return -np.sin(pitch) * lx + np.sin(roll) * np.cos(pitch) * ly + np.cos(roll) * np.cos(pitch) * lz


def height_heave(
    rec: Recording,
    window_s: float | None = None,
    fix: str = "rtk",
    lever_arm: Any = None,
) -> tuple[Recording, dict[str, Any]]:
    """Heave (m, + up) from the ``gnss_height`` channel of ``rec`` (see the module docstring): ``window_s``
    (None: 10 dominant periods, 60–600 s), ``fix`` (:data:`FIX_FILTERS`), ``lever_arm`` (monitoring point relative
    to the antenna, m body FRD; applied with the recording's roll/pitch). Returns the recording on the heights' own
    times — heave, settled, gnss_height, gnss_fix_quality (when present), ref_heave (when the input has one) —
    and a summary."""
    if "gnss_height" not in rec.channels:
        raise ImutoolError(
            f"no gnss_height channel (GGA, PTNL,GGK/PJK) for a height heave; has {', '.join(rec.channels) or 'none'}",
            path=str(rec.meta.get("source") or "") or None,
        )
    if fix not in FIX_FILTERS:
        raise ImutoolError(f"GNSS fix filter {fix!r}: expected one of {', '.join(FIX_FILTERS)}")
    h_all = np.asarray(rec.get("gnss_height", "m"), float)
    rows = np.flatnonzero(np.isfinite(h_all))
    t = rec.time[rows]
    h = h_all[rows]
    summary: dict[str, Any] = {"heave_method": "gnss_height", "heights": int(len(rows))}
    warnings: list[str] = []
    quality = None
    if "gnss_fix_quality" in rec.channels:
        quality = np.asarray(rec["gnss_fix_quality"], float)[rows]
        ok = np.isin(quality, FIX_FILTERS[fix])
        seen = {
            GGA_QUALITY.get(int(q), str(int(q))): int(n)
            for q, n in zip(*np.unique(quality[np.isfinite(quality)], return_counts=True), strict=True)
        }
        summary["fix_quality"] = seen
        summary["fix_filter"] = f"{fix}: quality {', '.join(str(q) for q in FIX_FILTERS[fix])} used"
    else:
        ok = np.ones(len(rows), bool)
        warnings.append("no gnss_fix_quality channel: every height used (fix quality not checked)")
        summary["fix_filter"] = "none (no fix quality)"
    summary["excluded_fix_quality"] = int((~ok).sum())
    if ok.sum() < 3:
        raise ImutoolError(
            f"heave from GNSS height: {int(ok.sum())} of {len(rows)} heights have an accepted fix ({fix}); "
            "use fix='any' (--gnss-fix any) to take lower-quality fixes",
            path=str(rec.meta.get("source") or "") or None,
        )
    hp = h.copy()
    if lever_arm is not None:
        lever = np.asarray(lever_arm, float).reshape(-1)
        if lever.shape != (3,):
            raise ImutoolError("GNSS lever arm: three numbers x,y,z (m, body FRD)")
        att = _attitude_at(rec, t)
        if att is None:
            warnings.append(
                "GNSS lever arm not applied: the recording has no roll/pitch (or q) to rotate it with; the heave is "
                "the antenna's"
            )
            summary["lever_arm"] = "not applied (no attitude)"
        else:
            down = lever_arm_down(att[0], att[1], lever)
            missing = ~np.isfinite(down)
            if missing.any():
                ok &= ~missing
                warnings.append(f"{int(missing.sum())} heights without roll/pitch at their time: excluded")
            hp = h - np.nan_to_num(down)
            summary["lever_arm"] = {"m_body_frd": lever.tolist(), "meaning": "monitoring point relative to antenna"}
    tu, hu = t[ok], hp[ok]
    if window_s is None:
        first, _ = detrend_height(tu, hu, DEFAULT_WINDOW_S)
        period = dominant_period(tu, first)
        window = (
            DEFAULT_WINDOW_S if period is None else min(MAX_WINDOW_S, max(DEFAULT_WINDOW_S, WINDOW_PERIODS * period))
        )
        summary["window_rule"] = f"{WINDOW_PERIODS:g} × dominant period, {DEFAULT_WINDOW_S:g}–{MAX_WINDOW_S:g} s"
    else:
        window = float(window_s)
        summary["window_rule"] = "given"
    heave_u, settled_u = detrend_height(tu, hu, window)
    heave = np.full(len(rows), np.nan)
    settled = np.zeros(len(rows))
    heave[ok] = heave_u
    settled[ok] = settled_u
    period = dominant_period(tu[settled_u > 0], heave_u[settled_u > 0]) if settled_u.sum() >= 16 else None
    out = Recording(t.copy())
    out.add("heave", heave, "m")
    out.add("settled", settled, "1")
    out.add("gnss_height", h, "m")
    if quality is not None:
        out.add("gnss_fix_quality", quality, "1")
    if "ref_heave" in rec.channels:
        out.add("ref_heave", interp_to(t, rec.time, np.asarray(rec.get("ref_heave", "m"), float)), "m")
    tm = stream_timing(t)
    summary.update(
        {
            "window_s": round(window, 3),
            "latency_s": round(window / 2, 3),
            "dominant_period_s": None if period is None else round(period, 3),
            "rate_hz": tm["rate_hz"],
            "settled_rows": int(settled.sum()),
            "heave_std_m": float(np.nanstd(heave[settled > 0])) if settled.any() else None,
            "height_datum": (rec.meta.get("gnss_height") or {}).get("datum", "as in the input"),
        }
    )
    if warnings:
        summary["warnings"] = warnings
    out.meta.update(
        {
            "heave": f"m, positive UP, from gnss_height detrended over a centred {window:.4g} s window (offline, "
            f"latency {window / 2:.4g} s)",
            "heave_method": "gnss_height",
            "heave_source": "GNSS height (no accelerometer)",
            "source": rec.meta.get("source", ""),
        }
    )
    if rec.meta.get("gnss_height"):
        out.meta["gnss_height"] = rec.meta["gnss_height"]
    return out, summary


def reference_heave(ref: Recording, t: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, str]:
    """The height heave of ``ref`` as a reference: (times s, heave m with NaN where unsettled or excluded,
    description), with the defaults of :func:`height_heave`."""
    out, s = height_heave(ref)
    hv = np.where(out["settled"] > 0, out["heave"], np.nan)
    return out.time, hv, f"gnss_height detrended over {s['window_s']:g} s ({s['fix_filter']})"
