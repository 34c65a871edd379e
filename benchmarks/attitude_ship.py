"""The ship grid of issue 35: a bridge inclinometer on ``imutool simulate ship-at-sea``, imutool beside VQF.

Factors (one at a time around a base cell, then the worst corners; not the full product):

- sway of the hull 0 / 0.5 / **1** / 1.5 m (peak over the voyage, a translation across the track),
- its period 6 / **10** / 14 s,
- irregular roll to a significant amplitude (2σ) of 10 / **20** / 30° (natural period 12 s),
- bridge height 10 / **20** / 30 m above the roll centre, 12 m aft (lever arm (−12, 0, −h) m, body FRD),
- the speed source: **GNSS hull velocity** at 1 Hz with 0.05 m/s noise (sog/cog columns, sway in them), SOG/COG
  smoothed by the receiver to the track (no sway), only the ship's log speed (constant), none,
- the lever arm given to the filter or not (then ``imutool filter`` estimates it from the motion), at every level
  of the other four factors.

Every voyage: heave ±2 m, pitch 3°, a 360° turn at 3 °/s and 8 m/s (from 180 s; 40 s in ``--quick``), MEMS noise
and drifting biases, 100 Hz, 10 minutes (3 in ``--quick``). Scored after the first two minutes: roll and pitch
RMSE and max |error| (deg), mean over the seeds with the worst seed beside it, and the share of samples the
filter's self-check flags. imutool runs through the library route (:func:`imutool.filtering.run_filter`, the
``imutool filter`` one) with the lever arm and the speed channels as a user gives them; VQF 2.1.2 (6D and 9D,
causal) and offline VQF 6D (``pip install vqf``, benchmark-only) run on the same rows, told neither the lever arm
nor the speed (they have no input for either).

``log`` speed: ``imutool filter --speed`` (the log's constant speed, taken along the bow: the turn's term).

Usage::

    python benchmarks/attitude_ship.py --quick        # 3-minute voyages, 7 cells, 1 seed (~30 s; no lever-arm estimate)
    python benchmarks/attitude_ship.py                # 10-minute voyages, 31 cells, seeds 0-2 (~2 min)
    python benchmarks/attitude_ship.py --param accel_lp_tau=5 --jobs 2
"""

from __future__ import annotations

import argparse
import multiprocessing
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from formats.frames import quat_multiply, quat_to_euler  # noqa: E402
from imutool.attitude import EkfParams  # noqa: E402
from imutool.filtering import run_filter  # noqa: E402
from imutool.sim import simulate  # noqa: E402

ENU2NED = np.array([0.0, np.sqrt(0.5), np.sqrt(0.5), 0.0])  # VQF's ENU quaternion → NED
BASE = {"sway": 1.0, "period": 10.0, "roll": 20.0, "height": 20.0, "speed": "gnss", "lever": True}
LEVELS = {
    "sway": (0.0, 0.5, 1.0, 1.5),
    "period": (6.0, 10.0, 14.0),
    "roll": (10.0, 20.0, 30.0),
    "height": (10.0, 20.0, 30.0),
    "speed": ("gnss", "smoothed", "log", "none"),
    "lever": (True, False),
}
WORST = {"sway": 1.5, "period": 6.0, "roll": 30.0, "height": 30.0}  # 1.64 m/s² of sway, the highest bridge
AFT_M = 12.0  # the bridge sensor's distance aft of the roll centre, m
SCORE_AFTER_S = 120.0
TURN_QUIET_S = 60.0  # "outside the turn": not in it, nor within this long after it ended
TURN_RAMP_S = 10.0  # the simulator's turn_ramp default


