"""The 16 BROAD trials changed the ways the next recording will differ from them, the defaults beside VQF in the same
run: another output rate, an uncalibrated gyro, a noisier sensor, a slower magnetometer, another mounting, no
magnetometer, an uncalibrated magnetometer, a recording started beside steel. A default that wins on the 16 as
recorded and loses on these has been tuned to one sensor.

Usage::

    pip install vqf                          # benchmark-only: never a dependency of the filter
    python benchmarks/attitude_stress.py     # 2–4 min

Each case is applied to every trial with its own seeded random numbers (trial i: seed 100 + i), so a run is
reproducible. Scoring as ``benchmarks/attitude_broad.py`` (BROAD's metric over the movement rows); "over ceiling"
counts trials above max(2 × VQF, VQF + 2°) in total or inclination. The column "before" is the defaults with the
three values they had before the accelerometer's low-pass became a Butterworth (``accel_lp_tau`` 3 s,
``gyro_scale_noise`` 0.003, ``accel_noise_gain`` 2.8), on this release's filter: what the new values do. What the
release before did (two first-order stages) is this script run in a checkout of that commit (docs/attitude.md).
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from attitude_broad import BROAD, ENU2NED, at_rate, limit, load_trials, score  # noqa: E402

from formats.frames import matrix_to_quat, quat_conjugate, quat_multiply, quat_to_matrix  # noqa: E402
from imutool.attitude import EkfParams, run_ekf  # noqa: E402

BEFORE = replace(EkfParams(), accel_lp_tau=3.0, gyro_scale_noise=0.003, accel_noise_gain=2.8)


def rotated_mounting(d: dict, rng: np.random.Generator) -> dict:
    """The sensor mounted in another orientation: every vector in the new body frame, the truth with it."""
    q = rng.normal(size=4)
    c = quat_to_matrix((q / np.linalg.norm(q))[None])[0]  # old body → new body
    out = dict(d, **{k: d[k] @ c.T for k in "gam"})
    qc = np.broadcast_to(quat_conjugate(matrix_to_quat(c[None]))[0], d["q"].shape)
    out["q"] = quat_multiply(d["q"], qc)
    return out


def gyro_bias(d: dict, rng: np.random.Generator, dps: float) -> dict:
    """A constant gyro bias of ``dps`` °/s in a random direction (an uncalibrated MEMS gyro: ±1–3 °/s)."""
    v = rng.normal(size=3)
    return dict(d, g=d["g"] + np.radians(dps) * v / np.linalg.norm(v))


def white_noise(d: dict, rng: np.random.Generator, gyro: float, accel: float, mag: float) -> dict:
    """White noise per sample added: gyro rad/s, accel m/s², mag µT (a consumer IMU: 0.01, 0.08, 1)."""
    return dict(
        d,
        g=d["g"] + rng.normal(0, gyro, d["g"].shape),
        a=d["a"] + rng.normal(0, accel, d["a"].shape),
        m=d["m"] + rng.normal(0, mag, d["m"].shape),
    )


def slow_magnetometer(d: dict, k: int) -> dict:
    """A magnetometer at 1/k of the IMU rate: NaN rows between its samples (VQF is given them held)."""
    m = np.full_like(d["m"], np.nan)
    m[::k] = d["m"][::k]
    return dict(d, m=m)


def hard_iron(d: dict, rng: np.random.Generator, ut: float) -> dict:
    """A magnetometer not calibrated: a body-fixed offset of ``ut`` µT in a random direction (a part's own hard
    iron, or steel fixed near it): the field's norm and dip then change with the orientation."""
    v = rng.normal(size=3)
    return dict(d, m=d["m"] + ut * v / np.linalg.norm(v))


def rows_lost(d: dict, rng: np.random.Generator, share: float) -> dict:
    """A share of the rows lost at random (a serial link dropping records): every column loses the same rows."""
    keep = rng.random(len(d["t"])) >= share
    return {k: v[keep] for k, v in d.items()}


def start_beside_steel(d: dict, offset_ut: tuple[float, float, float], seconds: float = 10.0) -> dict:
    """The recording started beside steel: a world-fixed field ``offset_ut`` (µT, NED) added to the magnetometer
    over the first ``seconds`` (the sensor is still then; BROAD's motion starts after 27–46 s). (0, 20, 0) makes
    the start's field 10 % strong and its dip 11° flat (the true field after it sits at the gates' edge) and starts
    the heading ≈ 50° off; (15, 0, −10) keeps the norm and turns the dip 24° flat (the gates reject the true field
    after it; the heading starts right)."""
    n0 = int(np.searchsorted(d["t"], d["t"][0] + seconds))
    q = d["q"][:n0].copy()
    ok = np.all(np.isfinite(q), axis=1)
    q[~ok] = d["q"][np.flatnonzero(np.all(np.isfinite(d["q"]), axis=1))[0]]  # truth lost: its first valid row
    m = d["m"].copy()
    m[:n0] += np.einsum("nji,j->ni", quat_to_matrix(q), np.asarray(offset_ut, float))
    return dict(d, m=m)


