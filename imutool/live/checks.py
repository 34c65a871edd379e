"""Self-checks of the live status, each evaluated causally over its own trailing window of input time.

The batch self-checks of ``filter`` (:mod:`imutool.attitude.selfcheck`) judge a whole run once it is over; a live
status needs to know *now*. Each check here looks only at the samples up to now, over its own window, and sets a
cause of V while it fails; a cause clears only after the check has passed for ``clear_s`` (hysteresis: no A/V
flicker at the edge). The engine hands each block to :meth:`LiveChecks.add` and the causes to the status.

- **gyro scale** (:class:`imutool.gyro_check.GyroScaleCheck`, the batch check's physics and thresholds): the
  window-pair discrepancy sums of each ``SCALE_BUCKET_S`` of samples, added over the last ``SCALE_WINDOW_S``; V when
  the gyro's best factor lies beyond 1.3 (or a reversed axis is the best candidate) **and** rescaling removes
  ≥ 1.5° RMS of tilt discrepancy: a gyro in the wrong range or unit, a reversed axis, or an acceleration the
  filter was not told of (a lever arm not given) — the tilt is wrong then whatever the filter's σ says;
- **stuck input**: a gyro or accelerometer axis whose value has not changed by a single bit for ``STUCK_S`` and
  ``STUCK_MIN_SAMPLES`` samples: a MEMS axis always has noise, so a held value is a frozen register, a broken
  axis or a converter that stopped (a whole frozen sensor is all six axes);
- **accelerometer far from g**: the mean magnitude of the specific force over ``ACCEL_WINDOW_S`` outside
  ``ACCEL_BAND`` × g (units wrong — off by 9.81 or 1000 —, an axis lost, or motion so violent that no tilt can be
  read from gravity: a ship's accelerations average out over seconds; BROAD's hand-shaken trials reach 1.5 g, its
  fast translation 3 g);
- saturation and the filter's own consistency flag stay where they were (:mod:`.status`, per block).

Not evaluated live, and why: the heading lag (it needs minutes of turning against a heading feed, and it changes
no roll/pitch: the heading sentences carry it as a delay); turns without a speed input (their roll error is speed ×
rate of turn, and the speed is what is missing: a course change is not a fault).
"""

from __future__ import annotations

from collections import deque

import numpy as np

from imutool.gyro_check import GyroScaleCheck

SCALE_BUCKET_S = 10.0  # s of samples per gyro-scale sum (pairs do not span buckets: ≤ 2 windows of 2 s lost each)
SCALE_WINDOW_S = 60.0  # s: the gyro-scale verdict's window (30 pairs of 2-s windows)
STUCK_S = 5.0  # s an axis must hold one value to count as stuck ...
STUCK_MIN_SAMPLES = 50  # ... and this many samples (a slow polled source)
ACCEL_WINDOW_S = 10.0  # s: the mean |specific force| window
ACCEL_BAND = (0.3, 3.0)  # × g: the plausible mean magnitude (units are off by 9.81 or 1000; vigorous hand motion 1.5)
CLEAR_S = 10.0  # s a check must pass before its cause clears
CHECK_EVERY_S = 0.25  # s of input between two runs of the checks (on the samples since)
AXES = ("gyro x", "gyro y", "gyro z", "accel x", "accel y", "accel z")