def cells(quick: bool) -> list[dict]:
    """The base cell, every other level of every factor alone, and the worst corners (every speed, lever or not)."""
    if quick:
        out = [dict(BASE)] + [{**BASE, "speed": s} for s in LEVELS["speed"][1:]] + [{**BASE, "lever": False}]
        return out + [{**WORST, "speed": "gnss", "lever": True}, {**WORST, "speed": "none", "lever": False}]
    out = [dict(BASE)]
    for factor, levels in LEVELS.items():
        out += [{**BASE, factor: v} for v in levels if v != BASE[factor]]
        if factor not in ("speed", "lever"):  # every level also without the lever arm (it is estimated then)
            out += [{**BASE, factor: v, "lever": False} for v in levels if v != BASE[factor]]
    out += [{**WORST, "speed": s, "lever": lv} for s in LEVELS["speed"] for lv in (True, False)]
    return out


def label(c: dict) -> str:
    diff = [f"{k} {c[k]:g}" for k in ("sway", "period", "roll", "height") if c[k] != BASE[k]]
    corner = all(c[k] == v for k, v in WORST.items())
    name = "worst corner" if corner else (", ".join(diff) if diff else "base")
    return f"{name}; {c['speed']}; {'lever arm' if c['lever'] else 'no lever arm'}"


def voyage(c: dict, seed: int, quick: bool):
    return simulate(
        "ship-at-sea",
        duration=180.0 if quick else 600.0,
        seed=seed,
        lever_arm=(-AFT_M, 0.0, -c["height"]),
        roll_significant_deg=c["roll"],
        sway_m=c["sway"],
        sway_period=c["period"],
        turn_start=40.0 if quick else 180.0,
        speed_source=c["speed"],
    )


def errors(roll: np.ndarray, pitch: np.ndarray, rec, keep: np.ndarray) -> dict:
    er, ep = (roll - rec["ref_roll"])[keep], (pitch - rec["ref_pitch"])[keep]
    return {
        "roll_rms": float(np.sqrt(np.mean(er**2))),
        "roll_max": float(np.abs(er).max()),
        "pitch_rms": float(np.sqrt(np.mean(ep**2))),
        "pitch_max": float(np.abs(ep).max()),
    }


def run_cell(job: tuple[dict, int, bool, dict]) -> dict:
    c, seed, quick, overrides = job
    rec = voyage(c, seed, quick)
    t = rec.time - rec.time[0]
    after = t >= SCORE_AFTER_S
    m = rec.meta  # the turn's span: its start, the heading change at its rate, one ramp (ref_rate_of_turn has the yaw)
    turn_end = m["turn_start_s"] + abs(m["turn_angle_deg"] / m["turn_rate_dps"]) + TURN_RAMP_S
    quiet = after & ((t < m["turn_start_s"]) | (t > turn_end + TURN_QUIET_S))
    prm = EkfParams(**overrides)
    lever = np.array(rec.meta["lever_arm_m"]) if c["lever"] else None
    speed = float(rec.meta["log_speed_mps"]) if c["speed"] == "log" else None  # `filter --speed`
    t0 = time.perf_counter()
    res = run_filter(rec, params=prm, lever_arm=lever, speed=speed)
    ours = res.recording
    out = {"cell": c, "seed": seed, "filter_s": time.perf_counter() - t0}
    out["imutool"] = errors(ours["roll"], ours["pitch"], rec, after)
    out["imutool"]["alarm"] = float(np.mean(ours["inconsistent"][after] > 0)) if "inconsistent" in ours.channels else 0
    out["imutool_quiet"] = errors(ours["roll"], ours["pitch"], rec, quiet) if quiet.any() else None
    try:
        from vqf import VQF, offlineVQF
    except ImportError:
        return out
    ts = float(np.median(np.diff(rec.time)))
    g, a, m = (np.ascontiguousarray(rec[k]) for k in ("gyro", "accel", "mag"))
    v = VQF(ts).updateBatch(g, a, m)
    for name, q in (
        ("VQF 6D", v["quat6D"]),
        ("VQF 9D", v["quat9D"]),
        ("offline VQF", offlineVQF(g, a, None, ts)["quat6D"]),
    ):
        r, p, _ = quat_to_euler(quat_multiply(np.broadcast_to(ENU2NED, q.shape), q))
        out[name] = errors(np.degrees(r), np.degrees(p), rec, after)
    return out


