"""Roll amplitude, period and peak-hold for a live display (MSC.363(92) §3, IEC 61162-1 HRM notes).

Amplitude and period are :func:`imutool.roll.roll_cycles` (the batch method ``imutool roll`` uses) on a
trailing window of heel (``window_s``, default 120 s), evaluated every ``every_s`` of input time: the values
are those of the latest completed excursion on each side, as ``imutool roll`` gives at the window's last sample.
Peak-hold is the running maximum of the heel to each side since the last reset (exact, every sample). A reset's
UTC is kept in a small JSON state file (``state_path``) written atomically, so it survives a restart.
"""

from __future__ import annotations

import json
import os
from collections import deque
from datetime import datetime, timezone
from typing import Any

import numpy as np

from imutool.roll import PORT, ROLL_DEFAULTS, STBD, roll_cycles

SPAN_PERIODS = 4.0  # roll periods of heel handed to roll_cycles once a period is known (the cost grows with it)
SPAN_MARGIN_S = 10.0


def iso_utc(t: float) -> str:
    """Host UTC epoch seconds → ISO 8601 with Z, seconds resolution."""
    return datetime.fromtimestamp(t, tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


class LiveRoll:
    """Incremental roll statistics: ``add(t, heel_deg)`` per block; amplitudes (deg, positive), period (s),
    peak-hold (deg, positive) and the reset's UTC as attributes."""

    def __init__(
        self,
        window_s: float = 120.0,
        every_s: float = 1.0,
        state_path: str | os.PathLike | None = None,
        hysteresis_deg: float = ROLL_DEFAULTS["hysteresis_deg"],
        max_period_s: float = ROLL_DEFAULTS["max_period_s"],
    ) -> None:
        self.window_s, self.every_s = float(window_s), float(every_s)
        self.hysteresis_deg, self.max_period_s = hysteresis_deg, max_period_s
        self._t: deque[np.ndarray] = deque()
        self._x: deque[np.ndarray] = deque()
        self._next_eval = -np.inf
        self._last_eval = -np.inf
        self._side = 0  # the Schmitt trigger's side: +1 above +h last, -1 below -h last, 0 not yet
        self._dirty = False
        self.amp_port: float | None = None
        self.amp_stbd: float | None = None
        self.period: float | None = None
        self.period_port: float | None = None
        self.period_stbd: float | None = None
        self.peak_port = 0.0
        self.peak_stbd = 0.0
        self.reset_utc: float | None = None
        self.state_path = None if state_path is None else os.fspath(state_path)
        self._load()

    def _load(self) -> None:
        if not self.state_path or not os.path.exists(self.state_path):
            return
        try:
            with open(self.state_path, encoding="utf-8") as f:
                s = json.load(f)
            self.reset_utc = float(s["reset_utc_s"]) if s.get("reset_utc_s") is not None else None
            self.peak_port = float(s.get("peak_port_deg", 0.0))
            self.peak_stbd = float(s.get("peak_stbd_deg", 0.0))
        except (OSError, ValueError, KeyError, TypeError):
            pass  # a damaged state file: start as after a reset

    def save(self) -> None:
        """Write the peak-hold and its reset time (atomic rename)."""
        if not self.state_path:
            return
        tmp = self.state_path + ".tmp"
        state = {
            "reset_utc_s": self.reset_utc,
            "reset_utc": None if self.reset_utc is None else iso_utc(self.reset_utc),
            "peak_port_deg": self.peak_port,
            "peak_stbd_deg": self.peak_stbd,
        }
        try:
            os.makedirs(os.path.dirname(os.path.abspath(self.state_path)), exist_ok=True)
            with open(tmp, "w", encoding="utf-8") as f:
                json.dump(state, f)
            os.replace(tmp, self.state_path)
        except OSError:
            pass  # a full disk must not stop the outputs; the engine logs the recording's state

    def reset(self, utc_s: float) -> None:
        """Reset the peak-hold at host UTC ``utc_s`` (s)."""
        self.peak_port = self.peak_stbd = 0.0
        self.reset_utc = float(utc_s)
        self.save()

    @property
    def reset_iso(self) -> str | None:
        return None if self.reset_utc is None else iso_utc(self.reset_utc)

    def add(self, t: np.ndarray, heel_deg: np.ndarray) -> None:
        """Take a block of heel samples (t s, heel deg + starboard down)."""
        if not len(t):
            return
        x = np.asarray(heel_deg, float)
        ok = np.isfinite(x)
        if ok.any():
            self.peak_stbd = max(self.peak_stbd, float(x[ok].max()))
            self.peak_port = max(self.peak_port, float(-x[ok].min()))
        self._t.append(np.asarray(t, float))
        self._x.append(x)
        while len(self._t) > 1 and self._t[0][-1] < t[-1] - self.window_s:
            self._t.popleft()
            self._x.popleft()
        # an excursion can only have completed where the heel crossed a threshold (the Schmitt trigger of
        # roll_cycles): evaluate then (at most every every_s), and every max_period_s to let stale values go
        h = self.hysteresis_deg
        crossed = False
        if ok.any():
            hi, lo = bool((x[ok] > h).any()), bool((x[ok] < -h).any())
            if (hi and self._side < 0) or (lo and self._side > 0) or (hi and lo) or self._side == 0:
                crossed = True
                last_hi = np.flatnonzero(x > h)
                last_lo = np.flatnonzero(x < -h)
                a = last_hi[-1] if last_hi.size else -1
                b = last_lo[-1] if last_lo.size else -1
                self._side = 1 if a > b else -1 if b > a else self._side
        self._dirty = self._dirty or crossed
        due = t[-1] >= self._next_eval
        if (self._dirty and due) or t[-1] >= self._last_eval + self.max_period_s:
            self._next_eval = t[-1] + self.every_s
            self._last_eval = float(t[-1])
            self._dirty = False
            self.evaluate()

    def refresh(self) -> None:
        """Evaluate now if an excursion may have completed since the last evaluation."""
        if self._dirty and self._t:
            self._dirty = False
            self._last_eval = float(self._t[-1][-1])
            self.evaluate()

    def window(self) -> tuple[np.ndarray, np.ndarray]:
        """The trailing window (t s, heel deg) the statistics are computed on (the blocks joined once: kept as one
        array, so the next join takes it and the few blocks since)."""
        tt, xx = np.concatenate(self._t), np.concatenate(self._x)
        keep = tt >= tt[-1] - self.window_s
        tt, xx = tt[keep], xx[keep]
        self._t, self._x = deque([tt]), deque([xx])
        return tt, xx

    def evaluate(self) -> None:
        """Recompute amplitude and period on the trailing window."""
        t, x = self.window()
        # the latest cycles of each side depend only on the samples since the excursion before them (the first,
        # partial excursion of a window is dropped): a window of a few roll periods gives what the whole one does
        if self.period is not None:
            span = min(self.window_s, SPAN_PERIODS * self.period + SPAN_MARGIN_S)
            keep = t >= t[-1] - span
            t, x = t[keep], x[keep]
        ok = np.isfinite(x)
        if ok.sum() < 8:
            return
        cyc = roll_cycles(t[ok], x[ok], self.hysteresis_deg, max_period_s=self.max_period_s)
        out: dict[int, Any] = {}
        for side in (PORT, STBD):
            idx = np.flatnonzero(cyc.side == side)
            out[side] = (float(cyc.amplitude_deg[idx[-1]]), float(cyc.period_s[idx[-1]])) if idx.size else None
        self.amp_port = None if out[PORT] is None else out[PORT][0]
        self.amp_stbd = None if out[STBD] is None else out[STBD][0]
        self.period_port = None if out[PORT] is None or not np.isfinite(out[PORT][1]) else out[PORT][1]
        self.period_stbd = None if out[STBD] is None or not np.isfinite(out[STBD][1]) else out[STBD][1]
        # the period of the side whose excursion completed last (roll_stats' roll_period), when still current
        self.period = None
        if len(cyc):
            p = float(cyc.period_s[-1])
            if np.isfinite(p) and t[-1] - float(cyc.t_end[-1]) <= self.max_period_s:
                self.period = p
