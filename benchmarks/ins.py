"""Speed of ZVI detection and the error-state INS on a long foot log (prints samples/s).

Usage: python benchmarks/ins.py [--minutes 60] [--rate 400]
A one-hour 400 Hz log (1.44 M samples) is built by repeating a simulated walk. Wall and CPU time are both printed
(on a shared machine the CPU time is the honest figure).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from imutool.ins import InsConfig, run_ins
from imutool.sim.walk import walk
from imutool.zvi import detect_zvi


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--rate", type=float, default=400.0)
    a = ap.parse_args()
    base = walk(seed=0, n_steps=50, rate_hz=a.rate)
    n_target = int(a.minutes * 60 * a.rate)
    reps = int(np.ceil(n_target / len(base)))
    gyro = np.tile(base["gyro"], (reps, 1))[:n_target]
    accel = np.tile(base["accel"], (reps, 1))[:n_target]
    t = np.arange(n_target) / a.rate
    # warm-up (numba compile / cache load) on a short slice
    t0 = time.perf_counter()
    z = detect_zvi(t[:20000], gyro[:20000], accel[:20000], "shoe").flags
    run_ins(t[:20000], gyro[:20000], accel[:20000], z, InsConfig(height_update=True))
    warm = time.perf_counter() - t0
    print(f"log: {n_target} samples ({a.minutes:g} min at {a.rate:g} Hz); warm-up/compile {warm:.2f} s")
    for det in ("shoe", "paper"):
        t0, c0 = time.perf_counter(), time.process_time()
        res = detect_zvi(t, gyro, accel, det)
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        print(
            f"zvi {det:13s}: wall {dt:6.2f} s, cpu {dc:6.2f} s  {n_target / dc / 1e6:6.2f} M samples/s (cpu)  "
            f"({len(res.intervals)} intervals)"
        )
    flags = detect_zvi(t, gyro, accel, "shoe").flags
    for label, cfg in (
        ("ins zupt", InsConfig()),
        ("ins zupt+height", InsConfig(height_update=True)),
        ("ins no-zupt", InsConfig(zupt=False)),
    ):
        t0, c0 = time.perf_counter(), time.process_time()
        run_ins(t, gyro, accel, flags, cfg)
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        print(f"{label:17s}: wall {dt:6.2f} s, cpu {dc:6.2f} s  {n_target / dc / 1e6:6.2f} M samples/s (cpu)")


if __name__ == "__main__":
    main()
