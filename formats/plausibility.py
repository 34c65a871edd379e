"""Plausibility of sensor inputs: units, axes and absurd samples, checked before any estimator runs.

Every check works on a :class:`Recording` in the working units (gyro rad/s, accel m/s², mag µT) and returns
findings whose message names the fix. Nothing here refuses data; the caller decides (``--strict``).

* **Units.** The accelerometer's median magnitude should be g (≈ 9.81 m/s²; a recording read in g gives ≈ 1,
  in mg ≈ 1000). The magnetometer's median magnitude should be the Earth's field (≈ 20–70 µT; gauss read as
  µT gives 0.2–0.7, milligauss or raw counts hundreds, nT tens of thousands). The gyro is checked against the
  accelerometer: while the sensor tilts, the measured gravity direction â changes as dâ/dt = −ω × â, so the
  change of â over a short step regressed on −(∫ω dt) × â has slope 1 when ω is in rad/s and 1/57.3 when the
  values are deg/s read as rad/s. A gyro that reads a large rate about horizontal axes while â does not
  move at all is flagged too, and so is a gyro beyond any sensor's range.
* **Gravity direction.** At rest an accelerometer measures +g upward; in the FRD body frame (z down) the
  mean specific force points along −z. A recording whose mean points along +z (FLU/ENU-style sensor, e.g.
  x-io's) or along a horizontal axis gets a warning naming ``--mounting`` and the remap that fixes it.
* **Absurd samples.** A sample beyond the physical range of any sensor of its kind (``PHYSICAL_LIMITS``) or
  not finite (±inf) is bridged: runs up to ``max_run_s`` (0.5 s) are interpolated linearly in time from
  their neighbours, longer runs set to NaN (the estimators skip NaN rows). When more than ``max_fraction``
  of a channel is beyond range nothing is bridged: that is a units problem, reported as such.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import units as _units
from .frames import parse_axis_remap
from .recording import Recording
from .units import STANDARD_GRAVITY

# beyond these no sensor of the kind measures (MEMS/FOG gyros ≤ ±4000 °/s ≈ 70 rad/s; high-g accelerometers
# ≤ ±400 g; magnetometers ≤ ±50 gauss): a sample past them is corrupt, not motion
PHYSICAL_LIMITS = {"gyro": 100.0, "accel": 4000.0, "mag": 5000.0}  # rad/s, m/s², µT

_DEG = math.pi / 180.0
_SENSORS = ("gyro", "accel", "mag")


@dataclass
class PlausibilityReport:
    """Findings of :func:`check_recording` / :func:`bridge_absurd` (warnings name their fix)."""

    warnings: list[str] = field(default_factory=list)
    bridged: dict[str, int] = field(default_factory=dict)  # samples interpolated, per channel
    set_nan: dict[str, int] = field(default_factory=dict)  # samples set to NaN (runs too long to bridge)
    figures: dict[str, Any] = field(default_factory=dict)
    # absurd samples per channel: [absurd, samples looked at, left as they are (too many: a unit error), first t]
    absurd: dict[str, list[float]] = field(default_factory=dict)

    def add_absurd(self, other: PlausibilityReport) -> None:
        """Add another report's absurd-sample counts to this one (a file checked chunk by chunk)."""
        for name, (nb, n, kept, t0) in other.absurd.items():
            mine = self.absurd.setdefault(name, [0, 0, 0, t0])
            mine[0], mine[1], mine[2], mine[3] = mine[0] + nb, mine[1] + n, mine[2] + kept, min(mine[3], t0)
        for mine, theirs in ((self.bridged, other.bridged), (self.set_nan, other.set_nan)):
            for name, k in theirs.items():
                mine[name] = mine.get(name, 0) + k

    def absurd_warnings(self, limits: dict[str, float] | None = None) -> list[str]:
        """One warning per channel with absurd samples: what was bridged, or why nothing was (a unit error)."""
        lim = dict(PHYSICAL_LIMITS, **(limits or {}))
        out = []
        for name, (nb, n, kept, t0) in self.absurd.items():
            if kept:
                out.append(
                    f"{int(kept)} of {int(n)} {name} samples ({100 * kept / n:.1f}%) are beyond any sensor's "
                    f"range (|value| > {lim[name]:g} in SI units or infinite): a unit or scale error, not "
                    f"corruption — check the {name} unit (not bridged)"
                )
            if nb > kept:
                out.append(
                    f"{int(nb - kept)} absurd {name} sample(s) (beyond the physical range or infinite; first "
                    f"at t = {t0:.6g} s): {self.bridged.get(name, 0)} interpolated from their neighbours, "
                    f"{self.set_nan.get(name, 0)} set to NaN (skipped by the estimators)"
                )
        return out

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"warnings": list(self.warnings)}
        if self.bridged:
            out["absurd_samples_interpolated"] = dict(self.bridged)
        if self.set_nan:
            out["absurd_samples_set_nan"] = dict(self.set_nan)
        out["figures"] = dict(self.figures)
        return out


