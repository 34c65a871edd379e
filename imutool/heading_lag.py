"""How late an external heading (gyrocompass HDT/THS, channel ``heading_true``) is against the gyro.

A gyrocompass's heading is often 0.1–1 s late; at 3 °/s a 0.5 s delay is a 1.5° heading error. The filter can read
the feed that much later (``heading_input_latency``), but the user must know the delay. This module measures it
from the run itself: the gyro's heading ψ_g (the Euler heading rate ψ̇ = (sin φ ω_y + cos φ ω_z) / cos θ, ZYX,
ω the bias-corrected body rate in rad/s, integrated over time) against the feed h. For a trial lag L the
difference h(t) − ψ_g(t − L) is high-passed (a centred 30 s moving mean removed: the gyro's drift and the feed's
offset go) and its mean square is the cost; the lag is where the cost is least (grid of 0.05 s over −1…3 s,
refined by a parabola). A lag is only measurable where the heading moves (a turn, the ship's yaw): where the cost
never rises WARN_COST_RATIO above its least, or the least is at an end of the grid, no lag is reported.
"""

from __future__ import annotations

import numpy as np

from formats.frames import quat_to_euler

LAG_GRID_S = np.round(np.arange(-1.0, 3.0 + 1e-9, 0.05), 2)  # trial lags (s)
HIGH_PASS_S = 30.0  # the moving mean removed from the difference (s)
STEP_S = 0.25  # the difference is evaluated on a grid this fine (s)
MIN_SPAN_S = 60.0  # fewer seconds of feed than this: no measurement
WARN_LAG_S = 0.2  # a measured lag this far from the configured latency is said ...
WARN_COST_RATIO = 1.25  # ... when the configured latency's cost is this many times the least (a mean square of
# ~300 independent 1 Hz fixes has a relative standard error of √(2/300) ≈ 8 %: 25 % is ≈ 3σ)


def _moving_mean(x: np.ndarray, ok: np.ndarray, width: int) -> np.ndarray:
    """Centred moving mean of x over ``width`` samples, counting only ``ok`` samples (NaN where none)."""
    k = np.ones(width)
    s = np.convolve(np.where(ok, x, 0.0), k, mode="same")
    c = np.convolve(ok.astype(float), k, mode="same")
    with np.errstate(invalid="ignore", divide="ignore"):
        return s / c


class HeadingLagTrack:
    """What the lag measurement keeps of a run, fed chunk by chunk (in memory: one chunk; streamed: each chunk as
    it is filtered): the gyro's heading ψ_g (deg, from 0 at the first sample; ψ̇ = (sin φ ω_y + cos φ ω_z) / cos θ
    in rad/s, ω = gyro − bias, body; φ, θ from q body→NED) integrated by trapezoids at the full rate across
    chunks, and the feed (deg, NaN: none) — both kept at the first sample of every ``keep_s`` s and the last one:
    a day at 200 Hz is held at 20 Hz."""

    def __init__(self, keep_s: float = 0.05, block: int = 1 << 20) -> None:
        self.keep_s, self.block = keep_s, block
        self.psi = 0.0  # ψ_g at the last sample seen (rad)
        self.last: tuple[float, float] | None = None  # (time s, ψ̇ rad/s) of the last sample seen
        self.bin = -np.inf  # the keep_s bin of the last sample kept
        self.t: list[np.ndarray] = []
        self.psi_g: list[np.ndarray] = []
        self.feed: list[np.ndarray] = []
        self.tail: tuple[float, float, float] | None = None  # (time, ψ_g, feed) of the last sample seen

    def add(self, time: np.ndarray, heading_deg: np.ndarray, q: np.ndarray, gyro: np.ndarray, bias: np.ndarray) -> None:
        """One chunk, in time order after the previous: time (N,) s, heading_deg (N,) the feed on the IMU time,
        q (N,4) the filter's attitude, gyro and bias (N,3) rad/s body."""
        for i0 in range(0, len(time), self.block):
            sl = slice(i0, min(len(time), i0 + self.block))
            t = np.asarray(time[sl], float)
            roll, pitch, _ = quat_to_euler(q[sl])
            w = np.asarray(gyro[sl], float) - np.asarray(bias[sl], float)
            rate = (np.sin(roll) * w[:, 1] + np.cos(roll) * w[:, 2]) / np.maximum(np.cos(pitch), 1e-6)
            rate = np.where(np.isfinite(rate), rate, 0.0)
            tb = t if self.last is None else np.concatenate([[self.last[0]], t])
            rb = rate if self.last is None else np.concatenate([[self.last[1]], rate])
            ps = self.psi + np.concatenate([[0.0], np.cumsum(0.5 * (rb[1:] + rb[:-1]) * np.diff(tb))])
            ps = ps if self.last is None else ps[1:]
            bins = np.floor(t / self.keep_s)
            keep = np.flatnonzero(bins > np.maximum.accumulate(np.concatenate([[self.bin], bins[:-1]])))
            h = np.asarray(heading_deg[sl], float)
            self.t.append(t[keep])
            self.psi_g.append(ps[keep])
            self.feed.append(h[keep])
            if len(t):
                self.bin = max(self.bin, float(bins.max()))
                self.psi, self.last = float(ps[-1]), (float(t[-1]), float(rate[-1]))
                self.tail = (float(t[-1]), float(ps[-1]), float(h[-1]))

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(times s, ψ_g deg, feed deg) kept, the last sample seen included."""
        t, psi, feed = (np.concatenate(x) if x else np.empty(0) for x in (self.t, self.psi_g, self.feed))
        if self.tail is not None and (len(t) == 0 or t[-1] != self.tail[0]):
            t, psi, feed = (np.append(a, v) for a, v in zip((t, psi, feed), self.tail, strict=True))
        return t, np.degrees(psi), feed

    def measure(self) -> dict | None:
        """:func:`measure_heading_lag` of what was added."""
        t, psi_g, h = self.arrays()
        return _measure(t, psi_g, h)


def measure_heading_lag(
    time: np.ndarray, heading_deg: np.ndarray, q: np.ndarray, gyro: np.ndarray, bias: np.ndarray
) -> dict | None:
    """The external heading's lag behind the gyro (s; positive: the feed is late), or None where the run cannot
    tell (under a minute of feed). time (N,) s; heading_deg (N,) the feed on the IMU time (deg, NaN: none);
    q (N,4) the filter's attitude body→NED; gyro, bias (N,3) rad/s body.

    Returns ``lag_s`` (the least-cost lag), ``cost_deg2`` (the high-passed mean square at that lag, deg²), ``resolved``
    (False where the least cost is at an end of LAG_GRID_S or the cost over the whole grid stays within
    WARN_COST_RATIO of the least: the run cannot tell the lag, and ``lag_s`` is then not a measurement) and the
    function ``cost_at(L)`` for a given latency (deg²)."""
    track = HeadingLagTrack()
    track.add(time, heading_deg, q, gyro, bias)
    return track.measure()


def _measure(t: np.ndarray, psi_g: np.ndarray, h: np.ndarray) -> dict | None:
    """The lag from the gyro's heading ``psi_g`` and the feed ``h`` (deg, NaN: none) at times ``t`` (s)."""
    ok = np.isfinite(h) & np.isfinite(t)
    if ok.sum() < 2 or t[ok][-1] - t[ok][0] < MIN_SPAN_S:
        return None
    grid = np.arange(t[ok][0], t[ok][-1], STEP_S)
    hg = np.interp(grid, t[ok], np.degrees(np.unwrap(np.radians(h[ok]))))
    near = np.interp(grid, t, ok.astype(float)) >= 1.0 - 1e-12  # the feed was there (not inside a gap)
    width = max(3, int(round(HIGH_PASS_S / STEP_S)) | 1)

    def cost_at(lag: float) -> float:
        d = hg - np.interp(grid - lag, t, psi_g, left=np.nan, right=np.nan)  # no gyro heading held past the ends
        have = near & np.isfinite(d)
        hp = d - _moving_mean(d, have, width)
        use = have & np.isfinite(hp)
        return float(np.mean(hp[use] ** 2)) if use.any() else np.nan

    costs = np.array([cost_at(lag) for lag in LAG_GRID_S])
    if not np.any(np.isfinite(costs)):
        return None
    i = int(np.nanargmin(costs))
    lag = float(LAG_GRID_S[i])
    at_edge = not 0 < i < len(LAG_GRID_S) - 1
    resolved = bool(not at_edge and np.nanmax(costs) >= WARN_COST_RATIO * costs[i])
    if not at_edge:  # parabola through the three points around the least cost
        c0, c1, c2 = costs[i - 1], costs[i], costs[i + 1]
        step = LAG_GRID_S[1] - LAG_GRID_S[0]
        den = c0 - 2 * c1 + c2
        if den > 0:
            lag += 0.5 * step * (c0 - c2) / den
    return {
        "lag_s": round(float(lag), 2),
        "cost_deg2": float(costs[i]),
        "resolved": resolved,
        "at_edge": at_edge,
        "cost_at": cost_at,
    }


