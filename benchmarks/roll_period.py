"""Roll period on real and simulated sea roll (issue 48): the method's mean period (same-side maxima) against the
zero-up-crossing and spectral peak periods, and against the method before issue 48 (±0.5° about 0°).

python benchmarks/roll_period.py            # every real record in ../shared/data with roll + the simulated grid
python benchmarks/roll_period.py --quick    # the simulated grid with one seed

Prints figures, asserts nothing. Real records: ``../shared/data`` relative to the project root (absent: skipped).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT.parent / "shared" / "data"
OLD = {"hysteresis_deg": 0.5, "centre": "zero", "smooth_frac": 0.0}  # the method before issue 48

# NMEA logs of shared/data whose sentences carry roll or heel; each is read and kept only with enough cycles
NMEA_LOGS = [
    "nmea_gpsd/bundg_zeus_9.log",
    "nmea_signalk/gofree-merrimac.log",
    "nmea_gpsd/pypilot.log",
    "nmea_gpsd/rst39.log",
    "nmea_gpsd/skytraq-PX1172RH_DS.log",
    "nmea_gpsd/tnt-revolution.log",
]
# the flume runs: whole records (calm before the waves reach the model, decay after) and their rolling parts
FLUME = [
    ("3012_1", None, "whole run"),
    ("3012_1", (28.0, 50.0), "waves (T 1.516 s)"),
    ("3012_1", (50.0, 64.0), "free decay"),
    ("4061_1", None, "whole run (roll locked)"),
    ("4061_1", (24.0, 53.0), "waves (T 1.158 s), roll locked"),
]
NOT_SHIP_ROLL = (
    "broad/, fusion/, xio_gait_tracking/, mag_hmc5883l/, rosbags/: hand, foot, robot and bench motion, no sea roll; "
    "nmea_gpsd hemi.log, saab-r4.log and nmea_signalk n2kd-183-merrimac.log: no roll or heel sentence"
)


def real_records() -> tuple[list[tuple[str, np.ndarray, np.ndarray]], list[str]]:
    """(name, t s, heel deg) of every real roll record, and the excluded ones with the reason."""
    import formats
    import imutool.gyrofree as G
    from imutool.roll_period import MIN_CYCLES

    recs, excluded = [], [NOT_SHIP_ROLL]
    if not DATA.is_dir():
        return recs, [f"{DATA} absent: no real records"]
    for name, win, what in FLUME:
        rec = formats.read(str(DATA / "ntnu_waves" / f"{name}.csv"))
        t = rec.time
        cam = np.degrees(rec["roll"])
        r = G.planar_roll(t, rec["acc_heave_ps"], rec["acc_heave_sb"], [0, -0.13, 0], [0, 0.13, 0], [0, 0, -1])
        acc = np.degrees(r["roll"])
        m = np.ones(t.size, bool) if win is None else (t >= win[0]) & (t < win[1])
        span = "" if win is None else f" {win[0]:g}-{win[1]:g} s"
        recs.append((f"ntnu {name} camera{span} ({what})", t[m], cam[m]))
        if name == "4061_1":
            excluded.append(
                f"ntnu {name} accelerometer-pair roll{span}: roll locked, {np.std(acc[m]):.2f}° RMS, below that "
                "roll's own error (0.33° RMS against the camera on 3012_1, tests/test_gyrofree.py)"
            )
        else:
            recs.append((f"ntnu {name} accel-pair roll{span} ({what})", t[m], acc[m]))
    for rel in NMEA_LOGS:
        rec = formats.read(str(DATA / rel))
        if "roll" not in rec.channels:
            excluded.append(f"{rel}: no roll channel")
            continue
        t, x = rec.series("roll")
        ok = np.isfinite(x)
        t, x = t[ok], x[ok]
        dur = float(t[-1] - t[0]) if t.size else 0.0
        ups = np.sum((x[1:] - np.mean(x) > 0) & (x[:-1] - np.mean(x) <= 0)) if t.size else 0
        if t.size < 20 or np.ptp(x) < 0.1 or ups < MIN_CYCLES + 1:
            excluded.append(
                f"{rel}: {t.size} roll samples over {dur:.1f} s, range {np.ptp(x) if t.size else 0:.2f}°: "
                "too few roll cycles" + (" (the heel never changes)" if t.size and np.ptp(x) < 0.1 else "")
            )
            continue
        recs.append((f"{rel} (XDR heel, {1 / np.median(np.diff(t)):.0f} Hz, {dur:.0f} s)", t, x))
    return recs, excluded


def _fmt(v: float | None, nd: int = 2) -> str:
    return "-" if v is None or not np.isfinite(v) else f"{v:.{nd}f}"


def old_sides(t: np.ndarray, x: np.ndarray) -> list[float | None]:
    """Mean starboard and port periods as the method before issue 48 reported them (every period)."""
    from imutool.roll import roll_cycles

    c = roll_cycles(t, x, **OLD)
    out = []
    for s in (1, -1):
        p = c.of_side(s).period_s
        p = p[np.isfinite(p)]
        out.append(float(p.mean()) if p.size else None)
    return out


def old_mean(t: np.ndarray, x: np.ndarray) -> float | None:
    p = [v for v in old_sides(t, x) if v is not None]
    return float(np.mean(p)) if p else None


def real_table() -> None:
    from imutool.roll import roll_stats

    recs, excluded = real_records()
    print("\nReal records (heel about the mean heel; error = method / zero-up-crossing − 1)\n")
    print(
        "| record | mean heel (°) | method period stbd / port (s) | method mean (s) | zero-up-crossing (s) | "
        "spectral peak (s) | error vs Tz | spread of the three | warning | before issue 48 stbd / port (s) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    errs = []
    for name, t, x in recs:
        rs = roll_stats(t, x)
        s, e = rs.summary(), rs.periods
        p2p, tz = e["peak_to_peak_s"], e["zero_up_crossing_s"]
        err = None if p2p is None or tz is None else 100 * (p2p / tz - 1)
        if err is not None:
            errs.append(err)
        old = old_sides(t, x)
        print(
            f"| {name} | {s['mean_heel_deg']:+.2f} | {_fmt(s['starboard']['period_mean_s'])} / "
            f"{_fmt(s['port']['period_mean_s'])} | {_fmt(p2p)} | {_fmt(tz)} | {_fmt(e['spectral_peak_s'])} | "
            f"{_fmt(err, 1)} % | {_fmt(None if e['spread'] is None else 100 * e['spread'], 0)} % | "
            f"{'yes' if rs.warnings else 'no'} | {_fmt(old[0])} / {_fmt(old[1])} |"
        )
    if errs:
        a = np.abs(errs)
        print(f"\n|error vs Tz|: mean {a.mean():.1f} %, worst {a.max():.1f} % over {len(errs)} records")
    print("\nExcluded:")
    for e in excluded:
        print(f"- {e}")


def sim_table(seeds: int) -> None:
    from imutool.roll import roll_stats
    from imutool.sim.sea import irregular_roll

    amps = (1.0, 2.0, 5.0, 10.0, 20.0)
    lists = (0.0, 2.35, 5.0)
    periods = (8.0, 12.0, 20.0)
    rates = ((1.0, 0.05, 0.1), (2.0, 0.03, 0.01), (10.0, 0.05, 0.01))  # Hz, noise deg 1σ, resolution deg
    print(
        f"\nSimulated narrow-band irregular roll (JONSWAP through a roll response ζ 0.08, 20 min; natural periods "
        f"{', '.join(f'{p:g}' for p in periods)} s; lists {', '.join(f'{v:g}' for v in lists)}°; 1 Hz/0.05°/0.1°, "
        f"2 Hz/0.03°/0.01°, 10 Hz/0.05°/0.01° (rate/noise/resolution); {seeds} seed(s)). Error against the known "
        "mean zero-up-crossing period Tz = 2π√(m0/m2) of the roll spectrum; spectral against its peak Tp:\n"
    )
    print(
        "| significant amplitude (°) | runs | method \\|error\\| mean / worst | zero-up-crossing mean / worst | "
        "spectral vs Tp mean / worst | warnings | before issue 48 mean / worst (no period) |"
    )
    print("|---|---|---|---|---|---|---|")
    allm = []
    for amp in amps:
        em, ez, es, eo, warn, none_old, n = [], [], [], [], 0, 0, 0
        for lst in lists:
            for tn in periods:
                for fs, noise, q in rates:
                    for seed in range(seeds):
                        t, x, tr = irregular_roll(
                            duration=1200.0,
                            rate_hz=fs,
                            seed=seed,
                            roll_period=tn,
                            significant_deg=amp,
                            list_deg=lst,
                            noise_deg=noise,
                            quantum_deg=q,
                        )
                        rs = roll_stats(t, x)
                        e = rs.periods
                        n += 1
                        warn += bool(rs.warnings)
                        em.append(abs(e["peak_to_peak_s"] / tr["tz_s"] - 1) if e["peak_to_peak_s"] else np.inf)
                        ez.append(abs(e["zero_up_crossing_s"] / tr["tz_s"] - 1) if e["zero_up_crossing_s"] else np.inf)
                        es.append(abs(e["spectral_peak_s"] / tr["tp_s"] - 1) if e["spectral_peak_s"] else np.inf)
                        o = old_mean(t, x)
                        if o is None:
                            none_old += 1
                        else:
                            eo.append(abs(o / tr["tz_s"] - 1))
        allm += em

        def mw(v: list[float]) -> str:
            a = 100 * np.asarray(v)
            return f"{a.mean():.1f} / {a.max():.1f} %" if a.size else "-"

        print(
            f"| {amp:g} | {n} | {mw(em)} | {mw(ez)} | {mw(es)} | {warn} | {mw(eo)} ({none_old} of {n} without a "
            "period) |"
        )
    a = 100 * np.asarray(allm)
    print(f"\nmethod |error| against Tz over all {a.size} runs: mean {a.mean():.2f} %, worst {a.max():.2f} %")
    bimodal(seeds)


def bimodal(seeds: int) -> None:
    """Swell and wind-sea roll of equal energy (16 s and 6 s, 3° significant each): the warning must fire."""
    from imutool.roll import roll_stats
    from imutool.sim.sea import irregular_roll

    print("\nBimodal roll (16 s swell + 6 s sea, 3° significant each, 2 Hz, 20 min): the cross-check\n")
    print("| seed | peak-to-peak (s) | zero-up-crossing (s) | spectral peak (s) | spread | warning |")
    print("|---|---|---|---|---|---|")
    for seed in range(2 * seeds):
        t, a, _ = irregular_roll(duration=1200.0, seed=seed, roll_period=6.0, significant_deg=3.0)
        _, b, _ = irregular_roll(duration=1200.0, seed=seed + 10, roll_period=16.0, significant_deg=3.0, noise_deg=0)
        rs = roll_stats(t, a + b)
        e = rs.periods
        print(
            f"| {seed} | {_fmt(e['peak_to_peak_s'])} | {_fmt(e['zero_up_crossing_s'])} | {_fmt(e['spectral_peak_s'])} "
            f"| {100 * e['spread']:.0f} % | {'yes' if rs.warnings else 'no'} |"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one seed for the simulated grid")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    t0 = time.perf_counter()
    real_table()
    sim_table(1 if args.quick else 2)
    print(f"\n({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
