"""Real-time heave for TSS1/PASHR: the vertical acceleration (the attitude's rotation of the specific force, less
gravity) through the causal band-pass double integrator of :func:`imutool.heave.bandpass_integrator`, its filter
state carried from block to block (``scipy.signal.sosfilt`` with ``zi``): the same output in any blocks.
Heave + up (m). Not reported (None) for ``settle_s`` after the start while the integrator's transient decays.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from formats.units import STANDARD_GRAVITY
from imutool.heave import bandpass_integrator

HEAVE_CUTOFF_HZ = 0.04  # Hz: the band-pass's high-pass corner (waves of 25 s and shorter pass)
HEAVE_ORDER = 3


class LiveHeave:
    """``add(t, q, accel)`` per block → heave (m, + up) per row; ``settled`` once ``settle_s`` has passed."""

    def __init__(self, rate_hz: float, cutoff_hz: float = HEAVE_CUTOFF_HZ, settle_s: float = 120.0) -> None:
        self.sos = bandpass_integrator(rate_hz, cutoff_hz, HEAVE_ORDER)
        self.zi = np.zeros((self.sos.shape[0], 2))
        self._sos_rows = [tuple(float(c) for c in row) for row in self.sos]
        self.settle_s = settle_s
        self.t0: float | None = None
        self.last: float | None = None
        self.settled = False

    def add(self, t: np.ndarray, R: np.ndarray, accel: np.ndarray) -> np.ndarray:
        """Heave (m, + up) of a block: t (N,) s, R (N,3,3) body→NED rotation, accel (N,3) m/s² body (a NaN row
        is taken as no vertical acceleration)."""
        if not len(t):
            return np.empty(0)
        if self.t0 is None:
            self.t0 = float(t[0])
        f_down = np.einsum("nj,nj->n", R[:, 2, :], np.asarray(accel, float))
        a_up = -f_down - STANDARD_GRAVITY
        a_up = np.where(np.isfinite(a_up), a_up, 0.0)
        if len(a_up) > 4:
            h, self.zi = signal.sosfilt(self.sos, a_up, zi=self.zi)
        else:
            h = _sos_rows(self._sos_rows, a_up, self.zi)
        self.settled = bool(t[-1] - self.t0 >= self.settle_s)
        self.last = float(h[-1])
        return h


def _sos_rows(sos: list[tuple[float, ...]], x: np.ndarray, zi: np.ndarray) -> np.ndarray:
    """``sosfilt`` (transposed direct form II, as scipy) for a few rows in plain Python; ``zi`` updated in place."""
    out = np.empty(len(x))
    for k in range(len(x)):
        v = float(x[k])
        for s, (b0, b1, b2, _a0, a1, a2) in enumerate(sos):
            y = b0 * v + zi[s, 0]
            zi[s, 0] = b1 * v - a1 * y + zi[s, 1]
            zi[s, 1] = b2 * v - a2 * y
            v = y
        out[k] = v
    return out
