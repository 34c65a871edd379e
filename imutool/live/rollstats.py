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
        hysteresis_deg: float | None = ROLL_DEFAULTS["hysteresis_deg"],
        max_period_s: float = ROLL_DEFAULTS["max_period_s"],
    ) -> None:
        self.window_s, self.every_s = float(window_s), float(every_s)
        self.hysteresis_deg, self.max_period_s = hysteresis_deg, max_period_s
        self._t: deque[np.ndarray] = deque()
        self._x: deque[np.ndarray] = deque()
        self._next_eval = -np.inf
        self._last_eval = -np.inf
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
        # evaluated every every_s of input time: the cycles are cut about the window's own mean heel with a
        # hysteresis scaled to its roll (imutool.roll_period), so no fixed threshold tells when one completed
        self._dirty = True
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
        # the whole trailing window, as `imutool roll` on it: the centre (a running mean heel), the hysteresis and
        # the smoothing of imutool.roll_period are taken from the window itself, so a shorter span would differ
        ok = np.isfinite(x)
        if ok.sum() < 8:  # no heel in the window: nothing current to show (a stale value is not shown)
            self.amp_port = self.amp_stbd = self.period = self.period_port = self.period_stbd = None
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