# -- helpers -------------------------------------------------------------------------------------------------
def _source_columns(rec: Recording, channel: str) -> list[str]:
    """The source CSV columns that became ``channel`` (from ``meta['column_mapping']``), else its columns."""
    cm = rec.meta.get("column_mapping")
    targets = rec.columns.get(channel, [])
    if isinstance(cm, str) and cm:
        src = {}
        for item in cm.split("; "):
            s, sep, rest = item.rpartition("->")
            if sep:
                src[rest.split("[", 1)[0]] = s
        got = [src.get(t) for t in targets]
        if all(got):
            return got  # type: ignore[return-value]
    return list(targets)


def _columns_fix(rec: Recording, channel: str, unit: str, kind: str | None = None) -> str:
    """The option that states the unit: --columns for a CSV or a bag (``kind``); a file that carries its own
    units (Parquet, NMEA) has to be fixed where it was written."""
    if kind in ("parquet", "nmea"):
        return f"the file states its own units: fix the {channel} values ({unit}) where it was written"
    cols = _source_columns(rec, channel)
    targets = rec.columns.get(channel, [])
    if not cols or len(cols) != len(targets):
        return f"state the unit of the {channel} columns ({unit})"
    spec = ",".join(f"{s}={t}:{unit}" for s, t in zip(cols, targets, strict=True))
    return f"give the unit: --columns '{spec}'"


def _assumed(rec: Recording) -> set[str]:
    a = rec.meta.get("units_assumed", "")
    return {s.strip() for s in a.split(",")} if isinstance(a, str) else set()


def _finite_rows(a: np.ndarray) -> np.ndarray:
    return np.all(np.isfinite(a), axis=1)


def _finite_xyz(rec: Recording, channel: str, min_rows: int = 10) -> np.ndarray | None:
    """The finite rows of a 3-axis channel, or None when it is absent, not (N, 3) or has fewer than min_rows."""
    a = rec.channels.get(channel)
    if a is None or a.ndim != 2 or a.shape[1] != 3:
        return None
    a = a[_finite_rows(a)]
    return a if len(a) >= min_rows else None


def _moving_mean(a: np.ndarray, w: int) -> np.ndarray:
    if w <= 1:
        return a
    c = np.cumsum(np.vstack([np.zeros((1, a.shape[1])), a]), axis=0)
    return (c[w:] - c[:-w]) / w


# -- unit checks ---------------------------------------------------------------------------------------------
BAG_KINDS = ("ros1", "ros2")  # formats.kind_of of a bag: its fields' units are the ROS messages', not a header's


def _mapped(rec: Recording, channel: str) -> bool:
    """Whether ``meta['column_mapping']`` names the unit of the channel's first column."""
    cm = rec.meta.get("column_mapping")
    targets = rec.columns.get(channel, [])
    if not isinstance(cm, str) or not targets:
        return False
    return any(item.rpartition("->")[2].split("[", 1)[0] == targets[0] for item in cm.split("; "))


def _unit_note(rec: Recording, channel: str, declared: str, kind: str | None = None) -> str:
    if kind in BAG_KINDS:
        if _mapped(rec, channel):
            return f"--columns gives the bag's {channel} in {declared}"
        msg = "magnetometer message" if channel == "mag" else "sensor_msgs/Imu"
        return f"the bag's {msg} carries {channel} in {declared} (ROS units)"
    if channel in _assumed(rec):
        return f"the header gives no unit for {channel}, so {declared} was assumed"
    return f"the header declares {channel} in {declared}"


def _declared(rec: Recording, channel: str, kind: str | None = None) -> tuple[str, float]:
    """The unit the channel's source columns were read in and its factor to SI (from the column mapping; for a
    bag, ``kind`` ros1/ros2, the unit of its message fields as read: ``meta['bag']['units']``)."""
    if kind in BAG_KINDS and not _mapped(rec, channel):
        bag = rec.meta.get("bag")
        u = (bag.get("units") or {}).get(channel) if isinstance(bag, dict) else None
        if isinstance(u, str) and _units.is_known(u):
            return u, _units.lookup(u)[1]
    cm = rec.meta.get("column_mapping")
    targets = rec.columns.get(channel, [])
    if isinstance(cm, str) and targets:
        for item in cm.split("; "):
            _, sep, rest = item.rpartition("->")
            if sep and rest.split("[", 1)[0] == targets[0] and "[" in rest:
                u = rest.split("[", 1)[1].rstrip("]")
                scale = 1.0
                if "x" in u and u.rsplit("x", 1)[1].replace(".", "").replace("e-", "").isdigit():
                    u, sc = u.rsplit("x", 1)
                    scale = float(sc)
                try:
                    return u, _units.lookup(u)[1] * scale
                except Exception:  # noqa: BLE001 - unknown: fall back to SI
                    break
    si = {"gyro": "rad/s", "accel": "m/s^2", "mag": "uT"}[channel]
    return si, 1.0