def fmt(runs: list[dict], key: str, what: str) -> str:
    vals = [r[key][what + "_rms"] for r in runs if r.get(key)]
    mx = [r[key][what + "_max"] for r in runs if r.get(key)]
    if not vals:
        return "–"
    worst = f" ({max(vals):.2f})" if len(vals) > 1 else ""
    return f"{np.mean(vals):.2f}{worst} / {max(mx):.2f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="3-minute voyages, 7 cells, one seed")
    ap.add_argument("--seeds", type=int, default=None, help="seeds 0..N-1 (default 3, 1 with --quick)")
    ap.add_argument("--jobs", type=int, default=2, help="processes (default 2)")
    ap.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help="EKF parameter override")
    args = ap.parse_args()
    overrides = {}
    for item in args.param:
        k, _, v = item.partition("=")
        overrides[k] = (
            type(getattr(EkfParams(), k))(v) if not isinstance(getattr(EkfParams(), k), bool) else v in ("1", "true")
        )
    seeds = range(args.seeds if args.seeds is not None else (1 if args.quick else 3))
    grid = cells(args.quick)
    jobs = [(c, s, args.quick, overrides) for c in grid for s in seeds]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs, mp_context=multiprocessing.get_context("fork")) as pool:
        results = list(pool.map(run_cell, jobs))
    by_cell = [[r for r in results if r["cell"] == c] for c in grid]
    dur = "3-minute" if args.quick else "10-minute"
    print(
        f"\n{dur} voyages, seeds {list(seeds)}, scored after {SCORE_AFTER_S:.0f} s; "
        f"EKF overrides {overrides or 'none'}; RMSE mean over seeds (worst seed) / max |error| of all seeds, deg; "
        "alarm = share of samples the self-check flags (worst seed); "
        f"'outside turns' = not turning, nor within {TURN_QUIET_S:.0f} s after a turn\n"
    )
    print(
        "| cell (sway m, period s, roll 2σ deg, bridge m; speed; lever arm) | imutool roll | imutool pitch | alarm "
        "| imutool roll outside turns | VQF 6D roll | VQF 9D roll | offline VQF roll | VQF 6D pitch |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for c, runs in zip(grid, by_cell, strict=True):
        alarm = max(r["imutool"]["alarm"] for r in runs)
        print(
            f"| {label(c)} | {fmt(runs, 'imutool', 'roll')} | {fmt(runs, 'imutool', 'pitch')} | {100 * alarm:.1f} % "
            f"| {fmt(runs, 'imutool_quiet', 'roll')} | {fmt(runs, 'VQF 6D', 'roll')} | {fmt(runs, 'VQF 9D', 'roll')} "
            f"| {fmt(runs, 'offline VQF', 'roll')} | {fmt(runs, 'VQF 6D', 'pitch')} |"
        )
    print("\nBy speed source and lever arm, over every cell and seed (roll RMSE mean / worst, max |error|, deg):\n")
    print(
        "| speed | lever arm | cells × seeds | imutool roll RMSE mean / worst | max | pitch max "
        "| VQF 6D roll RMSE mean / worst |"
    )
    print("|---|---|---|---|---|---|---|")
    for s in LEVELS["speed"]:
        for lv in (True, False):
            rs = [r for r in results if r["cell"]["speed"] == s and r["cell"]["lever"] == lv]
            if not rs:
                continue
            ro = [r["imutool"]["roll_rms"] for r in rs]
            vq = [r["VQF 6D"]["roll_rms"] for r in rs if "VQF 6D" in r]
            vqs = f"{np.mean(vq):.2f} / {max(vq):.2f}" if vq else "–"
            print(
                f"| {s} | {'given' if lv else 'not given'} | {len(rs)} | {np.mean(ro):.2f} / {max(ro):.2f} "
                f"| {max(r['imutool']['roll_max'] for r in rs):.2f} | {max(r['imutool']['pitch_max'] for r in rs):.2f} "
                f"| {vqs} |"
            )
    print(f"\n{len(jobs)} runs in {time.perf_counter() - t0:.0f} s on {args.jobs} processes")


if __name__ == "__main__":
    main()
