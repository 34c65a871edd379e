"""The MRU grid of issue 50: a bridge sensor on a hard voyage nobody tuned on, the axes the ship grid lacks.

Base cell (the issue's voyage): a bridge sensor 20 m above and 12 m aft of the roll centre, irregular roll to a
significant 20°, heave ±2 m at 7.5 s, 1 m of sway at 10 s, a 360° turn at 3 °/s and 8 m/s, a MEMS accelerometer
with a 5 mg bias on each axis (random signs), a gyro whose bias wanders (0.002 °/s/√s), a 1 Hz receiver whose
hull velocity has 3 cm/s of noise and is held between fixes (``vel_n``/``vel_e``), the lever arm given.

Axes (one at a time around the base): accelerometer bias 0 / 2 / **5** mg; heave 0 / 1 / **2** / 3 m; GNSS velocity
noise 1 / **3** / 5 cm/s; GNSS rate **1** / 5 / 10 Hz; fixes **held** or NaN-separated; gyro bias instability good
(0.0005 °/s/√s) / **0.002** / poor (0.01); a voyage without any turn; the receiver's track-smoothed SOG/COG; no
GNSS (the no-GNSS path, for the regression check). The filter is told what a user states: the receiver's σ and
rate, and the gyro's bias instability (``aided_gyro_bias_rw``, the sensor's figure) — but in the "told False"
cells, which leave it at its default (0.0023 °/s/√s).

Scored: roll and pitch RMSE and max |error| (deg) after the end of the first turn (and one ramp); before the
turn (from 60 s), the RMSE and the share of samples with |error| ≤ 2σ; "2σ" = that share over every row from 60 s
(roll and pitch pooled; the goal is 90–98 %); the accelerometer bias's error at the end (mg, x/y/z), where the
output has it.

Usage::

    python benchmarks/attitude_mru.py --quick      # 5-minute voyages (turn from 90 s), 1 seed
    python benchmarks/attitude_mru.py              # 10-minute voyages (turn from 180 s), seeds 0-2
    python benchmarks/attitude_mru.py --speed      # samples/s of the filter with and without GNSS velocity
    python benchmarks/attitude_mru.py --seeds 10 --factor heave   # base + one axis's cells, seeds 0-9
    python benchmarks/attitude_mru.py --limit      # the idealised limit of the accelerometer bias (below)

``--limit``: the information limit of the accelerometer bias in one turn, from an exact linear model of a level
platform (horizontal errors only: velocity, tilt, gyro bias, accelerometer bias; δv̇ = (g + heave's acceleration)
J ψ + R b_a, ψ̇ = −R δb_g, the gyro bias a random walk of q, velocity fixes with σ_v): the Kalman filter of that
model holds the Cramér–Rao bound, which its final σ of b_a is. Beside it the rough estimate from the Brownian
bridge of the gyro bias inside the turn, g q √(π/6) Ω^−1.5 (docs/attitude.md, "The limit").
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

from imutool.attitude import EkfParams  # noqa: E402
from imutool.filtering import run_filter  # noqa: E402
from imutool.sim import simulate  # noqa: E402

G = 9.80665
BASE = {
    "bias_mg": 5.0,
    "heave": 2.0,
    "vnoise": 0.03,
    "rate": 1.0,
    "fixes": "held",
    "gyro_rw": 0.002,
    "turn": True,
    "speed": "gnss",
    "told": True,
}
LEVELS = {
    "bias_mg": (0.0, 2.0),
    "heave": (0.0, 1.0, 3.0),
    "vnoise": (0.01, 0.05),
    "rate": (5.0, 10.0),
    "fixes": ("nan",),
    "gyro_rw": (0.0005, 0.01),
    "turn": (False,),
    "speed": ("smoothed", "none"),
}
QUICK = ("bias_mg", "turn", "speed")
START_S = 60.0  # scored from here (the filter's start-up before)
TURN_RAMP_S = 10.0


def cells(quick: bool, factors: list[str] | None = None) -> list[dict]:
    out = [dict(BASE)]
    for factor, levels in LEVELS.items():
        if (quick and factor not in QUICK) or (factors and factor not in factors):
            continue
        out += [{**BASE, factor: v} for v in levels]
    if not quick and (not factors or "told" in factors):  # the gyro's bias instability not told (the default
        # aided_gyro_bias_rw, 0.0023 °/s/√s)
        out += [{**BASE, "gyro_rw": g, "told": False} for g in (0.0005, 0.01)]
    return out


def label(c: dict) -> str:
    diff = [f"{k} {c[k]}" for k in BASE if c[k] != BASE[k]]
    return ", ".join(diff) if diff else "base (the issue's voyage)"


def voyage(c: dict, seed: int, quick: bool):
    rng = np.random.default_rng([seed, 50])
    rec = simulate(
        "ship-at-sea",
        duration=300.0 if quick else 600.0,
        seed=seed,
        lever_arm=(-12.0, 0.0, -20.0),
        roll_significant_deg=20.0,
        sway_m=1.0,
        sway_period=10.0,
        heave_m=c["heave"],
        heave_period=7.5,
        turn_start=90.0 if quick else 180.0,
        turn_angle_deg=360.0 if c["turn"] else 0.0,
        accel_bias_mg=0.0,
        gyro_bias_rw_deg_s=c["gyro_rw"],
        gnss_rate_hz=c["rate"],
        gnss_vel_noise_mps=c["vnoise"],
        speed_source=c["speed"],
        gnss_columns="vel" if c["speed"] == "gnss" else "sog_cog",
    )
    # a bias of exactly bias_mg on each axis, random signs (the simulator draws its size uniformly)
    bias = rng.choice([-1.0, 1.0], 3) * c["bias_mg"] * 1e-3 * G
    rec.channels["accel"] = rec["accel"] + bias
    rec.meta["accel_bias_m_s2"] = bias.tolist()
    if c["fixes"] == "nan" and "vel_n" in rec.channels:
        vn = rec["vel_n"]
        start = np.concatenate([[True], np.diff(vn) != 0])
        for k in ("vel_n", "vel_e"):
            rec.channels[k] = np.where(start, rec[k], np.nan)
    return rec


def run_cell(job: tuple[dict, int, bool, dict]) -> dict:
    c, seed, quick, overrides = job
    rec = voyage(c, seed, quick)
    t = rec.time - rec.time[0]
    m = rec.meta
    turn_end = m["turn_start_s"] + abs(360.0 / m["turn_rate_dps"]) + TURN_RAMP_S if c["turn"] else np.inf
    t0 = time.perf_counter()
    told = {"aided_gyro_bias_rw": float(np.radians(c["gyro_rw"]))} if c["told"] else {}
    # the receiver's class and rate are stated (gnss_velocity_noise, gnss_min_interval), and the gyro's bias
    # instability (aided_gyro_bias_rw, the sensor's figure) but in the "told False" cells
    rx = {"gnss_velocity_noise": max(c["vnoise"], 0.01), "gnss_min_interval": 0.5 / c["rate"]}
    prm = EkfParams(**{**rx, **told, **overrides})
    res = run_filter(rec, params=prm, lever_arm=np.array(m["lever_arm_m"]))
    out = res.recording
    er, ep = out["roll"] - rec["ref_roll"], out["pitch"] - rec["ref_pitch"]
    sr, sp = out["roll_std"], out["pitch_std"]
    scored = t >= START_S
    after = t > turn_end
    before = scored & (t < m["turn_start_s"]) if c["turn"] else scored
    r = {"cell": c, "seed": seed, "filter_s": time.perf_counter() - t0}
    for name, sel in (("after", after), ("before", before)):
        if sel.any():
            r[name] = {
                "roll_rms": float(np.sqrt(np.mean(er[sel] ** 2))),
                "roll_max": float(np.abs(er[sel]).max()),
                "pitch_rms": float(np.sqrt(np.mean(ep[sel] ** 2))),
                "pitch_max": float(np.abs(ep[sel]).max()),
                "cover": float(
                    np.mean(np.concatenate([np.abs(er[sel]) <= 2 * sr[sel], np.abs(ep[sel]) <= 2 * sp[sel]]))
                ),
                "roll_sigma": float(np.nanmean(sr[sel])),
                "pitch_sigma": float(np.nanmean(sp[sel])),
            }
    r["cover"] = float(
        np.mean(np.concatenate([np.abs(er[scored]) <= 2 * sr[scored], np.abs(ep[scored]) <= 2 * sp[scored]]))
    )
    r["ratio"] = res.summary.get("aided", {}).get("velocity_innovation_ratio")
    if "accel_bias" in out.channels:
        est = out["accel_bias"][-1]
        r["bias_err_mg"] = (np.abs(est - np.array(m["accel_bias_m_s2"])) / G * 1e3).tolist()
        r["bias_std_mg"] = (out["accel_bias_std"][-1] / G * 1e3).tolist()
    return r


def fmt(runs: list[dict], part: str, what: str) -> str:
    v = [x[part][what + "_rms"] for x in runs if part in x]
    mx = [x[part][what + "_max"] for x in runs if part in x]
    if not v:
        return "–"
    worst = f" ({max(v):.3f})" if len(v) > 1 else ""
    return f"{np.mean(v):.3f}{worst} / {max(mx):.2f}"


def level_limit(
    q_deg: float = 0.002,
    turn_dps: float = 3.0,
    sigma_v: float = 0.03,
    rate_hz: float = 1.0,
    heave_m: float = 0.0,
    heave_period: float = 7.5,
    before: float = 180.0,
    after: float = 290.0,
    arw_deg: float = 0.005,
    dt: float = 0.1,
) -> float:
    """The accelerometer bias's σ (mg) after a 360° turn at ``turn_dps`` on a level platform (module docstring,
    ``--limit``): q the gyro's rate random walk (°/s/√s), arw its white noise (°/s/√Hz), a sinusoidal heave of
    ``heave_m`` (amplitude, m) modulating the vertical force."""
    q, om, arw = np.radians(q_deg), np.radians(turn_dps), np.radians(arw_deg)
    span = 2 * np.pi / om
    p = np.diag([sigma_v**2] * 2 + [np.radians(1.0) ** 2] * 2 + [0.002**2] * 2 + [0.05**2] * 2)
    j = np.array([[0.0, -1.0], [1.0, 0.0]])
    qd = np.zeros((8, 8))
    qd[2:4, 2:4] = np.eye(2) * arw**2 * dt
    qd[4:6, 4:6] = np.eye(2) * q**2 * dt
    h = np.zeros((2, 8))
    h[:, :2] = np.eye(2)
    every = max(1, int(round(1.0 / (rate_hz * dt))))
    for k, t in enumerate(np.arange(0.0, before + span + after, dt)):
        chi = om * np.clip(t - before, 0.0, span)
        rz = np.array([[np.cos(chi), -np.sin(chi)], [np.sin(chi), np.cos(chi)]])
        w = 2 * np.pi / heave_period
        f = np.zeros((8, 8))
        f[0:2, 2:4] = (G + heave_m * w**2 * np.sin(w * t)) * j
        f[0:2, 6:8] = rz
        f[2:4, 4:6] = -rz
        phi = np.eye(8) + f * dt + f @ f * dt**2 / 2
        p = phi @ p @ phi.T + qd
        if k % every == 0:
            s = h @ p @ h.T + np.eye(2) * sigma_v**2
            gain = p @ h.T @ np.linalg.inv(s)
            p = (np.eye(8) - gain @ h) @ p
    return float(np.sqrt(p[6, 6]) / G * 1e3)


def limits() -> None:
    print("| gyro q °/s/√s | turn °/s | σ_v m/s | fixes Hz | heave m | limit mg | bridge estimate mg |")
    print("|---|---|---|---|---|---|---|")
    rows = [
        (0.002, 3.0, 0.03, 1.0, 0.0),
        (0.002, 3.0, 0.038, 1.0, 0.0),
        (0.002, 3.0, 0.001, 1.0, 0.0),
        (0.002, 3.0, 0.03, 10.0, 0.0),
        (0.002, 3.0, 0.05, 1.0, 0.0),
        (0.002, 3.0, 0.038, 1.0, 1.0),
        (0.002, 3.0, 0.038, 1.0, 2.0),
        (0.0005, 3.0, 0.03, 1.0, 0.0),
        (0.01, 3.0, 0.03, 1.0, 0.0),
        (0.002, 1.5, 0.03, 1.0, 0.0),
        (0.002, 6.0, 0.03, 1.0, 0.0),
    ]
    for q, om, sv, f, hv in rows:
        bridge = np.radians(q) * np.sqrt(np.pi / 6) * np.radians(om) ** -1.5 * 1e3
        print(f"| {q} | {om} | {sv} | {f:g} | {hv:g} | {level_limit(q, om, sv, f, hv):.2f} | {bridge:.2f} |")


def speed() -> None:
    from imutool.attitude import run_ekf
    from imutool.attitude.recording import gnss_inputs

    rec = simulate("ship-at-sea", duration=5000.0, seed=0, rate_hz=200.0, gnss_columns="vel", turn_start=300.0)
    t, g, a, mg = rec.time, rec["gyro"], rec["accel"], rec["mag"]
    _, _, vel = gnss_inputs(rec)
    lever = np.array(rec.meta["lever_arm_m"])
    for label_, kw in (("no GNSS", {}), ("GNSS velocity", {"velocity_ne": vel})):
        small = {k: v[:2000] for k, v in kw.items()}
        run_ekf(t[:2000], g[:2000], a[:2000], mg[:2000], lever_arm=lever, **small)
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            run_ekf(t, g, a, mg, lever_arm=lever, **kw)
            best = min(best, time.perf_counter() - t0)
        print(f"run_ekf, {label_}: {len(t) / best / 1e6:.2f} M samples/s ({len(t)} samples, best of 3)")
    from imutool.attitude.aided import run_aided

    res, _ = run_ekf(t, g, a, mg, lever_arm=lever, velocity_ne=vel)
    prm = EkfParams()
    run_aided(t[:2000], g[:2000], a[:2000], vel[:2000], res.q[:2000], res.bias[:2000], res.std[:2000], prm, lever)
    run_aided(
        t[:2000], g[:2000], a[:2000], vel[:2000], res.q[:2000], res.bias[:2000], res.std[:2000], prm, lever, smooth=True
    )
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        run_aided(t, g, a, vel, res.q, res.bias, res.std, prm, lever, smooth=True)
        best = min(best, time.perf_counter() - t0)
    ekf = best
    print(f"run_aided (the second pass, smoothed): {len(t) / best / 1e6:.2f} M samples/s")
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        r, _ = run_ekf(t, g, a, mg, lever_arm=lever, velocity_ne=vel)
        run_aided(t, g, a, vel, r.q, r.bias, r.std, prm, lever, smooth=True)
        best = min(best, time.perf_counter() - t0)
    print(f"EKF + aided pass with GNSS velocity: {len(t) / best / 1e6:.2f} M samples/s (aided alone {ekf:.3f} s)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--seeds", type=int, default=None)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--speed", action="store_true")
    ap.add_argument("--limit", action="store_true", help="the idealised limit of the accelerometer bias")
    ap.add_argument("--factor", action="append", default=[], help="only the base and this axis's cells (repeat)")
    ap.add_argument("--param", action="append", default=[], metavar="NAME=VALUE")
    args = ap.parse_args()
    if args.speed:
        speed()
        return
    if args.limit:
        limits()
        return
    overrides = {}
    for item in args.param:
        k, _, v = item.partition("=")
        d = getattr(EkfParams(), k)
        overrides[k] = v in ("1", "true") if isinstance(d, bool) else type(d)(v)
    seeds = range(args.seeds if args.seeds is not None else (1 if args.quick else 3))
    grid = cells(args.quick, args.factor)
    jobs = [(c, s, args.quick, overrides) for c in grid for s in seeds]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs, mp_context=multiprocessing.get_context("fork")) as pool:
        results = list(pool.map(run_cell, jobs))
    print(
        f"\n{'5' if args.quick else '10'}-minute voyages, seeds {list(seeds)}; RMSE mean (worst seed) / max |error|, "
        "deg; 2σ = share of |error| ≤ 2σ from 60 s (roll and pitch); bias error at the end, mg (worst seed)\n"
    )
    print(
        "| cell | roll after turn | pitch after turn | roll before turn | 2σ before | 2σ all | bias error x/y/z mg "
        "| bias σ x/y/z mg | σ roll / pitch after | innovation ratio |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for c in grid:
        runs = [r for r in results if r["cell"] == c]
        cb = [r["before"]["cover"] for r in runs if "before" in r]
        be = [r["bias_err_mg"] for r in runs if "bias_err_mg" in r]
        bes = "/".join(f"{x:.2f}" for x in np.max(be, axis=0)) if be else "–"
        bs = [r["bias_std_mg"] for r in runs if "bias_std_mg" in r]
        bss = "/".join(f"{x:.2f}" for x in np.mean(bs, axis=0)) if bs else "–"
        before = f"{100 * min(cb):.0f} %" if cb else "–"
        sa = [(r["after"]["roll_sigma"], r["after"]["pitch_sigma"]) for r in runs if "after" in r]
        sig = "{:.3f} / {:.3f}".format(*np.mean(sa, axis=0)) if sa else "–"
        cover = f"{100 * min(r['cover'] for r in runs):.0f}–{100 * max(r['cover'] for r in runs):.0f} %"
        print(
            f"| {label(c)} | {fmt(runs, 'after', 'roll')} | {fmt(runs, 'after', 'pitch')} "
            f"| {fmt(runs, 'before', 'roll')} | {before} | {cover} | {bes} | {bss} | {sig} "
            f"| {max(r['ratio'] or 0 for r in runs):.2f} |"
        )
    print(f"\n{len(jobs)} runs in {time.perf_counter() - t0:.0f} s on {args.jobs} processes")


if __name__ == "__main__":
    main()