def _magnitude_check(
    rec: Recording,
    rep: PlausibilityReport,
    channel: str,
    lo: float,
    hi: float,
    candidates: tuple[str, ...],
    what: str,
    expected: str,
    kind: str | None = None,
) -> None:
    a = _finite_xyz(rec, channel)
    if a is None:
        return
    med = float(np.median(np.linalg.norm(a, axis=1)))
    si = {"accel": "m/s²", "mag": "µT"}[channel]
    rep.figures[f"{channel}_median_norm"] = med
    if lo <= med <= hi:
        return
    if med < 1e-9 * hi:
        rep.warnings.append(f"{what} reads ≈ 0 in every sample (not connected?); expected {expected}")
        return
    unit, factor = _declared(rec, channel, kind)
    note = _unit_note(rec, channel, unit, kind)
    raw = med / factor  # the median magnitude in the file's own numbers
    for cand in candidates:
        f = _units.lookup(cand)[1]
        if lo <= raw * f <= hi and not math.isclose(f, factor, rel_tol=1e-6):
            extra = " (or raw counts)" if cand in ("mgauss", "mg") else ""
            rep.warnings.append(
                f"UNITS: {what} median magnitude is {med:.4g} {si} (expected {expected}): {note}, but the values "
                f"look like {cand}{extra} — {_columns_fix(rec, channel, cand, kind)}"
            )
            return
    rep.warnings.append(
        f"UNITS: {what} median magnitude is {med:.4g} {si} (expected {expected}): {note}; raw counts? — "
        f"{_columns_fix(rec, channel, candidates[0] + '*SCALE', kind)} with the sensor's scale per count"
    )


def check_accel_units(rec: Recording, rep: PlausibilityReport, kind: str | None = None) -> None:
    """Median |accel| ≈ g (a walk, a ship or a rotation keep the median near g)."""
    g = STANDARD_GRAVITY
    _magnitude_check(
        rec, rep, "accel", 0.6 * g, 1.6 * g, ("g", "m/s^2", "mg"), "accelerometer", "≈ 9.81 m/s² at rest", kind
    )


def check_mag_units(rec: Recording, rep: PlausibilityReport, kind: str | None = None) -> None:
    """Median |mag| within 10–150 µT (Earth 20–70 µT; a ship's own field and hard iron widen it)."""
    _magnitude_check(
        rec,
        rep,
        "mag",
        10.0,
        150.0,
        ("gauss", "uT", "mgauss", "nT", "T"),
        "magnetometer",
        "the Earth's field, 20–70 µT",
        kind,
    )


def gyro_tilt_ratio(rec: Recording, steps_s: tuple[float, ...] = (0.1, 0.2, 0.5)) -> dict[str, float] | None:
    """Slope k of the accelerometer-direction change on the gyro-predicted change (1 for rad/s).

    Block means over each step length in ``steps_s``; the step with the best correlation is kept (short steps
    are noisy, long ones break the small-angle model). Returns {k, correlation, step_s, predicted_tilt_rad,
    observed_tilt_rad, horizontal_rate_rad_s} or None when the recording has no gyro/accel pair or too few
    samples.
    """
    best = None
    for st in steps_s:
        r = _tilt_ratio_one(rec, st)
        if r is not None and (best is None or r["correlation"] > best["correlation"]):
            best = r
    return best


def _tilt_ratio_one(rec: Recording, step_s: float) -> dict[str, float] | None:
    w = rec.channels.get("gyro")
    a = rec.channels.get("accel")
    if w is None or a is None or w.shape[1:] != (3,) or a.shape[1:] != (3,) or len(rec) < 20:
        return None
    ok = _finite_rows(w) & _finite_rows(a)
    t = rec.time[ok]
    w = w[ok]
    a = a[ok]
    if len(t) < 20:
        return None
    dt = float(np.median(np.diff(t)))
    if not np.isfinite(dt) or dt <= 0:
        return None
    n = max(1, int(round(step_s / dt)))
    m = len(t) // n
    if m < 10:
        return None
    # block means: noise down by √n, both signals on the same step
    wb = w[: m * n].reshape(m, n, 3).mean(axis=1)
    ab = a[: m * n].reshape(m, n, 3).mean(axis=1)
    tb = t[: m * n].reshape(m, n).mean(axis=1)
    na = np.linalg.norm(ab, axis=1)
    good = na > 1e-9
    ah = np.where(good[:, None], ab / np.where(good, na, 1.0)[:, None], np.nan)
    d_obs = ah[1:] - ah[:-1]
    dtb = np.diff(tb)
    wm = 0.5 * (wb[1:] + wb[:-1])
    am = 0.5 * (ah[1:] + ah[:-1])
    horiz = np.linalg.norm(np.cross(wb, ah), axis=1)  # rate about axes perpendicular to gravity
    wm_c = wm - np.median(wb, axis=0)  # a constant bias does not tilt anything
    d_pred = -np.cross(wm_c * dtb[:, None], am)
    keep = np.all(np.isfinite(d_obs), axis=1) & np.all(np.isfinite(d_pred), axis=1) & (dtb < 3 * n * dt)
    d_obs, d_pred = d_obs[keep], d_pred[keep]
    if len(d_obs) < 10:
        return None
    spp = float(np.sum(d_pred * d_pred))
    soo = float(np.sum(d_obs * d_obs))
    spo = float(np.sum(d_pred * d_obs))
    k = spo / spp if spp > 0 else float("nan")
    corr = spo / math.sqrt(spp * soo) if spp > 0 and soo > 0 else 0.0
    return {
        "k": k,
        "correlation": corr,
        "step_s": n * dt,
        "predicted_tilt_rad": float(np.sum(np.linalg.norm(d_pred, axis=1))),
        "observed_tilt_rad": float(np.sum(np.linalg.norm(d_obs, axis=1))),
        "horizontal_rate_rad_s": float(np.nanmedian(horiz)) if np.any(np.isfinite(horiz)) else float("nan"),
    }


