"""Heave benchmark: accuracy per sea state (simulator truth), the paper's platform, NTNU real data, and speed
(a day at 200 Hz). Prints markdown tables. Usage: python benchmarks/heave.py [--quick] [--no-speed | --only-speed]"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

import formats
from imutool import heave as H
from imutool.metrics import best_lag, interp_to
from imutool.sim.sea import heave_platform, sea_state

QUICK = "--quick" in sys.argv


def rmse(out, ref, flag, ch):
    m = out[flag] > 0.5
    return float(np.sqrt(np.mean((out[ch] - ref)[m] ** 2)))


def sea_table() -> None:
    print("| Hs m | Tp s | sig. heave m | delayed RMS | bound | real-time RMS | bound | band-pass RMS |")
    print("|---|---|---|---|---|---|---|---|")
    for hs in (1.0, 2.0, 4.0):
        for tp in (5.0, 9.0, 15.0):
            rec = sea_state(duration=600 if QUICK else 1200, rate_hz=10, hs=hs, tp=tp, seed=7)
            ref = rec["ref_heave"]
            sig = 4 * np.std(ref)
            rt, _ = H.heave_recording(rec, method="realtime")
            bp, _ = H.heave_recording(rec, method="bandpass")
            ed = rmse(rt, ref, "settled_delayed", "heave_delayed")
            er = rmse(rt, ref, "settled", "heave")
            eb = rmse(bp, ref, "settled", "heave")
            print(f"| {hs:g} | {tp:g} | {sig:.2f} | {100 * ed:.1f} cm | {100 * max(0.02, 0.02 * sig):.1f} cm "
                  f"| {100 * er:.1f} cm | {100 * max(0.05, 0.05 * sig):.1f} cm | {100 * eb:.1f} cm |", flush=True)


def platform_table() -> None:
    print("\n| amplitude m | KF multi-step (paper) RMSE | realtime RMSE | envelope detrend RMSE | improvement |")
    print("|---|---|---|---|---|")
    for amp in (0.03, 0.035, 0.04, 0.045, 0.05):
        rec = heave_platform(duration=300, rate_hz=100, amplitude=amp, seed=int(amp * 1000))
        ref = rec["ref_heave"]
        p, _ = H.heave_recording(rec, method="paper")
        r, _ = H.heave_recording(rec, method="realtime")
        e, _ = H.heave_recording(rec, method="envelope")
        m = (p["settled"] > 0.5) & (e["settled"] > 0.5)
        ep, er, ee = (float(np.sqrt(np.mean((x["heave"] - ref)[m] ** 2))) for x in (p, r, e))
        print(f"| {amp} | {1000 * ep:.2f} mm | {1000 * er:.2f} mm | {1000 * ee:.2f} mm | "
              f"{100 * (1 - ep / ee):+.0f} % |", flush=True)


def ntnu_table() -> None:
    root = Path(__file__).resolve().parents[2] / "shared" / "data" / "ntnu_waves"
    print("\n| file | camera lag s | zero-phase BP2 baseline (same samples) | delayed | real-time (settled) "
          "| BP2 on real-time samples |")
    print("|---|---|---|---|---|---|")
    for fn in ("3012_1.csv", "4061_1.csv"):
        p = root / fn
        if not p.exists():
            print(f"| {fn} | (not available) |")
            continue
        rec = formats.read(str(p))
        cols = ["acc_heave_sb", "acc_heave_ps"]
        out, _ = H.heave_recording(rec, vertical=cols)
        a = np.mean([rec[c] for c in cols], axis=0)
        base = H.heave_zero_phase_bandpass(a, rec.rate_hz, 0.3, 3.0)
        cam = rec["heave"]

        def err(x, m, rec=rec, cam=cam):
            lag, _ = best_lag(rec.time[m], x[m], rec.time, cam, 0.1)
            return lag, float(np.sqrt(np.nanmean((x[m] - interp_to(rec.time[m] - lag, rec.time, cam)) ** 2)))

        md, mr = out["settled_delayed"] > 0.5, out["settled"] > 0.5
        lag, ed = err(out["heave_delayed"], md)
        _, eb = err(base, md)
        _, er = err(out["heave"], mr)
        _, ebr = err(base, mr)
        print(f"| {fn} | {lag:+.3f} | {1000 * eb:.2f} mm | {1000 * ed:.2f} mm | {1000 * er:.2f} mm | "
              f"{1000 * ebr:.2f} mm |", flush=True)


def speed() -> None:
    # a day at 200 Hz: one hour of simulated sea tiled 24 times (the estimator does not know)
    hour = sea_state(duration=3600, rate_hz=200, hs=2.0, tp=9.0, seed=1, components=80)
    a, _ = H.vertical_acceleration(hour, attitude="ref")
    a = np.tile(a, 24)
    t = np.arange(len(a)) / 200.0
    for method in ("bandpass", "realtime", "paper"):
        t0 = time.perf_counter()
        H.estimate_heave(t, a, method=method)
        print(f"speed: {method}: 24 h at 200 Hz ({len(a):,} samples) in {time.perf_counter() - t0:.1f} s",
              flush=True)


if __name__ == "__main__":
    H.estimate_heave(np.arange(2000) / 10.0, np.sin(np.arange(2000) / 10.0), method="realtime")  # JIT warm-up
    if "--only-speed" not in sys.argv:
        ntnu_table()
        platform_table()
        sea_table()
    if "--no-speed" not in sys.argv:
        speed()
