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


def _columns_fix(rec: Recording, channel: str, unit: str) -> str:
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
def _unit_note(rec: Recording, channel: str, declared: str) -> str:
    if channel in _assumed(rec):
        return f"the header gives no unit for {channel}, so {declared} was assumed"
    return f"the header declares {channel} in {declared}"


def _declared(rec: Recording, channel: str) -> tuple[str, float]:
    """The unit the channel's source columns were read in and its factor to SI (from the column mapping)."""
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
    unit, factor = _declared(rec, channel)
    note = _unit_note(rec, channel, unit)
    raw = med / factor  # the median magnitude in the file's own numbers
    for cand in candidates:
        f = _units.lookup(cand)[1]
        if lo <= raw * f <= hi and not math.isclose(f, factor, rel_tol=1e-6):
            extra = " (or raw counts)" if cand in ("mgauss", "mg") else ""
            rep.warnings.append(
                f"UNITS: {what} median magnitude is {med:.4g} {si} (expected {expected}): {note}, but the values "
                f"look like {cand}{extra} — {_columns_fix(rec, channel, cand)}"
            )
            return
    rep.warnings.append(
        f"UNITS: {what} median magnitude is {med:.4g} {si} (expected {expected}): {note}; raw counts? — "
        f"{_columns_fix(rec, channel, candidates[0] + '*SCALE')} with the sensor's scale per count"
    )


def check_accel_units(rec: Recording, rep: PlausibilityReport) -> None:
    """Median |accel| ≈ g (a walk, a ship or a rotation keep the median near g)."""
    g = STANDARD_GRAVITY
    _magnitude_check(rec, rep, "accel", 0.6 * g, 1.6 * g, ("g", "m/s^2", "mg"), "accelerometer", "≈ 9.81 m/s² at rest")


def check_mag_units(rec: Recording, rep: PlausibilityReport) -> None:
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


def check_gyro_units(rec: Recording, rep: PlausibilityReport) -> None:
    """Gyro scale against the accelerometer's tilting (:func:`gyro_tilt_ratio`), else against any gyro's range."""
    wf = _finite_xyz(rec, "gyro")
    if wf is None:
        return
    unit, factor = _declared(rec, "gyro")
    note = _unit_note(rec, "gyro", unit)
    p99 = float(np.percentile(np.linalg.norm(wf, axis=1), 99))
    rep.figures["gyro_p99_norm_rad_s"] = p99
    r = gyro_tilt_ratio(rec)
    if r is not None:
        rep.figures["gyro_tilt_slope"] = r["k"]
        rep.figures["gyro_tilt_correlation"] = r["correlation"]
    # deg/s and rad/s differ by 57.3×: decide at the geometric midpoint (7.5×) when the two agree in shape
    if r is not None and r["correlation"] > 0.4 and r["k"] > 0:
        k = r["k"]  # SI values × k = what the accelerometer's tilting says
        if 1 / 7.5 <= k <= 7.5:
            return
        true_factor = factor * k
        for cand in ("deg/s", "rad/s"):
            f = _units.lookup(cand)[1]
            if 1 / 7.5 <= true_factor / f <= 7.5:
                rep.warnings.append(
                    f"UNITS: gyro rates are {1 / k:.3g}× the tilting the accelerometer shows: {note}, but the "
                    f"values look like {cand} — {_columns_fix(rec, 'gyro', cand)}"
                )
                return
        rep.warnings.append(
            f"UNITS: gyro rates disagree with the tilting the accelerometer shows by a factor {1 / k:.3g} "
            f"(expected 1): {note}; wrong unit or scale? — {_columns_fix(rec, 'gyro', 'UNIT*SCALE')}"
        )
        return
    if p99 > PHYSICAL_LIMITS["gyro"] / 2 and not math.isclose(factor, _DEG, rel_tol=1e-6):
        rep.warnings.append(
            f"UNITS: gyro reads up to {p99:.3g} rad/s ({p99 / _DEG:.3g} °/s), beyond any gyro's range: {note}, "
            f"but the values look like deg/s — {_columns_fix(rec, 'gyro', 'deg/s')}"
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
            f"{_columns_fix(rec, 'gyro', 'deg/s')}"
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
    from .frames import parse_axis_remap

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


def check_gravity_direction(rec: Recording, rep: PlausibilityReport, mounting: str | None = None) -> None:
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
    what = (
        "+z: the sensor's z axis points up (FLU/ENU-style sensor, e.g. x-io, ROS REP-103)"
        if axis == 2 and sign > 0
        else f"{'+' if sign > 0 else '-'}{_AX[axis]}: that sensor axis points up"
    )
    given = f" even after --mounting {mounting!r}" if mounting else ""
    rep.warnings.append(
        f"AXES: the mean specific force points along {what}{given}; imutool's body frame is FRD (z down, so "
        f"an accelerometer at rest reads −9.81 m/s² on z) — give the sensor mounting, e.g. --mounting {fix} "
        f"(otherwise roll/pitch come out about {tilt:.0f}° off)"
    )


def sample_rows(rec: Recording, max_rows: int = 60_000, pieces: int = 6) -> Recording:
    """``rec`` itself, or for a long recording ``pieces`` evenly spaced contiguous stretches of ``max_rows`` rows
    in all (statistics of units and axes do not need every row; contiguous stretches keep the time structure
    the gyro/tilt comparison needs)."""
    n = len(rec)
    if n <= max_rows:
        return rec
    k = max_rows // pieces
    starts = np.linspace(0, n - k, pieces).astype(np.int64)
    idx = (starts[:, None] + np.arange(k)[None, :]).ravel()
    return Recording(
        rec.time[idx],
        {c: rec.channels[c][idx] for c in _SENSORS if c in rec.channels},
        {c: u for c, u in rec.units.items() if c in _SENSORS},
        dict(rec.meta),
        {c: list(v) for c, v in rec.columns.items() if c in _SENSORS},
    )


def check_recording(rec: Recording, mounting: str | None = None) -> PlausibilityReport:
    """Run every plausibility check on the sensor channels of ``rec`` (working units, after mounting).

    Long recordings are checked on :func:`sample_rows` (about 60 000 rows in six stretches)."""
    rep = PlausibilityReport()
    rec = sample_rows(rec)
    check_accel_units(rec, rep)
    check_gyro_units(rec, rep)
    check_mag_units(rec, rep)
    check_gravity_direction(rec, rep, mounting)
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
    against this many samples when more than the recording's (a stream: the rows seen so far).
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
        if nb > max_fraction * max(len(a), out_of):  # a unit or scale problem, not corruption: left as it is
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
