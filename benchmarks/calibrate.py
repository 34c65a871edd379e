"""Calibration speed: Allan deviation on 24 h of 200 Hz data (3 axes), ellipsoid fit on 100 k samples.

Run: python benchmarks/calibrate.py   (prints figures; targets: Allan < 10 s, ellipsoid fit < 1 s)

(Not named calibration.py: run from this folder, that name hid the `calibration` package from every benchmark.)
"""

from __future__ import annotations

import os
import sys
import time

# this script is named like the package it measures: keep benchmarks/ off the import path
_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != _HERE] + [os.path.dirname(_HERE)]

import numpy as np  # noqa: E402

from calibration.allan import allan_deviation, analyse  # noqa: E402
from calibration.magnetometer import calibrate_sphere  # noqa: E402


def bench_allan(hours: float = 24.0, rate_hz: float = 200.0) -> None:
    n = int(hours * 3600 * rate_hz)
    rng = np.random.default_rng(0)
    y = rng.standard_normal((n, 3)).astype(np.float64) * 1e-3
    y += np.cumsum(rng.standard_normal((n, 3)) * 1e-6, axis=0)
    allan_deviation(y[:1000], rate_hz)  # compile / load the numba kernel outside the timing
    t0, c0 = time.perf_counter(), time.process_time()
    res = analyse(y, rate_hz, "gyro", "rad/s")
    dt, dc = time.perf_counter() - t0, time.process_time() - c0
    print(
        f"Allan deviation, {hours:g} h @ {rate_hz:g} Hz × 3 axes ({n:,} samples/axis, {len(res.taus)} τ values "
        f"{res.taus[0]:.3g}–{res.taus[-1]:.3g} s) + noise terms: {dt:.2f} s wall, {dc:.2f} s CPU  "
        f"(target < 10 s; load average now {os.getloadavg()[0]:.1f})"
    )


def bench_ellipsoid(n: int = 100_000) -> None:
    rng = np.random.default_rng(1)
    u = rng.standard_normal((n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    a_s = np.array([[1.08, 0.05, -0.03], [0.05, 0.93, 0.06], [-0.03, 0.06, 1.01]])
    m = 50 * u @ a_s.T + [12, -25, 8] + rng.normal(0, 0.15, (n, 3))
    for kind in ("full", "auto"):
        calibrate_sphere(m[:1000], kind)  # numba kernel loaded outside the timing
        best, cpu = np.inf, np.inf
        for _ in range(3):
            t0, c0 = time.perf_counter(), time.process_time()
            fit = calibrate_sphere(m, kind, field_ut=50.0)
            best, cpu = min(best, time.perf_counter() - t0), min(cpu, time.process_time() - c0)
        err = np.linalg.norm(fit.A - np.linalg.inv(a_s)) / np.linalg.norm(np.linalg.inv(a_s))
        print(
            f"ellipsoid fit ({kind}: Li–Griffiths + least_squares refinement + coverage + covariance), "
            f"{n:,} samples: {best:.3f} s wall, {cpu:.3f} s CPU, best of 3  (A error {100 * err:.3f} %; "
            "target < 1 s for 'full')"
        )


if __name__ == "__main__":
    bench_ellipsoid()
    bench_allan()
