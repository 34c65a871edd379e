"""How the accelerometer low-pass's defaults were chosen (docs/attitude.md, "The low-pass: a Butterworth"): the
shape's leakage floor on BROAD, and every candidate on BROAD at three rates and on the simulated ships, with the
rule that picks one.

Usage::

    pip install vqf                             # benchmark-only: never a dependency of the filter
    python benchmarks/attitude_defaults.py      # both tables (~3 min on 2 cores)
    python benchmarks/attitude_defaults.py --leakage

Leakage floor: the specific force rotated into the world frame with the *true* attitude, low-passed (two
first-order stages of τ/2, as before 2026-11-27, or the second-order Butterworth of delay τ, as now) and its
inclination from the vertical: what a filter that followed its low-pass exactly would still get wrong from
translational acceleration alone (RMS over BROAD's movement rows, deg).

Candidates: ``accel_lp_tau`` × ``gyro_scale_noise`` × ``accel_noise_gain`` below, everything else at its default.
Rule (stated before it was applied): the σ must not be under-stated (roll/pitch NEES ≤ 2 on each of eight 90-s
ship-roll seeds) and ship-roll's roll RMSE ≤ 0.4° (mean of the eight); among those, the lowest mean over the 16
trials at 286, 95 and 48 Hz of (total/VQF + inclination/VQF)/2, VQF run on the same data in this script.
"""

from __future__ import annotations

import argparse
import itertools
import multiprocessing
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.signal import butter, lfilter

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from attitude_broad import BROAD, at_rate, load_trials, run_vqf, score  # noqa: E402
from attitude_rate import euler_deg, ship_roll_scores  # noqa: E402

from formats.frames import quat_to_matrix  # noqa: E402
from imutool.attitude import EkfParams, run_ekf  # noqa: E402
from imutool.sim import simulate  # noqa: E402

GRID = {"accel_lp_tau": (2.5, 3.0), "gyro_scale_noise": (0.003, 0.006, 0.01), "accel_noise_gain": (2.8, 3.4, 4.0)}
RATES = (1, 3, 6)  # BROAD's 286 Hz, averaged by 3 (95 Hz) and by 6 (48 Hz)
_DATA: dict = {}  # the worker processes (fork) read the trials and the simulations from here


def leakage() -> None:
    print("Leakage floor, inclination of the low-passed world-frame force (true attitude), RMS deg:")
    print("| trial | two stages τ 3 s | Butterworth τ 3 s | Butterworth τ 2.5 s |\n|---|---|---|---|")
    rows = []
    for name, d in load_trials().items():
        ok = np.all(np.isfinite(d["q"]), axis=1) & np.all(np.isfinite(d["a"]), axis=1)
        q = np.where(ok[:, None], d["q"], [1.0, 0.0, 0.0, 0.0])
        fw = np.einsum("nij,nj->ni", quat_to_matrix(q), np.nan_to_num(d["a"]))
        held = np.maximum.accumulate(np.where(ok, np.arange(len(ok)), 0))  # a bad row holds the last good one
        fw = fw[held]
        f0, x = fw[0], fw - fw[0]  # the filters start at the first row's force: run them on the change
        ts = float(np.median(np.diff(d["t"])))
        al = ts / (1.5 + ts)  # one stage of τ/2 = 1.5 s
        cells = [lfilter([al], [1, al - 1], lfilter([al], [1, al - 1], x, axis=0), axis=0)]
        for tau in (3.0, 2.5):
            b, a = butter(2, np.sqrt(2) / (2 * np.pi * tau) * 2 * ts)  # cut-off √2/τ rad/s, as the filter's
            cells.append(lfilter(b, a, x, axis=0))
        m = d["mv"] & ok
        r = []
        for lp in cells:
            f = lp + f0
            incl = np.degrees(np.arccos(np.clip(-f[:, 2] / np.linalg.norm(f, axis=1), -1.0, 1.0)))
            r.append(float(np.sqrt(np.mean(incl[m] ** 2))))
        rows.append(r)
        print(f"| {name} | " + " | ".join(f"{x:.3f}" for x in r) + " |")
    print("| **mean** | " + " | ".join(f"{x:.3f}" for x in np.mean(rows, axis=0)) + " |")