def heading_lag_check(measured: dict | None, latency_s: float) -> tuple[dict, list[str]]:
    """Summary entries (``heading_input_lag_s``, the lag measured) and one warning where the measured lag is
    ≥ WARN_LAG_S from the configured ``latency_s`` (s) and the data tell the two apart (the configured latency's
    cost ≥ WARN_COST_RATIO × the least)."""
    if measured is None:
        return {"heading_input_lag_s": None}, []  # under a minute of feed
    if not measured.get("resolved", True):  # the heading never moved enough, or the lag is off the grid
        if (
            measured.get("at_edge")
            and abs(measured["lag_s"] - latency_s) >= WARN_LAG_S
            and measured["cost_at"](latency_s) >= WARN_COST_RATIO * measured["cost_deg2"]
        ):
            return {"heading_input_lag_s": None}, [
                f"the external heading (heading_true) is off from the gyro by {measured['lag_s']:+.2f} s or more "
                f"(the end of the lags tried, {LAG_GRID_S[0]:g}…{LAG_GRID_S[-1]:g} s; heading_input_latency is "
                f"{latency_s:g} s): check the heading feed's clock against the IMU's"
            ]
        return {"heading_input_lag_s": None}, []
    out = {"heading_input_lag_s": measured["lag_s"]}
    lag = measured["lag_s"]
    if abs(lag - latency_s) < WARN_LAG_S:
        return out, []
    if measured["cost_at"](latency_s) < WARN_COST_RATIO * measured["cost_deg2"]:
        return out, []  # the run's heading hardly moved: it cannot tell the two apart
    if lag < 0:  # a feed ahead of the gyro is a clock offset, not a latency the parameter can take
        return out, [
            f"the external heading (heading_true) leads the gyro by about {-lag:.2f} s, measured in this "
            f"run (heading_input_latency is {latency_s:g} s): its time stamps are early against the IMU's "
            "(a clock offset); align the clocks, heading_input_latency cannot be negative"
        ]
    return out, [
        f"the external heading (heading_true) lags the gyro by about {lag:.2f} s, measured in this run "
        f"(heading_input_latency is {latency_s:g} s): through a turn that is a heading error of "
        f"{abs(lag - latency_s):.2f} s × the turn rate; set --param heading_input_latency={lag:.2f} "
        "if the gyrocompass's delay is that"
    ]
