"""The platform's motion, ship or hand-held, told from the gyro; it sets the accelerometer low-pass's delay.

A ship moves slowly and narrowly: roll, pitch and yaw at wave periods of 5–20 s, rates below ~20 °/s, almost all
of the rotation's power below 0.5 Hz. Its translations (sway, surge, heave) are at the same periods and no lever
arm removes them, so the low-pass must be long against the wave band (``ship_lp_tau``, 5 s: a sway at 6 s
attenuated 14×, at 10 s 5×) — and not longer, since the tilt it lags by is τ × the gyro bias's error (on the ship
grid τ 5 s gave 0.13–0.15° RMS with a receiver's smoothed track, τ 10 s 0.17–0.19°, τ 2.5 s 0.23–0.39°).
Hand-held and vehicle motion is broadband and fast: the hand-held low-pass (``accel_lp_tau``, 2.5 s), chosen on
the BROAD trials.

``auto`` (the default) calls a recording a ship when the 99th percentile of its rotation rate is below
``SHIP_MAX_RATE`` and at least ``SHIP_LOW_SHARE`` of its rotation's power (above 0.02 Hz) lies below
``SHIP_BAND_HZ``. On the shared data the two kinds sit far apart: the 16 BROAD trials 82–1074 °/s, low share
0.00–0.79; the ship simulations 4–19 °/s, low share 1.00. A still sensor is not a ship (no rotation to judge).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from formats.plausibility import PHYSICAL_LIMITS
from imutool.attitude.params import EkfParams

SHIP_MAX_RATE = 30.0  # deg/s, 99th percentile of the rotation rate
SHIP_LOW_SHARE = 0.9  # share of the rotation's power (above 0.02 Hz) below SHIP_BAND_HZ
SHIP_BAND_HZ = 0.5
MIN_RATE = 0.5  # deg/s: below this 99th percentile the sensor is still, not rolling
ANALYSIS_MAX_S = 600.0  # s: auto looks at the first ten minutes (30 roll periods; a stream holds that much back)
ANALYSIS_HZ = 10.0  # Hz: the gyro is averaged down to about this rate first (the band of interest is < 1 Hz)


@dataclass(frozen=True)
class MotionChoice:
    """What the motion model decided: ``kind`` ship or handheld, how (``asked`` auto/ship/handheld), the
    statistics auto used (rate p99 deg/s, low-frequency share, dominant period s; NaN where not measured) and the
    low-pass delay it gives (s)."""

    kind: str
    asked: str
    rate_p99_dps: float
    low_share: float
    period_s: float
    lp_tau_s: float

    def summary(self) -> dict[str, Any]:
        """The summary's and the output metadata's ``motion`` entry."""
        out: dict[str, Any] = {"kind": self.kind, "asked": self.asked, "accel_lp_tau_s": self.lp_tau_s}
        if np.isfinite(self.rate_p99_dps):
            out.update(
                rate_p99_dps=round(self.rate_p99_dps, 2),
                low_frequency_share=round(self.low_share, 3),
                dominant_period_s=round(self.period_s, 2) if np.isfinite(self.period_s) else None,
            )
        return out


def _usable(t: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Rows that are motion: finite, and within any gyro's range (beyond: corrupt; an in-memory run has bridged
    them, a stream's first chunks are judged before it does, so both leave them out and judge the same motion)."""
    return np.isfinite(g).all(axis=1) & np.isfinite(t) & (np.abs(g).max(axis=1, initial=0.0) < PHYSICAL_LIMITS["gyro"])


def _first_span(t: np.ndarray, g: np.ndarray, head: int = 10_000) -> tuple[np.ndarray, np.ndarray]:
    """The rows of ``t`` (s) and ``g`` up to ANALYSIS_MAX_S after the first usable one, where the times increase
    (views: a whole recording's later rows are not looked at); otherwise all of them."""
    if len(t) < 2 or not np.all(t[1:] > t[:-1]):  # (NaN fails too)
        return t, g
    ok = _usable(t[:head], g[:head])
    if not ok.any():
        return t, g
    end = int(np.searchsorted(t, t[int(np.argmax(ok))] + ANALYSIS_MAX_S, side="right"))
    return t[:end], g[:end]


def motion_statistics(time: np.ndarray, gyro: np.ndarray) -> tuple[float, float, float]:
    """(99th percentile of the rotation rate, deg/s; share of its power between 0.02 Hz and SHIP_BAND_HZ of that
    above 0.02 Hz; dominant period, s) of the first ANALYSIS_MAX_S of ``gyro`` (N,3) rad/s; NaN where too short."""
    t = np.asarray(time, dtype=np.float64)
    g = np.asarray(gyro, dtype=np.float64).reshape(len(t), 3)
    t, g = _first_span(t, g)
    ok = _usable(t, g)
    t, g = t[ok], g[ok]
    if len(t) < 16 or t[-1] - t[0] <= 0:
        return np.nan, np.nan, np.nan
    keep = t - t[0] <= ANALYSIS_MAX_S
    t, g = t[keep], g[keep]
    dt = float(np.median(np.diff(t)))
    step = max(1, int(round(1.0 / (ANALYSIS_HZ * dt)))) if dt > 0 else 1
    m = len(g) // step
    if m < 16:
        return np.nan, np.nan, np.nan
    gd = g[: m * step].reshape(m, step, 3).mean(axis=1)  # block means: rates at ~ANALYSIS_HZ
    rate = np.degrees(np.linalg.norm(gd - np.median(gd, axis=0), axis=1))
    p99 = float(np.percentile(rate, 99))
    x = gd - gd.mean(axis=0)
    power = (np.abs(np.fft.rfft(x, axis=0)) ** 2).sum(axis=1)
    freq = np.fft.rfftfreq(m, dt * step)
    above = freq > 0.02
    total = float(power[above].sum())
    if total <= 0:
        return p99, np.nan, np.nan
    low = float(power[above & (freq < SHIP_BAND_HZ)].sum()) / total
    period = 1.0 / float(freq[above][np.argmax(power[above])])
    return p99, low, period


def choose_motion(params: EkfParams, time: np.ndarray, gyro: np.ndarray) -> MotionChoice:
    """The motion of a recording (``params.motion``: ship and handheld as asked; auto from the gyro)."""
    p99, low, period = motion_statistics(time, gyro) if params.motion == "auto" else (np.nan, np.nan, np.nan)
    if params.motion == "auto":
        ship = bool(MIN_RATE <= p99 < SHIP_MAX_RATE and low >= SHIP_LOW_SHARE)
    else:
        ship = params.motion == "ship"
    tau = params.ship_lp_tau if ship else params.accel_lp_tau
    return MotionChoice("ship" if ship else "handheld", params.motion, p99, low, period, float(tau))


def params_for_motion(params: EkfParams, choice: MotionChoice) -> EkfParams:
    """The parameters the filter runs with: the low-pass delay of the chosen motion."""
    if choice.lp_tau_s == params.accel_lp_tau:
        return params
    return replace(params, accel_lp_tau=choice.lp_tau_s)
