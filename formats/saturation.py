"""Saturation: samples where a sensor sat at the end of its range (a clipped accelerometer or gyro).

A sensor shaken beyond its range reports its range limit, not the motion: flat tops at one value. Per axis and
sign, the extreme value of a recording (or chunk) is taken for a range limit when it is held for ``MIN_RUN``
samples or more in a row somewhere and lies beyond ``FLOORS`` (a still sensor repeats its values too, but
within ±1 g and a few °/s); every sample at a limit is flagged. Nothing is changed here: the attitude filter
does not use a clipped accelerometer sample, and says so (:func:`imutool.attitude.recording.ekf_recording`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .units import STANDARD_GRAVITY

MIN_RUN = 3  # samples held at the extreme in a row: a range limit, not a peak (a smooth peak's top moves)
FLOORS = {"accel": 1.5 * STANDARD_GRAVITY, "gyro": 1.0}  # m/s², rad/s: no sensor's range ends below these


@dataclass
class Clipping:
    """Where one channel is clipped: ``mask`` (N,) bool, ``limits`` the clipped values per axis, in the
    channel's units (``None`` where an axis is not clipped)."""

    mask: np.ndarray
    limits: list[tuple[float, ...]]

    @property
    def count(self) -> int:
        return int(self.mask.sum())


def _longest_run(flags: np.ndarray) -> int:
    if not flags.any():
        return 0
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flags.astype(np.int8), [0]])))
    return int((edges[1::2] - edges[::2]).max())


def clipped(values: np.ndarray, channel: str, min_run: int = MIN_RUN) -> Clipping:
    """The samples of ``values`` ((N,3) in SI units: accel m/s², gyro rad/s) at a range limit of ``channel``."""
    x = np.asarray(values, dtype=np.float64)
    x = x.reshape(len(x), -1)
    mask = np.zeros(len(x), dtype=bool)
    limits: list[tuple[float, ...]] = []
    floor = FLOORS[channel]
    if len(x):  # the usual case first, in two passes over the whole array: every value finite or NaN and short of
        flat = x.reshape(-1)  # the floor, no axis holds anything there (fmax/fmin ignore NaN; ±inf: the long way)
        hi, lo = float(np.fmax.reduce(flat)), float(np.fmin.reduce(flat))
        if np.isfinite(hi) and np.isfinite(lo) and hi < floor and -lo < floor:
            return Clipping(mask, [()] * x.shape[1])
    for axis in range(x.shape[1]):
        col = x[:, axis]
        found: list[float] = []
        finite = np.isfinite(col)
        if finite.sum() >= min_run:
            for sign in (1.0, -1.0):
                extreme = float(np.max(sign * col[finite]))
                if extreme < floor:
                    continue
                at = sign * col == extreme
                if _longest_run(at) >= min_run:
                    mask |= at
                    found.append(sign * extreme)
        limits.append(tuple(found))
    return Clipping(mask, limits)


def clipping_warning(channel: str, limits: set[float], count: int, unit: str) -> str:
    """One line for a user: which channel, at which values (``limits``, in ``unit``), how many samples, and what it
    means."""
    where = ", ".join(f"{v:g}" for v in sorted(limits))
    what = {
        "accel": "not used by the attitude filter there (the motion went beyond the sensor's range)",
        "gyro": "the attitude integrates a wrong rate there: check the gyro's range setting",
    }[channel]
    return f"{channel} clipped at {where} {unit} (its range limit) on {count} samples: {what}"