# the units a gyro is written in by mistake (deg/s ↔ rad/s is 57.3×, milli-units 1000×): the tilt slope proposes those
# within GYRO_UNIT_MATCH of its factor, the window-pair test chooses (a lever arm or an acceleration the body feels
# while it rolls multiplies the short-step slope by 1 + hω²/g: 5–12 on a mast, no unit's factor)
GYRO_UNITS = ("deg/s", "rad/s", "mrad/s", "mdps")
GYRO_UNIT_MATCH = 7.5  # the geometric midpoint of deg/s and rad/s
GYRO_COUNTS_SLOPE = 30.0  # a slope this far from 1 and near no unit: raw counts or a scale, if confirmed
UNIT_EXPLAINS = 0.75  # share of the mean-square discrepancy the best candidate removes that a unit must remove
PAIR_WINDOW_S = 2.0  # s, windows of the confirmation (imutool.gyro_check.WINDOW_S)
PAIR_MIN_REMOVED_DEG = 1.5  # RMS tilt discrepancy a unit must remove (imutool.gyro_check.MIN_DISCREPANCY_DEG)


def _rotvec_quat(r: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) of rotation vectors r (..., 3) rad."""
    ang = np.linalg.norm(r, axis=-1)
    half = 0.5 * ang
    k = np.where(ang > 1e-12, np.sin(half) / np.where(ang > 1e-12, ang, 1.0), 0.5)
    return np.concatenate([np.cos(half)[..., None], r * k[..., None]], axis=-1)


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a0, a1, a2, a3 = np.moveaxis(a, -1, 0)
    b0, b1, b2, b3 = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
        ],
        axis=-1,
    )


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q) v for unit quaternions q (..., 4) and vectors v (..., 3)."""
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + q[..., :1] * t + np.cross(u, t)


def window_pair_discrepancy(
    rec: Recording, factors: tuple[float, ...], window: float = PAIR_WINDOW_S, max_rate_hz: float = 50.0
) -> tuple[np.ndarray, int] | None:
    """RMS tilt discrepancy J(s) (rad) between consecutive ``window``-s windows for each factor s on the gyro's rates:
    the physics of the attitude filter's own gyro check (:mod:`imutool.gyro_check`), without the filter.

    The gyro (median removed as its bias, rates × s) is integrated from the start of each pair of windows; the mean
    specific force of each window in that frame is −g·ẑ for both when s is right, whatever the motion, since a
    bounded velocity averages the acceleration out. Samples are block-averaged to at most ``max_rate_hz``. Returns
    (J per factor, pairs), or None when fewer than two pairs fit (the window shrinks to a third of a short span,
    not below 0.25 s)."""
    w, a = rec.channels.get("gyro"), rec.channels.get("accel")
    if w is None or a is None or w.shape[1:] != (3,) or a.shape[1:] != (3,):
        return None
    ok = _finite_rows(w) & _finite_rows(a)
    t, w, a = rec.time[ok], w[ok], a[ok]
    if len(t) < 20:
        return None
    dt = float(np.median(np.diff(t)))
    if not np.isfinite(dt) or dt <= 0:
        return None
    window = min(window, (t[-1] - t[0]) / 3.0)
    if window < 0.25:
        return None
    m = max(1, int(round(1.0 / (max_rate_hz * dt))))
    nb = len(t) // m
    tb = t[: nb * m].reshape(nb, m).mean(axis=1)
    span = t[m - 1 : nb * m : m] - t[: nb * m : m]
    wb = w[: nb * m].reshape(nb, m, 3).mean(axis=1)
    fb = a[: nb * m].reshape(nb, m, 3).mean(axis=1)
    n_win = max(1, int(round(window / (m * dt))))  # blocks per window
    n_pairs = nb // n_win - 1
    if n_pairs < 2:
        return None
    idx = (np.arange(n_pairs) * n_win)[:, None] + np.arange(2 * n_win)[None, :]  # (pairs, 2 windows of blocks)
    step = np.diff(tb[idx], axis=1)
    good = np.all((step > 0) & (step <= 3 * m * dt), axis=1) & np.all(span[idx] <= 2 * m * dt, axis=1)
    idx, step = idx[good], step[good]
    if len(idx) < 2:
        return None
    rate = wb - np.median(wb, axis=0)
    s = np.asarray(factors, float)[:, None, None]
    q = np.zeros((len(s), len(idx), 4))
    q[..., 0] = 1.0
    sums = np.zeros((2, len(s), len(idx), 3))
    for j in range(2 * n_win):
        if j:
            r = 0.5 * (rate[idx[:, j - 1]] + rate[idx[:, j]]) * step[:, j - 1, None]
            q = _qmul(q, _rotvec_quat(s * r[None]))
            q /= np.linalg.norm(q, axis=-1, keepdims=True)
        sums[int(j >= n_win)] += _rotate(q, np.broadcast_to(fb[idx[:, j]], q.shape[:-1] + (3,)))
    g = float(np.median(np.linalg.norm(fb, axis=1)))
    d = (sums[0] - sums[1]) / n_win
    j2 = np.mean(np.sum(d * d, axis=-1), axis=-1) / (g * g if g > 0 else 1.0)
    return np.sqrt(j2), len(idx)