CASES = {
    "as recorded (286 Hz)": lambda d, r: d,
    "averaged to 95 Hz": lambda d, r: at_rate(d, 3),
    "averaged to 48 Hz": lambda d, r: at_rate(d, 6),
    "mounting rotated": rotated_mounting,
    "gyro bias 0.5 °/s": lambda d, r: gyro_bias(d, r, 0.5),
    "gyro bias 2 °/s": lambda d, r: gyro_bias(d, r, 2.0),
    "noise: gyro 0.01 rad/s": lambda d, r: white_noise(d, r, 0.01, 0.0, 0.0),
    "noise: accel 0.08 m/s²": lambda d, r: white_noise(d, r, 0.0, 0.08, 0.0),
    "noise: mag 1 µT": lambda d, r: white_noise(d, r, 0.0, 0.0, 1.0),
    "noise: all three": lambda d, r: white_noise(d, r, 0.01, 0.08, 1.0),
    "magnetometer at 1/4 rate": lambda d, r: slow_magnetometer(d, 4),
    "magnetometer uncalibrated: 8 µT hard iron": lambda d, r: hard_iron(d, r, 8.0),
    "no magnetometer (6D)": lambda d, r: dict(d, m=np.full_like(d["m"], np.nan)),
    "1 % of rows lost (VQF assumes a fixed step)": lambda d, r: rows_lost(d, r, 0.01),
    "started beside steel: 20 µT east for 10 s": lambda d, r: start_beside_steel(d, (0.0, 20.0, 0.0)),
    "started beside steel: 15 µT north, 10 µT up for 10 s": lambda d, r: start_beside_steel(d, (15.0, 0.0, -10.0)),
}


def held(m: np.ndarray) -> np.ndarray:
    """NaN rows filled with the last finite row (what a VQF user would feed)."""
    idx = np.where(np.isfinite(m).all(axis=1), np.arange(len(m)), 0)
    return m[np.maximum.accumulate(idx)]


def vqf_causal(d: dict, six_d: bool) -> tuple[float, float]:
    from vqf import VQF

    ts = float(np.median(np.diff(d["t"])))
    g, a, m = (np.ascontiguousarray(x) for x in (d["g"], d["a"], held(d["m"])))
    out = VQF(ts).updateBatch(g, a) if six_d else VQF(ts).updateBatch(g, a, m)
    q = out["quat6D"] if six_d else out["quat9D"]
    return score(quat_multiply(np.broadcast_to(ENU2NED, q.shape), q), d)


def main() -> None:
    if not BROAD.is_dir():
        sys.exit(f"BROAD trials not found at {BROAD} (set IMUTOOL_SHARED_DATA)")
    t0 = time.perf_counter()
    trials = load_trials()
    print(f"{len(trials)} BROAD trials from {BROAD}; load average {os.getloadavg()[0]:.1f}")
    print(
        "\nCausal RMSE total / inclination (deg), mean over the 16 trials (worst trial in brackets); 6D: "
        "inclination only (no heading reference)"
    )
    print("| case | imutool defaults | before | VQF | over ceiling (imutool / before) |\n|---|---|---|---|---|")
    for name, change in CASES.items():
        six_d = "6D" in name
        rows = []
        for i, d in enumerate(trials.values()):
            dd = change(d, np.random.default_rng(100 + i))
            mag = None if six_d else dd["m"]
            ours = score(run_ekf(dd["t"], dd["g"], dd["a"], mag, EkfParams())[0].q, dd)
            before = score(run_ekf(dd["t"], dd["g"], dd["a"], mag, BEFORE)[0].q, dd)
            rows.append([*ours, *before, *vqf_causal(dd, six_d)])
        r = np.array(rows)
        lim = np.array([[limit(v) for v in row[4:6]] for row in r])
        over = [int(np.sum((r[:, j : j + 2] > lim).any(axis=1))) for j in (0, 2)]
        if six_d:
            cells = [f"– / {r[:, j + 1].mean():.3f} (– / {r[:, j + 1].max():.2f})" for j in (0, 2, 4)]
            over = [int(np.sum(r[:, j + 1] > lim[:, 1])) for j in (0, 2)]
        else:
            cells = [
                f"{r[:, j].mean():.2f} / {r[:, j + 1].mean():.3f} ({r[:, j].max():.2f} / {r[:, j + 1].max():.2f})"
                for j in (0, 2, 4)
            ]
        print(f"| {name} | {' | '.join(cells)} | {over[0]} / {over[1]} |", flush=True)
    print(f"\n({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
