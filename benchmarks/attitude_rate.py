"""The EKF updating every sample against the defaults (updates every N samples, N from ``update_rate_hz``), in one
run, on the simulated ships: accuracy, the σ's consistency (NEES) and what N was used. BROAD's rows come from
``benchmarks/attitude_broad.py`` (the defaults) and ``--broad`` here (N = 1, 2, 3, 5, 10 on all 16 trials).

Usage::

    python benchmarks/attitude_rate.py            # ships (~1 min)
    python benchmarks/attitude_rate.py --broad    # + BROAD with N = 1, 2, 3, 5, 10 (needs ../shared/data)

Errors in degrees; ship-at-sea after the first minute; heading wrapped to ±180°.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from formats.frames import quat_to_euler, wrap_deg180  # noqa: E402
from imutool.attitude import EkfParams, run_ekf, zero_lag_smooth  # noqa: E402
from imutool.sim import simulate  # noqa: E402

CASES = {"every sample": EkfParams(update_every=1), "defaults": EkfParams()}


def rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.asarray(e) ** 2)))


def euler_deg(q: np.ndarray) -> list[np.ndarray]:
    return [np.degrees(x) for x in quat_to_euler(q)]


def ship_roll_scores(prm: EkfParams, recs: list) -> tuple[list[float], list[float]]:
    """Causal roll RMSE (deg) and roll + pitch NEES (after the first 10 %) on each ship-roll recording."""
    roll, nees = [], []
    for rec in recs:
        res, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], rec["mag"], prm)
        ro, pi, _ = euler_deg(res.q)
        sd = np.degrees(res.std)
        late = slice(len(ro) // 10, None)
        roll.append(rms(ro - rec["ref_roll"]))
        nees.append(
            float(((((ro - rec["ref_roll"]) / sd[:, 0]) ** 2 + ((pi - rec["ref_pitch"]) / sd[:, 1]) ** 2)[late]).mean())
        )
    return roll, nees


def ship_roll() -> None:
    rec = simulate("ship-roll", seed=1)
    for name, prm in CASES.items():
        res, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], rec["mag"], prm, keep_cov=True)
        sm = zero_lag_smooth(res, rec["gyro"], rec["accel"], rec["mag"], prm)
        out = []
        for r in (res, sm):
            ro, pi, he = euler_deg(r.q)
            out.append(
                f"{rms(ro - rec['ref_roll']):.3f} / {rms(pi - rec['ref_pitch']):.3f} / "
                f"{rms(wrap_deg180(he - rec['ref_heading'])):.3f}"
            )
        print(
            f"ship-roll seed 1, {name} (N = {res.summary['update_every']}): roll / pitch / heading RMSE "
            f"causal {out[0]}, smoother {out[1]}"
        )
    recs = [simulate("ship-roll", duration=90, seed=seed) for seed in range(8)]
    for name, prm in CASES.items():
        roll, nees = ship_roll_scores(prm, recs)
        print(
            f"ship-roll 90 s seeds 0-7, {name}: roll RMSE mean {np.mean(roll):.3f} worst {max(roll):.3f}; "
            f"NEES {min(nees):.2f}-{max(nees):.2f}, mean {np.mean(nees):.2f}"
        )


def gyrocompass(rec) -> np.ndarray:
    """A 1 Hz gyrocompass from the truth (0.3° noise, 0.1° resolution), interpolated onto the IMU rows (deg)."""
    t = rec.time - rec.time[0]
    idx = np.flatnonzero(np.diff(np.floor(t), prepend=-1) > 0)
    fix = np.round((rec["ref_heading"][idx] + np.random.default_rng(0).normal(0.0, 0.3, len(idx))) % 360, 1)
    return np.degrees(np.interp(rec.time, rec.time[idx], np.unwrap(np.radians(fix)))) % 360


def baselines(rec, after: np.ndarray) -> str:
    """Accelerometer-only tilt and offline VQF 6D (the `vqf` package, benchmark-only) on the same run."""
    a = rec["accel"]
    roll = np.degrees(np.arctan2(-a[:, 1], -a[:, 2]))  # FRD: the specific force reads −g on z at rest
    pitch = np.degrees(np.arctan2(a[:, 0], np.hypot(a[:, 1], a[:, 2])))
    rows = [("accelerometer-only", roll, pitch)]
    try:
        from vqf import offlineVQF

        from formats.frames import quat_multiply

        q = offlineVQF(
            np.ascontiguousarray(rec["gyro"]), np.ascontiguousarray(a), None, float(np.median(np.diff(rec.time)))
        )["quat6D"]
        enu2ned = np.array([0.0, np.sqrt(0.5), np.sqrt(0.5), 0.0])
        r, p, _ = euler_deg(quat_multiply(np.broadcast_to(enu2ned, q.shape), q))
        rows.append(("offline VQF 6D", r, p))
    except ImportError:
        rows.append(("offline VQF: not installed (pip install vqf)", roll * np.nan, pitch * np.nan))
    out = []
    for label, r, p in rows:
        er, ep = (r - rec["ref_roll"])[after], (p - rec["ref_pitch"])[after]
        out.append(f"{label}: {rms(er):.2f} / {rms(ep):.2f} (max {np.abs(er).max():.2f} / {np.abs(ep).max():.2f})")
    return "; ".join(out)


def ship_at_sea() -> None:
    for seed in (0, 1, 3):
        rec = simulate("ship-at-sea", duration=300, seed=seed)
        arm = np.array(rec.meta["lever_arm_m"])
        after = rec.time - rec.time[0] >= 60
        for name, prm in CASES.items():
            cells = []
            for label, lever, gnss, smooth, heading in (
                ("lever arm + SOG/COG", True, True, False, False),
                ("+ smoother", True, True, True, False),
                ("SOG/COG only", False, True, False, False),
                ("neither", False, False, False, False),
                ("gyrocompass, no mag", True, True, False, True),
            ):
                sog, cog = (rec["sog"], rec["cog"]) if gnss else (None, None)
                mag = None if heading else rec["mag"]
                res, _ = run_ekf(
                    rec.time,
                    rec["gyro"],
                    rec["accel"],
                    mag,
                    prm,
                    sog,
                    cog,
                    lever_arm=arm if lever else None,
                    keep_cov=smooth,
                    heading_deg=gyrocompass(rec) if heading else None,
                )
                if smooth:
                    res = zero_lag_smooth(res, rec["gyro"], rec["accel"], mag, prm, sog, cog, arm)
                ro, pi, he = euler_deg(res.q)
                er, ep = (ro - rec["ref_roll"])[after], (pi - rec["ref_pitch"])[after]
                eh = wrap_deg180(he - rec["ref_heading"])[after]
                cells.append(
                    f"{label}: {rms(er):.2f} / {rms(ep):.2f} (max {np.abs(er).max():.2f} / "
                    f"{np.abs(ep).max():.2f})" + (f", heading {rms(eh):.2f}" if heading else "")
                )
            print(
                f"ship-at-sea seed {seed}, {name} (N = {res.summary['update_every']}), roll / pitch RMS: "
                + "; ".join(cells)
            )
        print(f"ship-at-sea seed {seed}, baselines, roll / pitch RMS: " + baselines(rec, after))
    rec = simulate("turn", seed=1)
    for name, prm in CASES.items():
        res, _ = run_ekf(rec.time, rec["gyro"], rec["accel"], rec["mag"], prm, rec["sog"], rec["cog"])
        err = (euler_deg(res.q)[0] - rec["ref_roll"])[rec.time - rec.time[0] > 40]
        print(f"turn seed 1, {name}: roll RMSE after 40 s {rms(err):.3f}, max {np.abs(err).max():.3f}")


def broad() -> None:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import attitude_broad

    trials = attitude_broad.load_trials()
    if not trials:
        print(f"BROAD: no trials in {attitude_broad.BROAD}")
        return
    for n in (1, 2, 3, 5, 10):
        sc = [attitude_broad.run_ours(d, EkfParams(update_every=n), False)[0] for d in trials.values()]
        tot, inc = np.array(sc).T
        print(
            f"BROAD {len(sc)} trials, N = {n}: causal total / inclination mean {tot.mean():.3f} / "
            f"{inc.mean():.4f}, worst {tot.max():.2f} / {inc.max():.2f}"
        )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--broad", action="store_true", help="also BROAD with N = 1, 2, 3, 5, 10")
    a = ap.parse_args()
    ship_roll()
    ship_at_sea()
    if a.broad:
        broad()


if __name__ == "__main__":
    main()