def _gyro_unit_claim(
    rec: Recording, rep: PlausibilityReport, k: float, factor: float
) -> tuple[str | None, float] | None:
    """What the tilt slope ``k`` may claim: (the unit the values look like, or None for a bare scale; the factor the
    SI values need), or None.

    Candidates are the units of :data:`GYRO_UNITS` within ``GYRO_UNIT_MATCH`` of the slope's factor (the slope on
    hand motion is off by up to ~2.5×: it only proposes), and the slope itself where it is ≥ 30× off (raw counts).
    The window-pair test (:func:`window_pair_discrepancy`, the physics of the filter's own check) chooses among
    them, and must find the best candidate better than the gyro as it is by ``PAIR_MIN_REMOVED_DEG``. A slope near
    no unit and < 30× off is an acceleration the body feels (a lever arm, a turn): no claim."""
    true_factor = factor * k  # rad/s per value, as the accelerometer's tilting says
    cands: list[tuple[str | None, float]] = []
    for unit in GYRO_UNITS:
        f = _units.lookup(unit)[1]
        if 1 / GYRO_UNIT_MATCH <= true_factor / f <= GYRO_UNIT_MATCH and not math.isclose(f, factor, rel_tol=1e-6):
            cands.append((unit, f / factor))
    if not (1 / GYRO_COUNTS_SLOPE < k < GYRO_COUNTS_SLOPE):
        cands.append((None, k))
    if not cands:
        rep.figures["gyro_tilt_verdict"] = "slope near no unit's factor: an acceleration, not a unit (no claim)"
        return None
    conf = window_pair_discrepancy(rec, (1.0, *(s for _, s in cands)))
    if conf is None:  # too short for the filter's check: a unit's factor alone is enough, a bare scale is not
        rep.figures["gyro_tilt_verdict"] = "too short to confirm"
        named = [c for c in cands if c[0] is not None]
        return min(named, key=lambda c: abs(math.log(c[1] / k))) if named else None
    j, pairs = conf
    i = int(np.argmin(j[1:]))
    named = [n for n, c in enumerate(cands) if c[0] is not None]
    if named:  # a unit that removes most of what the best candidate removes is the answer (a slope is not exact)
        u = min(named, key=lambda n: j[1 + n])
        if j[0] ** 2 - j[1 + u] ** 2 >= UNIT_EXPLAINS * (j[0] ** 2 - j[1 + i] ** 2):
            i = u
    best, j1, jb = cands[i], float(j[0]), float(j[1 + i])
    rep.figures["gyro_window_check"] = {
        "factor": best[1],
        "discrepancy_as_is_deg": math.degrees(j1),
        "discrepancy_rescaled_deg": math.degrees(jb),
        "pairs": pairs,
    }
    if jb < j1 and math.degrees(math.sqrt(max(j1 * j1 - jb * jb, 0.0))) >= PAIR_MIN_REMOVED_DEG:
        return best
    rep.figures["gyro_tilt_verdict"] = "not confirmed by the window-pair test: no claim"
    return None


def check_gyro_units(rec: Recording, rep: PlausibilityReport, kind: str | None = None) -> None:
    """Gyro unit against the accelerometer's tilting (:func:`gyro_tilt_ratio`), else against any gyro's range.

    A unit is claimed only where the tilt slope lands near a unit's factor (:data:`GYRO_UNITS`; or ≥ 30× off:
    raw counts) **and** the window-pair test of the attitude filter's gyro check agrees
    (:func:`window_pair_discrepancy`): a slope that is a lever arm's or a turn's acceleration is not a unit."""
    wf = _finite_xyz(rec, "gyro")
    if wf is None:
        return
    unit, factor = _declared(rec, "gyro", kind)
    note = _unit_note(rec, "gyro", unit, kind)
    p99 = float(np.percentile(np.linalg.norm(wf, axis=1), 99))
    rep.figures["gyro_p99_norm_rad_s"] = p99
    r = gyro_tilt_ratio(rec)
    if r is not None:
        rep.figures["gyro_tilt_slope"] = r["k"]
        rep.figures["gyro_tilt_correlation"] = r["correlation"]
    # deg/s and rad/s differ by 57.3×: no verdict within 7.5× (the geometric midpoint) of 1
    if r is not None and r["correlation"] > 0.4 and r["k"] > 0:
        k = r["k"]  # SI values × k = what the accelerometer's tilting says
        if 1 / 7.5 <= k <= 7.5:
            return
        claim = _gyro_unit_claim(rec, rep, k, factor)
        if claim is None:
            return
        cand, _s = claim
        if cand is not None:
            rep.warnings.append(
                f"UNITS: gyro rates are {1 / k:.3g}× the tilting the accelerometer shows: {note}, but the "
                f"values look like {cand} — {_columns_fix(rec, 'gyro', cand, kind)}"
            )
        else:
            rep.warnings.append(
                f"UNITS: gyro rates disagree with the tilting the accelerometer shows by a factor {1 / k:.3g} "
                f"(expected 1): {note}; raw counts or a wrong scale? — "
                f"{_columns_fix(rec, 'gyro', 'UNIT*SCALE', kind)}"
            )
        return
    if p99 > PHYSICAL_LIMITS["gyro"] / 2 and not math.isclose(factor, _DEG, rel_tol=1e-6):
        rep.warnings.append(
            f"UNITS: gyro reads up to {p99:.3g} rad/s ({p99 / _DEG:.3g} °/s), beyond any gyro's range: {note}, "
            f"but the values look like deg/s — {_columns_fix(rec, 'gyro', 'deg/s', kind)}"
        )
        return
    if (
        r is not None
        and r["horizontal_rate_rad_s"] > 0.3
        and r["observed_tilt_rad"] < 0.05 * r["predicted_tilt_rad"]
        and not math.isclose(factor, _DEG, rel_tol=1e-6)
    ):
        h = r["horizontal_rate_rad_s"]
        rep.warnings.append(
            f"UNITS: gyro reads a median {h:.3g} rad/s about horizontal axes while the accelerometer shows no "
            f"tilting: {note}, but the values look like deg/s (or carry a huge bias) — "
            f"{_columns_fix(rec, 'gyro', 'deg/s', kind)}"
        )


