"""``imutool selfcheck``: compile the numba kernels of the commands once and check a tiny end-to-end run.

For a fresh install or a CI image: every step runs a library route a command runs, on a few seconds of simulated
data with known truth, so its kernels are compiled into the per-user cache (:mod:`formats.jit.cache`) with the
types the commands use, and the result is checked against a bound a wrong implementation would break:

1. simulate a ship rolling (30 s, 200 Hz) and round-trip it through the imutool CSV (bit-exact);
2. the quaternion EKF (``run_filter``) on that file: roll and pitch RMSE against truth ≤ 1.5°;
3. the zero-lag smoother on the same data: roll RMSE ≤ 1.0°;
4. the compass filter on a heading swing: RMSE ≤ 25°;
5. heave on a simulated sea state: delayed heave RMSE ≤ 10 % of the significant heave;
6. the INS on a simulated walk (finite track); 7. roll statistics (MSC.363(92)) of the estimated roll;
8. a magnetometer sphere calibration; 9. an Allan deviation; 10. ROS1 and ROS2 (MCAP) bag round trips;
11. the microcontroller bridge decoder.

Any failure raises :class:`ImutoolError` naming the step.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import formats
from calibration.allan import allan_deviation
from formats.errors import ImutoolError
from formats.jit import cache as kernel_cache
from imutool.calibrate import calibrate_mag
from imutool.capture.bridge import BridgeDecoder, Frame, encode_binary
from imutool.evaluation import evaluate
from imutool.filtering import run_filter
from imutool.heave import evaluate_heave, heave_recording
from imutool.ins import ins
from imutool.roll import roll_stats
from imutool.sim import simulate

ROLL_RMSE_MAX_DEG = 1.5  # causal EKF, first 30 s of a ship roll (README: 0.30° over the full default run)
SMOOTH_RMSE_MAX_DEG = 1.0
HEAVE_RMSE_MAX_PCT = 10.0  # delayed heave once settled, % of the significant heave (seed 1: 0.6 %)
HEADING_RMSE_MAX_DEG = 25.0  # uncalibrated iron + deviation in the swing: ~14°; a wrong sign or axis: ≥ 90°


@dataclass
class CheckStep:
    """One step of the self-check: its name, wall time (s) and what it found."""

    name: str
    seconds: float
    detail: str


@dataclass
class SelfcheckResult:
    """All steps, the kernel cache folder used and its source version."""

    steps: list[CheckStep] = field(default_factory=list)
    cache_folder: str | None = None
    persistent_cache: bool = True

    @property
    def seconds(self) -> float:
        return sum(s.seconds for s in self.steps)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")


def _rmse(ev: dict, name: str) -> float:
    try:
        return float(ev["angles"][name]["rmse"])
    except (KeyError, TypeError) as e:
        raise ImutoolError(f"no {name} error in the evaluation") from e


class _Run:
    """The steps, sharing a temporary folder and the simulated ship."""

    def __init__(self, work: Path):
        self.work = work
        self.ship_csv = work / "ship.csv"
        self.estimate = None

    def csv_round_trip(self) -> str:

        rec = simulate("ship-roll", duration=30.0, seed=1)
        formats.write(rec, self.ship_csv)
        back = formats.read(self.ship_csv)
        if not _same(rec.time, back.time):
            raise ImutoolError("time column differs after a CSV round trip")
        bad = [name for name in rec.channels if name not in back.channels or not _same(rec[name], back[name])]
        if bad:
            raise ImutoolError(f"channels differ after a CSV round trip: {', '.join(bad)}")
        return f"{len(rec)} rows, {len(rec.channels)} channels, bit-exact"

    def ekf(self) -> str:

        res = run_filter(self.ship_csv, self.work / "est.csv")
        self.estimate = res.recording
        ev = evaluate(res.recording)
        roll, pitch = _rmse(ev, "roll"), _rmse(ev, "pitch")
        if not (roll <= ROLL_RMSE_MAX_DEG and pitch <= ROLL_RMSE_MAX_DEG):
            raise ImutoolError(f"roll/pitch RMSE {roll:.2f}°/{pitch:.2f}° > {ROLL_RMSE_MAX_DEG}°")
        return f"roll RMSE {roll:.2f}°, pitch {pitch:.2f}° (bound {ROLL_RMSE_MAX_DEG}°)"

    def smoother(self) -> str:

        res = run_filter(self.ship_csv, smooth=True)
        roll = _rmse(evaluate(res.recording), "roll")
        if not roll <= SMOOTH_RMSE_MAX_DEG:
            raise ImutoolError(f"smoothed roll RMSE {roll:.2f}° > {SMOOTH_RMSE_MAX_DEG}°")
        return f"roll RMSE {roll:.2f}° (bound {SMOOTH_RMSE_MAX_DEG}°)"

    def compass(self) -> str:

        res = run_filter(simulate("compass-swing", seed=1), method="compass")
        hdg = _rmse(evaluate(res.recording), "heading")
        if not hdg <= HEADING_RMSE_MAX_DEG:
            raise ImutoolError(f"heading RMSE {hdg:.2f}° > {HEADING_RMSE_MAX_DEG}°")
        return f"heading RMSE {hdg:.2f}° (bound {HEADING_RMSE_MAX_DEG}°)"

    def heave(self) -> str:
        sea = simulate("sea-state", duration=120.0, seed=1)
        out, _ = heave_recording(sea)
        ev = evaluate_heave(out, sea)["heave_delayed"]
        if "not_evaluated" in ev:
            raise ImutoolError(f"delayed heave: {ev['not_evaluated']}")
        pct = float(ev["rmse_pct_of_significant"])
        if not (ev["n"] > 0 and pct <= HEAVE_RMSE_MAX_PCT):
            raise ImutoolError(f"delayed heave RMSE {pct:.1f} % of the significant heave > {HEAVE_RMSE_MAX_PCT} %")
        return f"delayed heave RMSE {pct:.1f} % of the significant heave (bound {HEAVE_RMSE_MAX_PCT} %)"

    def ins_walk(self) -> str:

        out, _ = ins(simulate("walk", duration=20.0, seed=1))
        pos = out["pos"]
        if not np.isfinite(pos).all():
            raise ImutoolError("INS position not finite")
        return f"{len(out)} samples, travelled {np.linalg.norm(pos[-1, :2] - pos[0, :2]):.1f} m"

    def roll_cycles(self) -> str:

        est = self.estimate if self.estimate is not None else formats.read(self.work / "est.csv")
        rs = roll_stats(est.time, np.asarray(est["roll"], float))
        if len(rs.cycles) < 2:
            raise ImutoolError(f"{len(rs.cycles)} roll half-cycles found in 30 s of a rolling ship")
        return f"{len(rs.cycles)} half-cycles"

    def magnetometer(self) -> str:

        calibrate_mag(simulate("mag-sphere", seed=1), self.work / "cal.toml")
        if not (self.work / "cal.toml").stat().st_size:
            raise ImutoolError("empty calibration file")
        return "sphere fit written"

    def allan(self) -> str:

        y = np.random.default_rng(1).normal(0.0, 0.01, 20_000)
        tau, adev, _ = allan_deviation(y, 100.0)
        if not (len(tau) and np.isfinite(adev).all()):
            raise ImutoolError("Allan deviation not finite")
        return f"{len(tau)} cluster times"

    def bags(self) -> str:

        rec = simulate("ship-roll", duration=5.0, seed=1)
        done = []
        for name in ("ship.bag", "ship.mcap"):
            path = self.work / name
            formats.write(rec, path)
            back = formats.read(path)
            if len(back) != len(rec) or not np.allclose(back["gyro"], rec["gyro"], rtol=0, atol=1e-12):
                raise ImutoolError(f"gyro differs after a {name.split('.')[1]} round trip")
            done.append(name.split(".")[1])
        return f"{' and '.join(done)} round trips, {len(rec)} messages each"

    def bridge(self) -> str:

        frames = [Frame(i, 5000 * i, tuple(range(i, i + 10))) for i in range(50)]
        seq, _, counts = BridgeDecoder(binary=True).feed_arrays(b"".join(encode_binary(f) for f in frames))
        if len(seq) != len(frames) or not np.array_equal(np.asarray(counts)[:, 0], np.arange(50)):
            raise ImutoolError(f"bridge decoder returned {len(seq)} of {len(frames)} frames")
        return f"{len(seq)} binary frames decoded"


STEPS: tuple[tuple[str, str], ...] = (
    ("simulate + CSV round trip", "csv_round_trip"),
    ("attitude EKF (filter)", "ekf"),
    ("zero-lag smoother (filter --smooth)", "smoother"),
    ("compass filter", "compass"),
    ("heave", "heave"),
    ("INS (ins)", "ins_walk"),
    ("roll statistics (roll)", "roll_cycles"),
    ("magnetometer calibration", "magnetometer"),
    ("Allan deviation (allan)", "allan"),
    ("ROS bags", "bags"),
    ("bridge frames (capture)", "bridge"),
)


def run_selfcheck(on_step: Callable[[CheckStep], None] | None = None) -> SelfcheckResult:
    """Run every step in a temporary folder; ``on_step`` is called after each. Raises ImutoolError on a failure."""
    result = SelfcheckResult()
    with tempfile.TemporaryDirectory(prefix="imutool-selfcheck-") as tmp:
        run = _Run(Path(tmp))
        for name, method in STEPS:
            t0 = time.perf_counter()
            try:
                detail = getattr(run, method)()
            except Exception as e:
                raise ImutoolError(f"selfcheck step {name!r} failed: {type(e).__name__}: {e}") from e
            step = CheckStep(name, time.perf_counter() - t0, detail)
            result.steps.append(step)
            if on_step is not None:
                on_step(step)
    folder = kernel_cache.cache_folder()
    result.cache_folder = str(folder) if folder is not None else None
    result.persistent_cache = kernel_cache.cache_is_persistent()
    return result
