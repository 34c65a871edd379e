"""Cost of the input checks every command runs (formats.plausibility): units/axes checks and absurd-sample scan.

Run: python benchmarks/plausibility.py   (prints figures for 1 h and 24 h of 200 Hz 9-axis data)
"""

from __future__ import annotations

import time

import numpy as np

from formats import Recording
from formats.plausibility import bridge_absurd, check_recording, dropped_rows
from imutool.sim import simulate


def main() -> None:
    base = simulate("ship-roll", duration=600, seed=1)
    for hours in (1.0, 24.0):
        n = int(hours * 3600 * 200)
        reps = -(-n // len(base))
        rec = Recording(np.arange(n) / 200.0, {k: np.tile(base[k], (reps, 1))[:n] for k in ("gyro", "accel", "mag")})
        best = {}
        for _ in range(3):
            t0 = time.perf_counter()
            rep = check_recording(rec)
            t1 = time.perf_counter()
            bridge_absurd(rec)
            t2 = time.perf_counter()
            dropped_rows(n, n, {}, rec.meta)
            best["checks"] = min(best.get("checks", 1e9), t1 - t0)
            best["absurd-sample scan"] = min(best.get("absurd-sample scan", 1e9), t2 - t1)
        print(
            f"{hours:>4.0f} h at 200 Hz ({n:,} rows): "
            + ", ".join(f"{k} {v * 1e3:.0f} ms" for k, v in best.items())
            + f" (best of 3; warnings: {len(rep.warnings)})"
        )


if __name__ == "__main__":
    main()
