"""Roll statistics per IMO MSC.363(92) annex §3: actual heel, roll period, roll amplitudes, peak hold.

Definitions (MSC.363(92) §3, standards.md P1): *actual heel angle* is the momentary roll angle of the ship
relative to level (deg, **+ starboard down**, − port, as in IEC 61162-1 HRM); *roll period* is the time between
two successive maxima of heel **on the same side**; *roll amplitude* is the maximum heel to port or to
starboard. *Peak hold* (IEC 61162-1 HRM notes, standards.md P7) is the largest port and starboard heel since the
last reset.

Method (documented in docs/report.md):

1. A Schmitt trigger with hysteresis ``h`` (deg) splits the **detection series** (heel − centre, smoothed over
   1/8 of the spectral peak period; :mod:`imutool.roll_period`) into alternating *excursions*: a starboard
   excursion starts when it rises above +h and ends when it falls below −h; a port excursion the other way round.
   The centre is the mean heel (a centred running mean over ``centre_window_s``, default 120 s) or 0 (a level
   ship, e.g. a motion table: ``centre='zero'``); h is scaled to the roll (0.1 × its running RMS, at least
   0.05°) unless a fixed ``hysteresis_deg`` is given. Oscillations smaller than ±h (noise, ripples on a crest)
   never switch the state, so a crest with two humps is one excursion, while every real roll cycle, small or
   biased by a list, is counted (a fixed ±0.5° about 0° counted two or three cycles of small or listed roll as
   one: periods ~2× too long, issue 48).
2. The extremum of each excursion is its largest |heel − centre| raw sample, refined by a least-squares
   parabola over ±``refine_frac`` × (excursion duration) around that sample, limited to the crest (contiguous
   samples within 30 % of the excursion depth of the extremum); with fewer than 5 such samples (a low rate), the
   parabola through the top 3 samples (sub-sample time, noise-averaged value).
3. Roll amplitude to a side = |refined extremum − centre| of that excursion (port amplitude reported positive, as
   HRM): **measured from the mean heel** by default (a ship listed 8° rolling ±5° has 5° to each side, not 13° and
   "3° to port"), from level with ``centre='zero'``; the signed heel of the extremum from level is kept as
   ``peak_deg``. Roll period of a side = time between the refined extrema of two consecutive excursions on that
   side (port and starboard are tracked separately); periods longer than ``max_period_s`` are discarded. The mean
   period is cross-checked against the zero-up-crossing and spectral peak periods (:mod:`imutool.roll_period`).
4. The first excursion is dropped when the recording starts inside it (its extremum may precede the start);
   the last one, still open at the end, is not reported.
5. Per-sample outputs are *causal*, as a device would display them: a cycle's values appear at the sample
   where its excursion ends (the crossing of the opposite threshold). Peak hold is the running maximum of the
   raw heel samples since the last reset (exact, no refinement; 0 on a side the ship has not heeled to).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from typing import Any

import numpy as np

from formats import Recording
from formats.errors import ImutoolError
from imutool.loading import merged_warnings
from imutool.roll_period import (  # noqa: F401  (running_mean, excursions: re-exported)
    Detection,
    detection,
    excursions,
    period_estimates,
    running_mean,
    typical,
)

STBD = 1
PORT = -1

ROLL_DEFAULTS: dict[str, Any] = {
    "hysteresis_deg": None,
    "centre": "running",
    "centre_window_s": 120.0,
    "refine_frac": 0.2,
    "max_period_s": 60.0,
    "hysteresis_frac": 0.1,
    "hysteresis_min_deg": 0.05,
    "smooth_frac": 0.125,
    "disagree_frac": 0.15,
}
"""The detector's settings (deg, s, fractions): the defaults of :func:`roll_cycles`, :func:`roll_stats` and
:func:`run_roll` (and of the ``imutool roll`` / ``imutool nmea`` options). ``hysteresis_deg`` None = scaled to the
roll (``hysteresis_frac`` × running RMS, at least ``hysteresis_min_deg``); ``centre`` 'running' = the mean heel over
``centre_window_s``; ``smooth_frac`` × the spectral peak period = the detection smoothing; ``disagree_frac``: the
spread of the three period estimates that raises a warning (:mod:`imutool.roll_period`)."""


@dataclass
class RollCycles:
    """One row per completed excursion (a half roll cycle), in time order.

    side: +1 starboard, −1 port. t_peak (s), peak_deg (signed heel at the extremum relative to level, deg),
    amplitude_deg (|peak − centre|, deg: measured from the mean heel with ``centre='running'``, from level with
    ``centre='zero'``), period_s (time since the previous extremum on the same side, NaN if none), t_start/t_end
    (s, threshold crossings bounding the excursion), i_end (sample index where the cycle becomes known).
    """

    side: np.ndarray
    t_peak: np.ndarray
    peak_deg: np.ndarray
    amplitude_deg: np.ndarray
    period_s: np.ndarray
    t_start: np.ndarray
    t_end: np.ndarray
    i_end: np.ndarray
    crest_s: np.ndarray | None = None  # s, crest width: time the heel stays within crest_band of the extremum

    def __len__(self) -> int:
        return int(self.side.shape[0])

    def of_side(self, side: int) -> RollCycles:
        m = self.side == side
        return RollCycles(
            *(None if getattr(self, f) is None else getattr(self, f)[m] for f in self.__dataclass_fields__)
        )

    def as_recording(self) -> Recording:
        """The per-cycle table as a Recording (time = t_peak) for writing with formats.write."""
        rec = Recording(
            self.t_peak.copy(),
            {
                "side": self.side.astype(float),
                "peak_heel": self.peak_deg,
                "amplitude": self.amplitude_deg,
                "period": self.period_s,
                "t_start": self.t_start,
                "t_end": self.t_end,
            },
            {"side": "1", "peak_heel": "deg", "amplitude": "deg", "period": "s", "t_start": "s", "t_end": "s"},
        )
        rec.meta["content"] = "roll cycles per MSC.363(92) §3: side +1 starboard / -1 port; time = time of the maximum"
        return rec


@dataclass
class RollStats:
    """Per-sample roll statistics (causal) plus the cycle table and the settings used."""

    time: np.ndarray
    heel: np.ndarray  # deg, + starboard
    roll_period: np.ndarray  # s, latest same-side period (side of the latest completed excursion)
    period_port: np.ndarray
    period_stbd: np.ndarray
    amp_port: np.ndarray  # deg, positive
    amp_stbd: np.ndarray  # deg
    peak_port: np.ndarray  # deg, positive, since last reset
    peak_stbd: np.ndarray
    reset_time: np.ndarray  # s, time of the last peak-hold reset
    valid: np.ndarray  # 1 when a period is known and the latest excursion ended < max_period_s ago
    cycles: RollCycles
    settings: dict[str, Any] = field(default_factory=dict)
    resets_utc: list[str | None] = field(default_factory=list)
    periods: dict[str, Any] = field(default_factory=dict)  # the three period estimates (imutool.roll_period)
    warnings: list[str] = field(default_factory=list)  # their disagreement

    def summary(self) -> dict[str, Any]:
        """Mean/max of periods and amplitudes per side (amplitudes from the centre: the mean heel by default),
        the mean heel, max heel to each side (from level), the period estimates side by side, counts, final peak
        hold, warnings."""
        out: dict[str, Any] = {"samples": int(self.time.size), "cycles": len(self.cycles)}
        out["period_mean_s"] = self.periods.get("peak_to_peak_s")  # the method's mean period (both sides)
        out["period_estimates"] = dict(self.periods)
        out["mean_heel_deg"] = self.settings.get("mean_heel_deg")
        out["amplitude_from"] = "mean heel" if self.settings.get("centre") == "running" else "level (0°)"
        for name, s in (("port", PORT), ("starboard", STBD)):
            c = self.cycles.of_side(s)
            per = typical(c.period_s, self.settings.get("max_period_s", D["max_period_s"]))
            out[name] = {
                "excursions": len(c),
                "periods": int(np.isfinite(c.period_s).sum()),
                "period_mean_s": float(per.mean()) if per.size else None,  # over the typical periods (≤ 3 × median)
                "amplitude_mean_deg": float(c.amplitude_deg.mean()) if len(c) else None,
                "amplitude_max_deg": float(c.amplitude_deg.max()) if len(c) else None,
                "heel_max_deg": float(np.max(s * c.peak_deg)) if len(c) else None,  # from level, + to this side
            }
        out["peak_hold_port_deg"] = _last_finite(self.peak_port)
        out["peak_hold_stbd_deg"] = _last_finite(self.peak_stbd)
        out["last_reset_utc"] = self.resets_utc[-1] if self.resets_utc else None
        out["warnings"] = list(self.warnings)
        return out

    def as_recording(self, meta: dict[str, Any] | None = None) -> Recording:
        """Per-sample columns: heel, roll_period, period_port/stbd, amp_port/stbd, peak_port/stbd, ..."""
        ch = {
            "heel": self.heel,
            "roll_period": self.roll_period,
            "period_port": self.period_port,
            "period_stbd": self.period_stbd,
            "amp_port": self.amp_port,
            "amp_stbd": self.amp_stbd,
            "peak_port": self.peak_port,
            "peak_stbd": self.peak_stbd,
            "peak_reset_time": self.reset_time,
            "roll_valid": self.valid.astype(float),
        }
        units = {
            "heel": "deg",
            "roll_period": "s",
            "period_port": "s",
            "period_stbd": "s",
            "amp_port": "deg",
            "amp_stbd": "deg",
            "peak_port": "deg",
            "peak_stbd": "deg",
            "peak_reset_time": "s",
            "roll_valid": "1",
        }
        rec = Recording(self.time.copy(), ch, units, dict(meta or {}))
        rec.meta["roll_stats"] = {
            **self.settings,
            "resets_utc": self.resets_utc,
            "convention": "heel + starboard down; amp_port/peak_port positive (HRM)",
            "period_estimates": self.periods,
        }
        if self.warnings:
            rec.meta["warnings"] = merged_warnings(rec.meta, list(self.warnings))
        return rec


def _last_finite(a: np.ndarray) -> float | None:
    ok = np.flatnonzero(np.isfinite(a))
    return float(a[ok[-1]]) if ok.size else None


def _refine(t: np.ndarray, x: np.ndarray, i0: int, i1: int, ie: int, side: int, frac: float) -> tuple[float, float]:
    """Least-squares parabola over ±frac·(t[i1]−t[i0]) around sample ie → (time, value) of the extremum."""
    w = frac * (t[i1] - t[i0])
    lo = int(np.searchsorted(t, t[ie] - w, side="left"))
    hi = int(np.searchsorted(t, t[ie] + w, side="right"))
    lo, hi = max(lo, i0), min(hi, i1)
    # ... and only the crest: contiguous samples within 30 % of the excursion depth of the extremum (a long
    # excursion with a sharp peak would otherwise bend a wide parabola off the peak)
    sx = side * x[i0:i1]
    top = side * x[ie] - 0.3 * (side * x[ie] - np.nanmin(sx))
    with np.errstate(invalid="ignore"):  # NaN is not in the crest (a comparison with NaN is False)
        left = side * x[lo:ie] >= top if ie > lo else np.zeros(0, bool)
        right = side * x[ie + 1 : hi] >= top if hi > ie + 1 else np.zeros(0, bool)
    out = np.flatnonzero(~left)
    a = lo + int(out[-1]) + 1 if out.size else min(lo, ie)
    out = np.flatnonzero(~right)
    b = ie + 1 + (int(out[0]) if out.size else right.size)
    lo, hi = a, b
    tt = t[lo:hi] - t[ie]
    xx = x[lo:hi]
    ok = np.isfinite(xx)
    tt, xx = tt[ok], xx[ok]
    if tt.size >= 5 and w > 0:
        s = tt / w
        a2, a1, a0 = np.polyfit(s, xx, 2)
        if a2 * side < 0:  # opens the right way
            sv = -a1 / (2 * a2)
            if abs(sv) <= 1.0:
                return float(t[ie] + sv * w), float(a0 + a1 * sv + a2 * sv * sv)
    elif i0 < ie < i1 - 1 and np.isfinite(x[ie - 1]) and np.isfinite(x[ie + 1]):
        # too few samples for the least-squares window (low rate): parabola through the 3 samples at the top
        tt = t[ie - 1 : ie + 2] - t[ie]
        a2, a1, a0 = np.polyfit(tt, x[ie - 1 : ie + 2], 2)
        if a2 * side < 0:
            tv = -a1 / (2 * a2)
            if tt[0] <= tv <= tt[2]:
                return float(t[ie] + tv), float(a0 + a1 * tv + a2 * tv * tv)
    return float(t[ie]), float(x[ie])


def _crest_width(t: np.ndarray, x: np.ndarray, i0: int, i1: int, ie: int, side: int, band: float) -> float:
    """Span (s) of the samples of the excursion [i0, i1) that come within ``band`` of its extremum x[ie].

    Contiguous or not: a flat crest, or a crest with two humps of nearly equal height, makes the time of the
    maximum ambiguous by about this much (noise, quantisation or a second unit may pick the other hump), so a
    period measured between two such maxima is not resolved better than that. At least one sample interval.
    """
    top = side * x[ie] - band
    seg = side * x[i0:i1]
    idx = np.flatnonzero(np.isfinite(seg) & (seg >= top)) + i0
    a, b = (int(idx[0]), int(idx[-1])) if idx.size else (ie, ie)
    lo = t[a] - 0.5 * (t[a] - t[a - 1]) if a > 0 else t[a]
    hi = t[b] + 0.5 * (t[b + 1] - t[b]) if b + 1 < t.size else t[b]
    return float(hi - lo)


D = ROLL_DEFAULTS

MOTION_TABLE: dict[str, Any] = {"centre": "zero", "smooth_frac": 0.0}
"""Settings for a motion table's programme (the inclinometer report, its simulated device): level is 0° (static
steps would move a mean heel) and no smoothing (one programme spans roll periods of 4–30 s, and the smoothing is
a fraction of the one spectral peak period of the window)."""


def detect(
    t: np.ndarray,
    heel_deg: np.ndarray,
    hysteresis_deg: float | None = D["hysteresis_deg"],
    centre: str = D["centre"],
    centre_window_s: float = D["centre_window_s"],
    max_period_s: float = D["max_period_s"],
    hysteresis_frac: float = D["hysteresis_frac"],
    hysteresis_min_deg: float = D["hysteresis_min_deg"],
    smooth_frac: float = D["smooth_frac"],
) -> Detection:
    """The checked detection series of a heel series (t s, heel deg + stbd): :func:`imutool.roll_period.detection`."""
    t = np.asarray(t, float)
    x = np.asarray(heel_deg, float)
    if t.shape != x.shape or t.ndim != 1:
        raise ImutoolError(f"roll: time and heel must be 1-D of equal length (got {t.shape}, {x.shape})")
    if hysteresis_deg is not None and not hysteresis_deg >= 0:
        raise ImutoolError(f"roll: hysteresis must be ≥ 0 deg or auto (got {hysteresis_deg})")
    if centre not in ("zero", "running"):
        raise ImutoolError(f"roll: centre must be 'zero' or 'running' (got {centre!r})")
    for name, val in (("centre window", centre_window_s), ("max period", max_period_s)):
        if not val > 0:
            raise ImutoolError(f"roll: {name} must be > 0 s (got {val})")
    for name, val in (("hysteresis fraction", hysteresis_frac), ("minimum hysteresis", hysteresis_min_deg)):
        if not val >= 0:
            raise ImutoolError(f"roll: {name} must be ≥ 0 (got {val})")
    if not 0 <= smooth_frac < 1:
        raise ImutoolError(f"roll: smoothing fraction must be in [0, 1) of the period (got {smooth_frac})")
    return detection(
        t, x, hysteresis_deg, centre, centre_window_s, max_period_s, hysteresis_frac, hysteresis_min_deg, smooth_frac
    )


def roll_cycles(
    t: np.ndarray,
    heel_deg: np.ndarray,
    hysteresis_deg: float | None = D["hysteresis_deg"],
    centre: str = D["centre"],
    centre_window_s: float = D["centre_window_s"],
    refine_frac: float = D["refine_frac"],
    max_period_s: float = D["max_period_s"],
    crest_band_deg: float = 0.1,
    *,
    hysteresis_frac: float = D["hysteresis_frac"],
    hysteresis_min_deg: float = D["hysteresis_min_deg"],
    smooth_frac: float = D["smooth_frac"],
    det: Detection | None = None,
) -> RollCycles:
    """Completed roll excursions of a heel series (t s, heel deg + stbd) per MSC.363(92) §3 (see module doc).

    Any window of samples works (no file knowledge): the centre, the smoothing and the scaled hysteresis come from
    the window itself (:mod:`imutool.roll_period`; minimum window there). crest_band_deg (deg): band below the
    extremum that defines each cycle's crest width ``crest_s`` (the ambiguity of the time of the maximum; used to
    refuse judging periods the data cannot resolve). det: a detection already made of the same samples.
    """
    t = np.asarray(t, float)
    x = np.asarray(heel_deg, float)
    if det is None:
        det = detect(
            t,
            x,
            hysteresis_deg,
            centre,
            centre_window_s,
            max_period_s,
            hysteresis_frac,
            hysteresis_min_deg,
            smooth_frac,
        )
    r = x - det.centre  # peaks are refined on the raw heel about the centre, not on the smoothed series
    side, i0, i1, ie, gen = excursions(np.ascontiguousarray(det.v), np.ascontiguousarray(det.h))
    keep = np.ones(side.size, bool)
    if side.size and gen[0] == 0:
        keep[0] = False
    side, i0, i1, ie = side[keep], i0[keep], i1[keep], ie[keep]
    n = side.size
    tp = np.empty(n)
    amp = np.empty(n)
    crest = np.empty(n)
    for k in range(n):
        a, b, e, sd = int(i0[k]), int(i1[k]), int(ie[k]), int(side[k])
        e = a + int(np.nanargmax(sd * r[a:b]))  # the raw extreme sample of the excursion
        tp[k], amp[k] = _refine(t, r, a, b, e, sd, refine_frac)
        crest[k] = _crest_width(t, r, a, b, e, sd, crest_band_deg)
    pk = amp + (np.interp(tp, t, det.centre) if n and np.any(det.centre != 0) else 0.0)
    period = np.full(n, np.nan)
    for s in (STBD, PORT):
        idx = np.flatnonzero(side == s)
        if idx.size > 1:
            d = np.diff(tp[idx])
            # consecutive same-side excursions must have exactly one opposite excursion between them
            consecutive = np.diff(idx) == 2
            period[idx[1:]] = np.where(consecutive & (d <= max_period_s), d, np.nan)
    return RollCycles(side.astype(np.int64), tp, pk, np.abs(amp), period, t[i0], t[i1], i1.astype(np.int64), crest)


def pair_cycles(ref: RollCycles, dut: RollCycles) -> np.ndarray:
    """For each reference excursion, the index of the DUT excursion it pairs with, or −1.

    Pairing by time overlap, one-to-one: reference excursion k and DUT excursion j pair when they are on the same
    side, their spans [t_start, t_end] overlap, and each is the only same-side excursion of the other that
    overlaps it. Irregular small roll makes one unit see a crossing the other does not (one long DUT excursion
    covering two reference excursions): such excursions pair with nothing, instead of with the wrong cycle.
    """
    out = np.full(len(ref), -1, np.int64)
    if len(ref) == 0 or len(dut) == 0:
        return out

    def overlaps(a: RollCycles, b: RollCycles) -> list[np.ndarray]:
        # b excursions whose span overlaps each a excursion (same side)
        lo = np.searchsorted(b.t_end, a.t_start, side="right")  # first b ending after a starts
        hi = np.searchsorted(b.t_start, a.t_end, side="left")  # b starting before a ends
        res = []
        for k in range(len(a)):
            idx = np.arange(lo[k], max(lo[k], hi[k]))
            res.append(idx[b.side[idx] == a.side[k]])
        return res

    r2d = overlaps(ref, dut)
    d2r = overlaps(dut, ref)
    for k, js in enumerate(r2d):
        if js.size == 1 and d2r[int(js[0])].size == 1 and int(d2r[int(js[0])][0]) == k:
            out[k] = int(js[0])
    return out


def _utc_of(t: float, utc_start: datetime | None) -> str | None:
    if utc_start is not None:
        return (utc_start + timedelta(seconds=float(t))).strftime("%Y-%m-%dT%H:%M:%S.%fZ")[:-4] + "Z"
    if t > 1e9:  # looks like Unix time already
        return datetime.fromtimestamp(float(t), tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")[:-4] + "Z"
    return None


def roll_stats(
    t: np.ndarray,
    heel_deg: np.ndarray,
    hysteresis_deg: float | None = D["hysteresis_deg"],
    centre: str = D["centre"],
    centre_window_s: float = D["centre_window_s"],
    refine_frac: float = D["refine_frac"],
    max_period_s: float = D["max_period_s"],
    resets_s: list[float] | tuple[float, ...] = (),
    utc_start: datetime | None = None,
    *,
    hysteresis_frac: float = D["hysteresis_frac"],
    hysteresis_min_deg: float = D["hysteresis_min_deg"],
    smooth_frac: float = D["smooth_frac"],
    disagree_frac: float = D["disagree_frac"],
) -> RollStats:
    """Per-sample MSC.363(92) roll statistics (causal), the cycle table and the period cross-check.

    t: s; heel_deg: deg, + starboard down; any window of samples (no file knowledge; minimum window in
    :mod:`imutool.roll_period`). resets_s: peak-hold reset times (s, same base as t); the recording start is always
    a reset. utc_start: UTC of t = 0 (for the reset time/date; Unix-epoch times are recognised without it). The
    detector's settings: :data:`ROLL_DEFAULTS`. ``periods`` of the result: the peak-to-peak (this method),
    zero-up-crossing and spectral peak periods side by side; ``warnings``: their disagreement (> disagree_frac).
    """
    t = np.asarray(t, float)
    x = np.asarray(heel_deg, float)
    det = detect(
        t, x, hysteresis_deg, centre, centre_window_s, max_period_s, hysteresis_frac, hysteresis_min_deg, smooth_frac
    )
    cyc = roll_cycles(t, x, refine_frac=refine_frac, max_period_s=max_period_s, det=det)
    periods, warns = period_estimates(cyc.period_s, t, det, hysteresis_min_deg, max_period_s, disagree_frac)
    n = t.size

    # causal step functions: value of the latest completed excursion at or before each sample
    def step(idx_sel: np.ndarray, values: np.ndarray) -> np.ndarray:
        out = np.full(n, np.nan)
        if idx_sel.size == 0:
            return out
        pos = np.searchsorted(cyc.i_end[idx_sel], np.arange(n), side="right") - 1
        has = pos >= 0
        out[has] = values[pos[has]]
        return out

    all_idx = np.arange(len(cyc))
    sp = np.flatnonzero(cyc.side == PORT)
    ss = np.flatnonzero(cyc.side == STBD)
    roll_period = step(all_idx, cyc.period_s[all_idx])
    period_port = step(sp, cyc.period_s[sp])
    period_stbd = step(ss, cyc.period_s[ss])
    amp_port = step(sp, cyc.amplitude_deg[sp])
    amp_stbd = step(ss, cyc.amplitude_deg[ss])
    last_end_t = step(all_idx, t[cyc.i_end])
    valid = np.isfinite(roll_period) & ((t - last_end_t) <= max_period_s)
    # peak hold since the last reset: running max of raw samples (NaN ignored)
    if n:
        resets = sorted({float(t[0])} | {float(r) for r in resets_s if t[0] <= r <= t[-1]})
    else:
        resets = []
    seg = np.searchsorted(np.asarray(resets), t, side="right") - 1 if n else np.zeros(0, int)
    peak_port = np.full(n, np.nan)
    peak_stbd = np.full(n, np.nan)
    reset_time = np.asarray(resets)[seg] if n else np.zeros(0)
    xs = np.where(np.isfinite(x), x, -np.inf)
    xp = np.where(np.isfinite(x), -x, -np.inf)
    for k in range(len(resets)):
        m = np.flatnonzero(seg == k)
        if m.size:
            a = np.maximum.accumulate(xs[m])
            b = np.maximum.accumulate(xp[m])
            # no heel to a side yet → 0 on that side (a heel that never went to port has no port peak)
            peak_stbd[m] = np.where(np.isfinite(a), np.maximum(a, 0.0), np.nan)
            peak_port[m] = np.where(np.isfinite(b), np.maximum(b, 0.0), np.nan)
    settings = {
        "hysteresis_deg": "auto" if hysteresis_deg is None else hysteresis_deg,
        "hysteresis_frac": hysteresis_frac,
        "hysteresis_min_deg": hysteresis_min_deg,
        "centre": centre,
        "centre_window_s": centre_window_s,
        "smooth_frac": smooth_frac,
        "refine_frac": refine_frac,
        "max_period_s": max_period_s,
        **det.settings,
        "definitions": (
            "MSC.363(92) annex §3: period between successive maxima on the same side; amplitude = |maximum − "
            + ("mean heel| (the running centre)" if centre == "running" else "0| (level ship)")
        ),
    }
    return RollStats(
        t,
        x,
        roll_period,
        period_port,
        period_stbd,
        amp_port,
        amp_stbd,
        peak_port,
        peak_stbd,
        reset_time,
        valid,
        cyc,
        settings,
        [_utc_of(r, utc_start) for r in resets],
        periods,
        warns,
    )


def heel_of(rec: Recording, path: str = "recording", channel: str | None = None) -> np.ndarray:
    """The heel series (deg, + starboard) of a recording: ``channel`` if given, else ``heel`` (HRM) or ``roll``."""
    if channel and channel not in rec.channels:
        raise ImutoolError(f"no channel {channel!r}; has {', '.join(rec.channels) or 'none'}", path=path)
    for name in (channel,) if channel else ("heel", "roll"):
        if name in rec.channels:
            a = rec.get(name, "deg") if rec.units.get(name) else rec[name]
            if a.ndim != 1:
                raise ImutoolError(f"channel {name!r} must be one column", path=path)
            return np.asarray(a, float)
    raise ImutoolError(
        f"needs a 'roll' or 'heel' channel (deg, + starboard down); has {', '.join(rec.channels) or 'none'}", path=path
    )
