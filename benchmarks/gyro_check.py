"""The gyro-scale self-check (imutool.gyro_check) on every shared BROAD trial and the ship simulations, intact,
with the gyro's rates scaled (a wrong full-scale range) and with one gyro axis reversed: the scale (or reversed
axes) it finds, the discrepancy that removes, and whether it warns. Also the check's cost beside the filter's.

Usage::

    python benchmarks/gyro_check.py            # BROAD (where ../shared/data is present) + simulator
    python benchmarks/gyro_check.py --sim-only
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from formats import Recording, read  # noqa: E402
from imutool.attitude import ekf_recording  # noqa: E402
from imutool.sim import simulate  # noqa: E402

BROAD = Path(os.environ.get("IMUTOOL_SHARED_DATA", ROOT.parent / "shared" / "data")) / "broad"
FACTORS = (1.0, 1.5, 2.0, 0.5)
REVERSED = ("x", "y", "z")  # one gyro axis reversed against the accelerometer (the axis check)


def scaled(rec: Recording, factor: float | np.ndarray) -> Recording:
    out = Recording(rec.time, meta=dict(rec.meta))
    for name in rec.channels:
        out.add(name, rec[name] * factor if name == "gyro" else rec[name], rec.units.get(name))
    return out


def row(name: str, rec: Recording, lever: np.ndarray | None) -> str:
    cells = []
    for k in (*FACTORS, *REVERSED):
        factor = k if not isinstance(k, str) else np.where(np.arange(3) == "xyz".index(k), -1.0, 1.0)
        _, s = ekf_recording(scaled(rec, factor), lever_arm=lever)
        c = s["gyro_scale_check"]
        found = f"{c['reversed_axes']} reversed" if "reversed_axes" in c else f"{c.get('scale', float('nan')):.2f}"
        cells.append(
            f"{found} / {c.get('discrepancy_deg', float('nan')):.1f}°" + (" **warned**" if c.get("flagged") else "")
        )
    return f"| {name} | " + " | ".join(cells) + " |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sim-only", action="store_true")
    args = ap.parse_args()
    print(
        "Scale found ŝ (or the axes found reversed) / RMS discrepancy it removes (the gyro's rates × the factor in "
        "the header, or one axis reversed):"
    )
    print(
        "| recording | " + " | ".join([f"gyro × {k:g}" for k in FACTORS] + [f"{a} reversed" for a in REVERSED]) + " |"
    )
    print("|---|" + "---|" * (len(FACTORS) + len(REVERSED)))
    if not args.sim_only and BROAD.is_dir():
        for f in sorted(BROAD.glob("*.csv")):
            print(row(f.stem, read(f), None), flush=True)
    for name, seed, kw, lever in (
        ("ship-roll", 7, {}, False),
        ("ship-roll", 2, {}, False),
        ("ship-at-sea", 0, {}, True),
        ("ship-at-sea", 3, {"turn_start": 100}, True),
        ("ship-at-sea", 3, {"turn_start": 100}, False),
    ):
        rec = simulate(name, duration=300, seed=seed, **kw)
        arm = np.array(rec.meta["lever_arm_m"]) if lever else None
        label = f"{name} seed {seed}" + (
            ", lever arm + SOG/COG" if lever else (", SOG/COG, no lever arm given" if "sog" in rec.channels else "")
        )
        print(row(label, rec, arm), flush=True)
    print(row("walk seed 1 (a foot in gait)", simulate("walk", duration=100, seed=1), None), flush=True)
    rec = simulate("ship-roll", duration=600, seed=1)
    t0 = time.perf_counter()
    ekf_recording(rec)
    with_check = time.perf_counter() - t0
    from imutool.attitude import run_ekf

    t0 = time.perf_counter()
    run_ekf(rec.time, rec["gyro"], rec["accel"], rec["mag"])
    print(
        f"\ncost: ekf_recording with the check {with_check:.2f} s, the filter alone {time.perf_counter() - t0:.2f} s "
        f"({len(rec)} samples)"
    )


if __name__ == "__main__":
    main()