def _score_candidate(kw: dict) -> dict:
    """One candidate in a worker: BROAD mean (total, inclination) per rate, ship-roll and ship-at-sea figures."""
    prm = replace(EkfParams(), **kw)
    out = dict(kw)
    for k in RATES:
        r = np.array([score(run_ekf(d["t"], d["g"], d["a"], d["m"], prm)[0].q, d) for d in _DATA[k].values()])
        out[k] = r.mean(axis=0)
    roll, nees = ship_roll_scores(prm, _DATA["ship-roll"])
    out["ship_roll"], out["ship_roll_worst"], out["nees"] = np.mean(roll), max(roll), (min(nees), max(nees))
    sea = []
    for rec in _DATA["ship-at-sea"]:
        after = rec.time - rec.time[0] >= 60
        res, _ = run_ekf(
            rec.time,
            rec["gyro"],
            rec["accel"],
            rec["mag"],
            prm,
            rec["sog"],
            rec["cog"],
            lever_arm=np.array(rec.meta["lever_arm_m"]),
        )
        err = (euler_deg(res.q)[0] - rec["ref_roll"])[after]
        sea.append((np.sqrt(np.mean(err**2)), np.abs(err).max()))
    out["sea"], out["sea_max"] = float(np.mean([s[0] for s in sea])), float(max(s[1] for s in sea))
    return out


def choose(jobs: int) -> None:
    trials = load_trials()
    _DATA.update({k: ({n: at_rate(d, k) for n, d in trials.items()} if k > 1 else trials) for k in RATES})
    _DATA["ship-roll"] = [simulate("ship-roll", duration=90, seed=s) for s in range(8)]
    _DATA["ship-at-sea"] = [simulate("ship-at-sea", duration=300, seed=s) for s in (0, 1, 3)]
    vqf = {k: np.array([run_vqf(d)[0] for d in _DATA[k].values()]).mean(axis=0) for k in RATES}
    cands = [dict(zip(GRID, v, strict=True)) for v in itertools.product(*GRID.values())]
    with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("fork")) as pool:
        rows = list(pool.map(_score_candidate, cands))
    print(
        "\nVQF's mean total / inclination: "
        + ", ".join(f"{286 / k:.0f} Hz {vqf[k][0]:.3f} / {vqf[k][1]:.4f}" for k in RATES)
    )
    print(
        "| τ s | gyro_scale_noise | accel_noise_gain | 286 Hz | 95 Hz | 48 Hz | score | ship-roll mean / worst |"
        " NEES | ship-at-sea roll RMS / max | kept |\n|" + "---|" * 11
    )
    best, best_score = None, np.inf
    for r in rows:
        rel = np.mean([(r[k][0] / vqf[k][0] + r[k][1] / vqf[k][1]) / 2 for k in RATES])
        kept = r["nees"][1] <= 2.0 and r["ship_roll"] <= 0.4
        if kept and rel < best_score:
            best, best_score = r, rel
        print(
            f"| {r['accel_lp_tau']} | {r['gyro_scale_noise']} | {r['accel_noise_gain']} | "
            + " | ".join(f"{r[k][0]:.3f} / {r[k][1]:.4f}" for k in RATES)
            + f" | {rel:.4f} | {r['ship_roll']:.3f} / {r['ship_roll_worst']:.3f} | "
            f"{r['nees'][0]:.2f}–{r['nees'][1]:.2f} | {r['sea']:.3f} / {r['sea_max']:.2f} | "
            f"{'yes' if kept else 'no'} |"
        )
    if best is not None:
        print("chosen: " + ", ".join(f"{k} = {best[k]}" for k in GRID) + f" (score {best_score:.4f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--leakage", action="store_true", help="the leakage floor only")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    args = ap.parse_args()
    if not BROAD.is_dir():
        sys.exit(f"BROAD trials not found at {BROAD} (set IMUTOOL_SHARED_DATA)")
    leakage()
    if not args.leakage:
        choose(args.jobs)


if __name__ == "__main__":
    main()
