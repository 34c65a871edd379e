"""Inclination while the sensor is still after motion, on every shared BROAD trial, beside VQF in the same run.

BROAD's metric scores the motion only (``movement`` rows). A user who reads a still sensor after motion — a level
put down, a bridge inclinometer after a manoeuvre — sees the rest. This benchmark scores the samples that follow
the last ``movement`` row and are still (|ω| < 0.05 rad/s for 1 s), with the same inclination metric, and prints
the gyro-bias error there (the mean gyro over that rest is the true bias). docs/attitude.md ("After motion, at
rest") has the figures and the variants measured.

Usage::

    pip install vqf
    python benchmarks/attitude_rest.py                           # defaults
    python benchmarks/attitude_rest.py --param rest_noise=0.005  # a variant (any EkfParams field)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from attitude_broad import BROAD, ENU2NED, load_trials, score  # noqa: E402

from formats.frames import quat_multiply  # noqa: E402
from imutool.attitude import EkfParams, params_from_options, run_ekf  # noqa: E402


def still_after_motion(d: dict) -> np.ndarray:
    dt = float(np.median(np.diff(d["t"])))
    n = max(1, int(round(1.0 / dt)))
    slow = (np.linalg.norm(d["g"], axis=1) < 0.05).astype(float)
    still = np.convolve(slow, np.ones(n) / n, mode="same") > 0.999
    return still & (np.arange(len(slow)) > np.flatnonzero(d["mv"])[-1]) & np.isfinite(d["q"]).all(1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--param", action="append", default=[], help="NAME=VALUE, an EkfParams field (as imutool filter --param)"
    )
    args = ap.parse_args()
    prm = params_from_options(None, args.param)[0]  # parsed and checked as `imutool filter --param`
    kw = {k: v for k, v in vars(prm).items() if v != getattr(EkfParams(), k)}
    from vqf import VQF

    if not BROAD.is_dir():
        sys.exit(f"no BROAD data at {BROAD}")
    rows = []
    print(f"parameters: {kw or 'defaults'}")
    print("| trial | rest (s) | imutool incl | VQF incl | imutool bias error (°/s, x y z) |")
    print("| --- | --- | --- | --- | --- |")
    for name, d in load_trials().items():
        m = still_after_motion(d)
        res, _ = run_ekf(d["t"], d["g"], d["a"], d["m"], prm)
        dt = float(np.median(np.diff(d["t"])))
        qv = VQF(dt).updateBatch(*(np.ascontiguousarray(d[k]) for k in "gam"))["quat9D"]
        qv = quat_multiply(np.broadcast_to(ENU2NED, qv.shape), qv)
        sub = {"q": d["q"][m], "mv": np.ones(m.sum(), bool)}
        ours, theirs = score(res.q[m], sub)[1], score(qv[m], sub)[1]
        berr = np.degrees(res.bias[m][-1] - d["g"][m].mean(0))
        rows.append((ours, theirs))
        print(
            f"| {name} | {m.sum() * dt:.0f} | {ours:.2f} | {theirs:.2f} | {' '.join(f'{x:+.3f}' for x in berr)} |",
            flush=True,
        )
    r = np.array(rows)
    print(f"| **mean** | | **{r[:, 0].mean():.3f}** | **{r[:, 1].mean():.3f}** | |")
    print(f"| worst | | {r[:, 0].max():.2f} | {r[:, 1].max():.2f} | |")


if __name__ == "__main__":
    main()