class LiveChecks:
    """The windowed checks of one live run (see the module doc): ``add`` per block, ``causes(t)`` for the status.

    dt_nominal s (the gyro-scale check's gap threshold is ``gap_factor`` × it), gravity m/s²."""

    def __init__(self, dt_nominal: float, gap_factor: float = 5.0, gravity: float = 9.80665) -> None:
        self.gap_dt, self.gravity = gap_factor * float(dt_nominal), float(gravity)
        self._pending: list[tuple[np.ndarray, ...]] = []  # blocks not yet checked (CHECK_EVERY_S)
        self._buf: list[tuple[np.ndarray, ...]] = []  # samples of the open gyro-scale bucket
        self._buckets: deque[tuple[float, np.ndarray, np.ndarray]] = deque()  # (t_end, sums, counts)
        self._last = np.full(6, np.nan)  # last value of each axis
        self._since_t = np.full(6, np.nan)  # time each axis last changed (s)
        self._since_n = np.zeros(6, np.int64)  # samples since
        self._acc: deque[tuple[float, float, int]] = deque()  # (t_end, sum |f|, count) per block
        self._acc_sum, self._acc_n = 0.0, 0  # their sums over the window
        self._failing: dict[str, tuple[str, float]] = {}  # kind → (cause text, time it last failed)
        self.scale: tuple[float, float, int] | None = None  # the last verdict's (ŝ, E rad, pairs)
        self.failures: dict[str, int] = {}  # times each kind started failing

    # ---------------------------------------------------------------------------------------------------- input
    def add(self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, bias: np.ndarray, force: np.ndarray) -> None:
        """One block: time (N,) s, gyro (N,3) rad/s and accel (N,3) m/s² as filtered (calibrated, mounted), the
        filter's gyro bias (N,3) rad/s and compensated specific force (N,3) m/s². The checks run every
        ``CHECK_EVERY_S`` of input on the blocks since (a live block is often one sample)."""
        if not len(t):
            return
        self._pending.append((t, gyro, accel, bias, force))
        if float(t[-1]) - float(self._pending[0][0][0]) < CHECK_EVERY_S:
            return
        if len(self._pending) == 1:
            t, gyro, accel, bias, force = (np.asarray(a, float) for a in self._pending[0])
        else:
            t, gyro, accel, bias, force = (np.concatenate(a) for a in zip(*self._pending, strict=True))
        self._pending.clear()
        t_end = float(t[-1])
        self._stuck(t, np.concatenate([gyro, accel], axis=1))
        self._accel(t_end, accel)
        self._buf.append((t, gyro, bias, force))
        if t_end - float(self._buf[0][0][0]) >= SCALE_BUCKET_S:
            self._scale_bucket(t_end)

    def _stuck(self, t: np.ndarray, x: np.ndarray) -> None:
        n = len(t)
        prev = np.concatenate([self._last[None, :], x[:-1]])
        changed = ~(x == prev)  # NaN (a missing sample) is no held value
        any_changed = changed.any(axis=0)
        last = n - 1 - np.argmax(changed[::-1], axis=0)  # the last row that changed, per axis
        self._since_t = np.where(any_changed, t[last], self._since_t)
        self._since_n = np.where(any_changed, n - 1 - last, self._since_n + n)
        self._last = x[-1].copy()
        t_end = float(t[-1])
        held = (self._since_n >= STUCK_MIN_SAMPLES) & (t_end - self._since_t >= STUCK_S)
        if held.any():
            axes = [AXES[i] for i in np.flatnonzero(held)]
            what = "all six axes" if len(axes) == 6 else ", ".join(axes)
            longest = float(np.nanmax(np.where(held, t_end - self._since_t, np.nan)))
            self._fail("stuck input", f"stuck input ({what} unchanged for {longest:.0f} s)", t_end)

    def _accel(self, t_end: float, accel: np.ndarray) -> None:
        f = np.linalg.norm(accel, axis=1)
        ok = np.isfinite(f)
        blk = (t_end, float(f[ok].sum()), int(ok.sum()))
        self._acc.append(blk)
        self._acc_sum, self._acc_n = self._acc_sum + blk[1], self._acc_n + blk[2]
        while self._acc and self._acc[0][0] < t_end - ACCEL_WINDOW_S:
            _, s, c = self._acc.popleft()
            self._acc_sum, self._acc_n = self._acc_sum - s, self._acc_n - c
        if self._acc_n and t_end - self._acc[0][0] >= 0.9 * ACCEL_WINDOW_S:
            mean = self._acc_sum / self._acc_n
            lo, hi = (b * self.gravity for b in ACCEL_BAND)
            if not lo <= mean <= hi:
                txt = (f"accelerometer far from g (mean |f| {mean:.2f} m/s^2 over {ACCEL_WINDOW_S:g} s: units, a lost "
                       "axis or violent motion)")  # fmt: skip
                self._fail("accelerometer far from g", txt, t_end)

    def _scale_bucket(self, t_end: float) -> None:
        t, g, b, f = (np.concatenate(a) for a in zip(*self._buf, strict=True))
        self._buf.clear()
        chk = GyroScaleCheck(gap_dt=self.gap_dt, gravity=self.gravity)
        chk.add(t, g, b, f)
        self._buckets.append((t_end, chk.sums, chk.counts))
        while self._buckets and self._buckets[0][0] <= t_end - SCALE_WINDOW_S:
            self._buckets.popleft()
        if t_end - float(t[0]) + SCALE_BUCKET_S * (len(self._buckets) - 1) < 0.9 * SCALE_WINDOW_S:
            return  # the window is not full yet: no verdict (a short window has a flat J)
        agg = GyroScaleCheck(gap_dt=self.gap_dt, gravity=self.gravity)
        agg.sums = np.sum([s for _, s, _ in self._buckets], axis=0)
        agg.counts = np.sum([c for _, _, c in self._buckets], axis=0)
        self.scale = agg.estimate()
        entry = agg.report()[0]["gyro_scale_check"]
        if not entry.get("flagged"):
            return
        if "reversed_axes" in entry:
            how = f"gyro {entry['reversed_axes']} reversed?"
        else:
            s = float(entry["scale"])
            how = f"rates {max(s, 1 / s):.2g}x too {'fast' if s < 1 else 'slow'}"
        txt = (f"gyro scale check ({how}: {entry['discrepancy_deg']:.1f} deg of tilt discrepancy over the last "
               f"{SCALE_WINDOW_S:g} s; wrong range/unit or a lever arm not given)")  # fmt: skip
        self._fail("gyro scale check", txt, t_end)

    def _fail(self, kind: str, text: str, t: float) -> None:
        if kind not in self._failing:
            self.failures[kind] = self.failures.get(kind, 0) + 1
        self._failing[kind] = (text, t)

    # --------------------------------------------------------------------------------------------------- output
    def causes(self, t: float) -> list[str]:
        """The causes of V at input time ``t`` (s): each check that failed within the last ``CLEAR_S``."""
        for kind in [k for k, (_, t_fail) in self._failing.items() if t - t_fail > CLEAR_S]:
            del self._failing[kind]
        return [text for text, _ in self._failing.values()]

    def summary(self) -> dict:
        out: dict = {"failures": dict(self.failures)}
        if self.scale is not None:
            s, e, pairs = self.scale
            out["gyro_scale_last"] = {"scale": round(s, 3), "discrepancy_deg": round(float(np.degrees(e)), 2),
                                      "pairs": pairs}  # fmt: skip
        return out