# -- gravity direction ---------------------------------------------------------------------------------------
_AX = "xyz"


def _remap_for_up_axis(axis: int, sign: float) -> str:
    """A proper rotation (as a --mounting remap) that takes sensor axis ``sign·axis`` (pointing up) to body −z."""
    if axis == 2:
        return "x,-y,-z" if sign > 0 else "x,y,z"
    # up axis becomes −z; keep the other horizontal axis, complete right-handed
    cand = []
    for perm in ("x", "y", "z", "-x", "-y", "-z"):
        for perm2 in ("x", "y", "z", "-x", "-y", "-z"):
            cand.append((perm, perm2))
    up = ("-" if sign > 0 else "") + _AX[axis]  # body z = −up

    for bx, by in cand:
        spec = f"{bx},{by},{up}"
        names = {s.lstrip("-") for s in (bx, by, up)}
        if len(names) != 3:
            continue
        try:
            parse_axis_remap(spec)
        except Exception:  # noqa: BLE001 - left-handed candidates are skipped
            continue
        return spec
    return "x,y,z"  # pragma: no cover


def check_gravity_direction(
    rec: Recording, rep: PlausibilityReport, mounting: str | None = None, kind: str | None = None
) -> None:
    """The mean specific force should point along body −z (FRD, at rest): otherwise name the mounting that fixes
    it. For a bag (``kind`` ros1/ros2) the data are already converted from REP-103 FLU to FRD, so a z axis up is
    the sensor's own mounting, not the FLU convention."""
    a = _finite_xyz(rec, "accel")
    if a is None:
        return
    na = np.linalg.norm(a, axis=1)
    a = a[na > 0]
    if len(a) < 10:
        return
    u = a / np.linalg.norm(a, axis=1, keepdims=True)
    mean = u.mean(axis=0)
    consistency = float(np.linalg.norm(mean))
    rep.figures["gravity_direction_consistency"] = consistency
    if consistency < 0.7:  # rotated through many attitudes (calibration sphere): no mean direction
        return
    d = mean / consistency
    rep.figures["mean_specific_force_direction"] = [float(v) for v in d]
    tilt = math.degrees(math.acos(max(-1.0, min(1.0, -d[2]))))  # angle from body −z (up in FRD)
    if tilt < 60.0:
        return
    axis = int(np.argmax(np.abs(d)))
    sign = float(np.sign(d[axis]))
    fix = _remap_for_up_axis(axis, sign)
    if axis == 2 and sign > 0 and kind in BAG_KINDS:
        what = (
            "+z after the bag's REP-103 (FLU) → FRD conversion: the sensor itself is mounted with that z axis up "
            "(its ROS z axis points down: mounted upside down, or a driver that publishes z-down axes as FLU)"
        )
    elif axis == 2 and sign > 0:
        what = "+z: the sensor's z axis points up (FLU/ENU-style axes, e.g. x-io, or ROS data not converted)"
    else:
        what = f"{'+' if sign > 0 else '-'}{_AX[axis]}: that sensor axis points up"
    given = f" even after --mounting {mounting!r}" if mounting else ""
    rep.warnings.append(
        f"AXES: the mean specific force points along {what}{given}; imutool's body frame is FRD (z down, so "
        f"an accelerometer at rest reads −9.81 m/s² on z) — give the sensor mounting, e.g. --mounting {fix} "
        f"(otherwise roll/pitch come out about {tilt:.0f}° off)"
    )


SAMPLE_ROWS = 60_000  # rows the plausibility checks look at in a long recording
SAMPLE_PIECES = 6  # in this many evenly spaced stretches


def sample_stretches(n: int, max_rows: int = SAMPLE_ROWS, pieces: int = SAMPLE_PIECES) -> list[tuple[int, int]]:
    """The rows [start, stop) of a recording of ``n`` rows that :func:`sample_rows` keeps: all of them, or
    ``pieces`` evenly spaced contiguous stretches of ``max_rows`` rows in all."""
    if n <= max_rows:
        return [(0, n)]
    k = max_rows // pieces
    return [(int(a), int(a) + k) for a in np.linspace(0, n - k, pieces).astype(np.int64)]


