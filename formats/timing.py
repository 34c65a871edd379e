"""The timing of one stream of samples: its true rate, whether it arrives in bursts, and its gaps.

A stream's rate is what it delivers: samples over time, (n − 1) / span. Its median step is that rate's inverse
for a steady stream, but not for one logged in bursts (a 77 Hz magnetometer read out 4 samples at a time, 3 ms
apart, every 52 ms: median step 3 ms, "304 Hz"), nor for one sentence type among others (a 1 Hz HDT whose rows sit
between 10 Hz rows of other sentences). :func:`stream_timing` looks at one stream's own sample times:

- **steady** (the median step is at least half the mean step): nominal step = the median step; a gap is a step
  longer than ``gap_factor`` × that.
- **bursty** (the median step is under half the mean step): samples are grouped into bursts (a step longer than
  the geometric mean of the median and the mean step starts a new burst); the burst period is the median time
  between burst starts; a gap is a time between burst starts longer than ``gap_factor`` × the burst period.
- never shorter than ``min_gap_s`` (the resolution of times that are estimates).

Times in s; rates in Hz. Used by the NMEA reader (per sentence type, ``meta['sentence_timing']``) and by
``imutool info`` (per channel with samples of its own).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

GAP_FACTOR = 3.0  # a step longer than this many nominal steps (or burst periods) is a gap (as Recording.validated)


def _r(v: float, nd: int = 6) -> float | None:
    return round(float(v), nd) if math.isfinite(v) else None


def stream_timing(
    t: np.ndarray, gap_factor: float = GAP_FACTOR, max_gaps: int = 5, min_gap_s: float = 0.0
) -> dict[str, Any]:
    """Rate, burst pattern and gaps of one stream's sample times ``t`` (s, non-decreasing; NaN dropped).

    ``min_gap_s``: no step shorter than this is a gap — for times known only to that resolution (an NMEA
    sentence without a time field, placed by its position between fixes 1 s apart, is a gap only beyond 2 s).

    Returns ``count``, ``span_s``, ``rate_hz`` ((count − 1)/span), ``step_s`` (nominal step: median step of a
    steady stream, burst period / samples per burst of a bursty one), ``bursty`` and, when bursty,
    ``burst`` (``samples`` median per burst, ``period_s``, ``step_within_s``), ``gaps`` (count), ``missing_s``
    (time beyond the nominal spacing inside the gaps) and ``first_gaps`` [(start s, length s)].
    """
    t = np.asarray(t, dtype=float)
    t = t[np.isfinite(t)]
    n = len(t)
    out: dict[str, Any] = {"count": int(n)}
    if n < 2:
        return {**out, "span_s": 0.0, "rate_hz": None, "step_s": None, "bursty": False, "gaps": 0, "missing_s": 0.0}
    d = np.diff(t)
    span = float(t[-1] - t[0])
    out["span_s"] = _r(span)
    if span <= 0:
        return {**out, "rate_hz": None, "step_s": None, "bursty": False, "gaps": 0, "missing_s": 0.0}
    mean_dt = span / (n - 1)
    med = float(np.median(d))
    out["rate_hz"] = _r(1.0 / mean_dt)
    bursty = n >= 8 and med < 0.5 * mean_dt
    out["bursty"] = bool(bursty)
    if bursty:
        split = math.sqrt(max(med, 1e-9 * mean_dt) * mean_dt)
        starts = np.concatenate([[0], np.flatnonzero(d > split) + 1])
        sizes = np.diff(np.concatenate([starts, [n]]))
        ts = t[starts]
        period = float(np.median(np.diff(ts))) if len(ts) > 1 else span
        within = d[d <= split]
        out["burst"] = {
            "samples": float(np.median(sizes)),
            "period_s": _r(period),
            "step_within_s": _r(float(np.median(within))) if within.size else None,
        }
        out["step_s"] = _r(mean_dt)
        steps, at, nominal = np.diff(ts), ts[:-1], period
    else:
        out["step_s"] = _r(med)
        steps, at, nominal = d, t[:-1], med
    limit = max(gap_factor * nominal, min_gap_s)
    out["gap_longer_than_s"] = _r(limit)
    gi = np.flatnonzero(steps > limit) if nominal > 0 else np.empty(0, int)
    out["gaps"] = int(len(gi))
    out["missing_s"] = _r(float(np.sum(steps[gi]) - len(gi) * nominal)) or 0.0
    out["first_gaps"] = [(_r(float(at[i])), _r(float(steps[i]))) for i in gi[:max_gaps]]
    return out


def describe(tm: dict[str, Any]) -> str:
    """One line for a person: ``10 Hz, 600 samples in 59.9 s, 0 gaps`` / ``77 Hz in bursts of 4 every 0.052 s``."""
    if not tm.get("rate_hz"):
        return f"{tm.get('count', 0)} sample(s), no rate"
    s = f"{tm['rate_hz']:.4g} Hz"
    if tm.get("bursty"):
        b = tm["burst"]
        s += f" in bursts of {b['samples']:g} every {b['period_s']:.3g} s"
    s += f", {tm['count']} samples in {tm['span_s']:.6g} s, {tm['gaps']} gap" + ("" if tm["gaps"] == 1 else "s")
    if tm["gaps"]:
        s += f" (≈{tm['missing_s']:.3g} s missing)"
    return s