def sample_rows(rec: Recording, max_rows: int = SAMPLE_ROWS, pieces: int = SAMPLE_PIECES) -> Recording:
    """``rec`` itself, or for a long recording ``pieces`` evenly spaced contiguous stretches of ``max_rows`` rows
    in all (statistics of units and axes do not need every row; contiguous stretches keep the time structure
    the gyro/tilt comparison needs)."""
    n = len(rec)
    if n <= max_rows:
        return rec
    idx = np.concatenate([np.arange(a, b) for a, b in sample_stretches(n, max_rows, pieces)])
    return Recording(
        rec.time[idx],
        {c: rec.channels[c][idx] for c in _SENSORS if c in rec.channels},
        {c: u for c, u in rec.units.items() if c in _SENSORS},
        dict(rec.meta),
        {c: list(v) for c, v in rec.columns.items() if c in _SENSORS},
    )


def joined_rows(pieces: list[Recording]) -> Recording:
    """The sensor channels of ``pieces`` (stretches of one recording, in order) as one recording: what
    :func:`sample_rows` gives for a recording read chunk by chunk."""
    first = pieces[0]
    return Recording(
        np.concatenate([p.time for p in pieces]),
        {c: np.concatenate([p.channels[c] for p in pieces]) for c in _SENSORS if c in first.channels},
        {c: u for c, u in first.units.items() if c in _SENSORS},
        dict(first.meta),
        {c: list(v) for c, v in first.columns.items() if c in _SENSORS},
    )


def check_recording(rec: Recording, mounting: str | None = None, kind: str | None = None) -> PlausibilityReport:
    """Run every plausibility check on the sensor channels of ``rec`` (working units, after mounting).

    ``kind``: the input's format (:func:`formats.kind_of`); a bag's units and axes are named as the bag's. Long
    recordings are checked on :func:`sample_rows` (about 60 000 rows in six stretches)."""
    rep = PlausibilityReport()
    if rec.multi_clock:  # sensors of several streams: compared on one sensor's clock (Recording.on_clock)
        first = next((c for c in ("accel", "gyro", "mag") if c in rec.channels), None)
        if first is None:
            return rep
        rec = rec.on_clock(first)
    rec = sample_rows(rec)
    check_accel_units(rec, rep, kind)
    check_gyro_units(rec, rep, kind)
    check_mag_units(rec, rep, kind)
    check_gravity_direction(rec, rep, mounting, kind)
    return rep


# -- absurd samples ------------------------------------------------------------------------------------------
def bridge_absurd(
    rec: Recording,
    limits: dict[str, float] | None = None,
    max_run_s: float = 0.5,
    max_fraction: float = 0.01,
    rep: PlausibilityReport | None = None,
    out_of: int = 0,
) -> tuple[Recording, PlausibilityReport]:
    """Bridge samples beyond the physical range (or ±inf) in the gyro/accel/mag channels.

    A sample is absurd when any axis is ±inf or beyond ``limits[channel]`` (working units; default
    :data:`PHYSICAL_LIMITS`). Runs of absurd samples no longer than ``max_run_s`` seconds (neighbour to
    neighbour) with valid neighbours on both sides are interpolated linearly in time; others are set to NaN.
    NaN samples are left alone. When more than ``max_fraction`` of a channel's samples are absurd nothing is
    changed and a warning says so (that is a unit or scale problem, not corruption); ``out_of``: judge that share
    against this many samples when more than the recording's (a stream: the rows seen so far). A channel ``rep``
    already holds a unit error for (a stream's earlier chunk) is left as it is in this chunk too.
    Returns (recording, report); the input is not modified.
    """
    rep = rep if rep is not None else PlausibilityReport()
    found = PlausibilityReport()  # this call's counts, added to ``rep`` with their warnings at the end
    lim = dict(PHYSICAL_LIMITS, **(limits or {}))
    out = rec
    for name in _SENSORS:
        a = rec.channels.get(name)
        if a is None or a.dtype.kind != "f" or len(a) == 0:
            continue
        a2 = a.reshape(len(a), -1)
        hi, lo = np.fmax.reduce(a2, axis=None), np.fmin.reduce(a2, axis=None)  # NaN-blind, no temporaries
        if not (hi > lim[name] or lo < -lim[name]):
            continue
        with np.errstate(invalid="ignore"):
            bad = np.any(np.isinf(a2) | (np.abs(a2) > lim[name]), axis=1)
        nb = int(np.count_nonzero(bad))
        if not nb:
            continue
        # a unit or scale problem, not corruption: left as it is; in a stream, once a chunk showed it, every later
        # chunk too (judged alone, the 100th chunk of a channel absurd throughout is 1 % of the rows seen)
        earlier_unit_error = rep.absurd.get(name, (0, 0, 0, 0.0))[2] > 0
        if earlier_unit_error or nb > max_fraction * max(len(a), out_of):
            found.absurd[name] = [nb, len(a), nb, float(rec.time[np.argmax(bad)])]
            continue
        if out is rec:
            out = rec.copy()
        b = out.channels[name].reshape(len(a), -1)
        b[bad] = np.nan
        valid = np.all(np.isfinite(b), axis=1)
        idx = np.flatnonzero(bad)
        # runs of consecutive bad rows
        starts = idx[np.concatenate([[True], np.diff(idx) > 1])]
        ends = idx[np.concatenate([np.diff(idx) > 1, [True]])]
        n_interp = n_nan = 0
        t = out.time
        for s, e in zip(starts, ends, strict=True):
            run = e - s + 1
            if s > 0 and e < len(b) - 1 and valid[s - 1] and valid[e + 1] and t[e + 1] - t[s - 1] <= max_run_s:
                f = (t[s : e + 1] - t[s - 1]) / (t[e + 1] - t[s - 1])
                b[s : e + 1] = b[s - 1] + f[:, None] * (b[e + 1] - b[s - 1])
                n_interp += run
            else:
                n_nan += run
        if n_interp:
            found.bridged[name] = int(n_interp)
        if n_nan:
            found.set_nan[name] = int(n_nan)
        found.absurd[name] = [nb, len(a), 0, float(t[idx[0]])]
    rep.add_absurd(found)
    rep.warnings += found.absurd_warnings(limits)
    return out, rep


# -- what validation did -------------------------------------------------------------------------------------
GNSS_TOPIC_TYPES = (
    "sensor_msgs/msg/NavSatFix",
    "geometry_msgs/msg/TwistStamped",
    "geometry_msgs/msg/TwistWithCovarianceStamped",
)


def topics_not_read_warning(topics: list[dict[str, Any]]) -> str:
    """The warning naming every bag topic that was not read (``meta['bag']['topics_not_read']``), with its type,
    message count and how to read it when imutool can."""

    def one(t: dict[str, Any]) -> str:
        how = "name it in --topic to read it" if t.get("type") in GNSS_TOPIC_TYPES else "a type imutool does not read"
        return f"{t.get('topic')} ({t.get('type')}, {t.get('messages')} msgs; {how})"

    return f"NOT READ: {len(topics)} bag topic(s): " + "; ".join(one(t) for t in topics)


def dropped_rows(
    n_in: int,
    n_out: int,
    validation: dict[str, Any],
    meta: dict[str, Any],
    duplicates: str = "drop",
    warn_fraction: float = 0.01,
) -> tuple[dict[str, Any], list[str]]:
    """Account for every row the reader and the time validation did not keep.

    n_in: rows the reader returned; n_out: rows after :meth:`Recording.validated`; validation: its report
    dict; meta: the reader's metadata (``skipped_rows`` = malformed rows the CSV reader skipped,
    ``bag.partial_read`` = a truncated bag). Returns ({rows_read, rows_kept, rows_dropped, dropped: {reason: n}},
    warnings) with a warning when more than ``warn_fraction`` of the rows read were dropped.
    """
    skipped = int(meta.get("skipped_rows", 0) or 0)
    reasons: dict[str, int] = {}
    if skipped:
        reasons["malformed rows (unparseable fields or wrong column count)"] = skipped
    bag = meta.get("bag")
    if isinstance(bag, dict):  # messages the bag reader could not decode
        topics = bag.get("topics") or {}
        bad = sum(int(v.get("undecodable_skipped", 0) or 0) for v in topics.values() if isinstance(v, dict))
        if bad:
            reasons["undecodable bag messages"] = bad
            skipped += bad
    nd = int(validation.get("duplicate_timestamps", 0) or 0)
    lost = n_in - n_out
    if nd and lost > 0:
        what = (
            "merged into the row before (--duplicates mean)"
            if duplicates == "mean"
            else "repeated timestamp (first row of each kept)"
        )
        reasons[what] = min(nd, lost)
        lost -= min(nd, lost)
    if lost > 0:
        reasons["time earlier than the row before (--backwards drop)"] = lost
    total_read = n_in + skipped
    dropped = sum(reasons.values())
    info: dict[str, Any] = {"rows_read": total_read, "rows_kept": n_out, "rows_dropped": dropped, "dropped": reasons}
    warns: list[str] = []
    if total_read and dropped > warn_fraction * total_read:
        why = ", ".join(f"{n} {r}" for r, n in reasons.items())
        fix = ""
        if nd:
            fix = (
                " — the timestamps repeat (a logger stamping on arrival?): fix the time column, or use "
                "--duplicates mean to average rows that share a time"
            )
        elif skipped:
            fix = " — check the file's format (`imutool info` lists the first malformed lines)"
        warns.append(
            f"DROPPED: validation dropped {dropped} of {total_read} rows ({100 * dropped / total_read:.1f}%): "
            f"{why}{fix}"
        )
    if isinstance(bag, dict):
        if bag.get("topics_not_read"):
            warns.append(topics_not_read_warning(bag["topics_not_read"]))
        if bag.get("partial_read"):
            warns.append(f"DROPPED: {bag['partial_read']}")
        lost = [n for n in bag.get("notes") or [] if "skipped" in str(n) or "could not" in str(n)]
        if lost:
            warns.append(
                "DROPPED: "
                + "; ".join(str(n) for n in lost[:3])
                + (f" (and {len(lost) - 3} more)" if len(lost) > 3 else "")
            )
    return info, warns
